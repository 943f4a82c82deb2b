"""The renderer's deformation paths: how a frame's weights become deformed vertices.

Three paths draw the same character through the same programs, buffers and passes
(:class:`~facepuppet.runtime.render.renderer.FaceRenderer` owns those); they differ in where the
blendshapes are summed:

* ``gpu`` (:mod:`.gpu`): in the vertex shader, from every shape's deltas in one 16-bit texture
  (:mod:`.deltas`); per frame only the active (shape, weight) pairs are uploaded.
* ``cpu`` (:mod:`.cpu`): with NumPy (:mod:`~facepuppet.runtime.render.cpu_deform`), the result
  written into the vertex buffer.
* ``elastic`` (:mod:`.elastic`): control-point displacements spread by a compact basis in the
  vertex shader (Yano & Harada 2009).

Each is a :class:`~.base.DeformationPath`: built once with the renderer's program builder, then per
frame ``prepare`` (CPU side), ``bind`` (before the draw calls), and ``release`` at the end.
"""
