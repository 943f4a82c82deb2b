"""Recordings: the session file format, the recorder, and the sources that replay a recording."""
