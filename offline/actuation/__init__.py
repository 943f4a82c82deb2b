"""Shin & Lee (2009) offline: stabilise, actuations (ICA), cubic fit, training, transfer."""
