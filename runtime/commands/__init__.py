"""The runtime's subcommands of ``facepuppet``: run, replay, demo, manipulate, contact-sheet."""
