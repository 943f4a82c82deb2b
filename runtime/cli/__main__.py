"""``python -m facepuppet.runtime.cli``: the ``facepuppet`` command."""

from facepuppet.runtime.cli.command import main

raise SystemExit(main())
