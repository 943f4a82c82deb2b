"""Unique names for what a glTF file names freely: nodes, materials, images read, mesh hosts written."""

from __future__ import annotations

from collections.abc import Iterable


class UniqueNames:
    """Names made unique in the order they are taken: a name taken already gets ``#2``, ``#3``, ... (the first
    free), as the glTF spec leaves names free to repeat and a character's names are keys. Each base name
    remembers where its count reached, so a file repeating one name many times costs linear time, not
    quadratic."""

    def __init__(self, taken: Iterable[str] = ()) -> None:
        self.used: set[str] = set(taken)
        self._next: dict[str, int] = {}

    def take(self, base: str) -> str:
        name, k = base, self._next.get(base, 1)
        while name in self.used:
            k += 1
            name = f"{base}#{k}"
        self._next[base] = k
        self.used.add(name)
        return name
