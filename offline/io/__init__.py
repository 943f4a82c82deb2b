"""Offline readers and writers: OBJ/MTL meshes, marker captures (TRC, C3D, CSV), rig import, glTF/VRM (``gltf/``)."""
