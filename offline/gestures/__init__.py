"""Ju & Lee (2008) offline: blend weights, regional features, speech intensity, the gesture database, detail transfer."""
