"""Offline readers: OBJ/MTL meshes, marker captures (TRC, C3D, CSV), rig import."""
