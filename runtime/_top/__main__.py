"""``python -m facepuppet`` is the ``facepuppet`` command."""

from facepuppet.runtime.cli import main

raise SystemExit(main())
