"""Ju & Lee (2008) offline: blend weights, regional features, speech intensity, gesture database, detail transfer."""
