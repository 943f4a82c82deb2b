"""Drawing a character: the GL context, the shader loader, the renderer and its deformation paths."""
