"""Shin & Lee (2009) at runtime: actor and pair tables, the marker solve, its stage, direct manipulation."""
