"""Ju & Lee (2008) at runtime: the gesture database, the two-level MRF synthesis, the gesture stage."""
