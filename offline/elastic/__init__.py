"""Yano & Harada (2009) offline: bi-Laplacian basis, parameters, control points, cloning, muscles."""
