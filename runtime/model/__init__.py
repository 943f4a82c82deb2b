"""facepuppet.runtime.model: the character model. ``Character`` (:mod:`.character`: neutral mesh, sparse
blendshape deltas, the ``character`` table kind) and its parts (:mod:`.character_parts`: materials,
skeleton, layout, VRM expressions and meta), and the maths of meshes and poses (:mod:`.geometry`: normals,
bounds, quaternions, Euler angles; :mod:`.rigid`: Kabsch alignment).
"""
