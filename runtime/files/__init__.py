"""facepuppet.runtime.files: the file policy. What a command reads from strangers and writes: the tables
format (:mod:`.tables`: schemas, bounded inflation, never pickled), the first check of every input file
(:mod:`.input_files`), and the one output policy (:mod:`.outputs`: refuse what exists, atomic writes).
"""
