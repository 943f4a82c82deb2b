"""Perfect sync: the 52 ARKit expressions cloned onto any character\x27s face (issue 14)."""
