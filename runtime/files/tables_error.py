"""The one error of the tables file format: a file, or tables about to be written, that is not acceptable.

Its own module so that both the format (:mod:`facepuppet.runtime.files.tables`) and the bounded reading of a
file's arrays (:mod:`facepuppet.runtime.files.table_members`) raise it without importing each other.
"""

from __future__ import annotations

import os

from facepuppet.runtime.errors import FacepuppetError

NO_FILE = "<tables>"  # the path of a TablesError about tables in memory


class TablesError(FacepuppetError, ValueError):
    """A tables file (or tables about to be written) is not acceptable.

    The message names the file and the field, what was expected and what was
    found.
    """

    def __init__(self, path: str | os.PathLike | None, field_name: str, problem: str) -> None:
        self.path = str(path) if path is not None else NO_FILE
        self.field = field_name
        self.problem = problem
        super().__init__(f"{self.path}: {field_name}: {problem}")
