"""Ouzounis et al. offline: kernel PLS, training pairs, baselines and the cyclic retarget error."""
