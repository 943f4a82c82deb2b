"""Ouzounis et al. at runtime: the kernel-PLS retarget tables and their per-frame stage."""
