"""The embedded demo: a procedural head and a synthetic performance, needing no data files."""
