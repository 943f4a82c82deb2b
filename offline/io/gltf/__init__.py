"""glTF 2.0 / GLB / VRM 0.x / VRM 1.0 characters, in (:mod:`.read`) and out (:mod:`.write`).

Core glTF is read and written by the ``read_*`` and ``write_*`` modules; each
extension or VRM concept has a module of its own (``khr_materials``,
``vrm_meta``, ``vrm_humanoid``, ``vrm_expressions``, ``vrm_first_person``,
``vrm_spring_bone``, ``vrm_materials``) holding its reader and its writers,
which :mod:`.read` and :mod:`.write` apply, in a listed order, after the core.
The container (GLB chunks, buffers, accessors) is
:mod:`facepuppet.offline.io.gltf_container`.
"""
