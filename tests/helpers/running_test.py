"""The marker names of the test now running, so a helper can check that the test declares what it uses.

tests/conftest.py sets ``marks`` around each test (set-up, call, tear-down) and ``need_shared`` reads it.
It lives in a module of its own because conftest.py is imported twice in this suite (as ``conftest`` and
as ``tests.conftest``) and each copy has its own globals; ``helpers.running_test`` is imported once.
"""

from __future__ import annotations

marks: frozenset[str] | None = None  # None outside a test (collection, session start and end)
