"""Yano & Harada (2009) at runtime: the elastic tables and their evaluation."""
