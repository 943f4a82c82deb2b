"""The problem list of ``check-gltf`` and the typed getters it walks a glTF document with.

A glTF from a stranger may hold any JSON where the specification asks for an
object, an array, an index or a number. Every value ``check-gltf`` looks at
goes through one of these getters, which report a value of the wrong type as a
problem naming its JSON path (``meshes[0].primitives: "x": must be an array``)
and hand the caller a harmless default, so the walk goes on and never raises.
Problems are listed once each; values are quoted through :func:`show`, which
bounds the text (a value may be a megabyte-long array).
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Iterator
from typing import Any

__all__ = ["JsonWalk", "show", "join", "is_int", "is_number"]

_KIND_NAMES = {dict: "an object", list: "an array", str: "a string", int: "an integer", float: "a number",
               bool: "true or false"}
_SHOW = reprlib.Repr()
_SHOW.maxstring, _SHOW.maxother, _SHOW.maxlist, _SHOW.maxdict, _SHOW.maxlevel = 40, 40, 6, 4, 2


def show(value: Any) -> str:
    """``value`` as a problem quotes it: a ``repr`` of bounded length and cost."""
    return _SHOW.repr(value)


def join(where: str, key: str) -> str:
    """The JSON path of ``key`` in the object at ``where`` ("" for the document), its name cut to 40 characters."""
    key = key if len(key) <= 40 else key[:37] + "..."
    return f"{where}.{key}" if where else key


def is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_number(v: Any) -> bool:
    """A finite JSON number (not a boolean; an integer too large for a float is not one)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _is_kind(v: Any, kind: type) -> bool:
    if kind is int:
        return is_int(v)
    if kind is float:
        return is_number(v)
    return isinstance(v, kind)


class JsonWalk:
    """The document being checked (``doc``), the problems found so far, and getters that report wrong types."""

    def __init__(self) -> None:
        self.doc: dict = {}
        self.problems: list[str] = []
        self._seen: set[str] = set()

    def bad(self, where: str, what: str) -> None:
        """Record the problem ``where: what`` (once)."""
        problem = f"{where}: {what}"
        if problem not in self._seen:
            self._seen.add(problem)
            self.problems.append(problem)

    # -- typed values -------------------------------------------------------------------------
    def value(self, obj: Any, key: str, kind: type, where: str, default: Any = None) -> Any:
        """``obj[key]`` when it is of ``kind`` (int: not a bool; float: any finite number); ``default`` when absent,
        or, after a problem naming ``where.key``, when of another kind. ``where`` "" is the document."""
        if not isinstance(obj, dict) or key not in obj:
            return default
        v = obj[key]
        if _is_kind(v, kind):
            return v
        self.bad(join(where, key), f"{show(v)}: must be {_KIND_NAMES[kind]}")
        return default

    def req(self, obj: dict, key: str, where: str, kind: type) -> Any:
        """``obj[key]``, required: None after a problem when it is missing or of another kind."""
        if key not in obj:
            self.bad(join(where, key), "missing (required)")
            return None
        return self.value(obj, key, kind, where)

    def dict_at(self, obj: Any, key: str, where: str) -> dict:
        """The object ``obj[key]``; {} when absent or not an object (the latter a problem)."""
        return self.value(obj, key, dict, where, {})

    def list_at(self, obj: Any, key: str, where: str) -> list:
        """The array ``obj[key]``; [] when absent or not an array (the latter a problem)."""
        return self.value(obj, key, list, where, [])

    def entries(self, values: list, where: str) -> Iterator[tuple[int, dict, str]]:
        """(index, object, JSON path) of the elements of ``values`` that are objects; the others are problems."""
        for i, o in enumerate(values):
            if isinstance(o, dict):
                yield i, o, f"{where}[{i}]"
            else:
                self.bad(f"{where}[{i}]", f"{show(o)}: must be an object")

    # -- the top-level arrays and references into them ----------------------------------------
    def items(self, key: str) -> list:
        """The top-level array ``key`` ([] when absent, or after a problem when not an array)."""
        v = self.doc.get(key, [])
        if not isinstance(v, list):
            self.bad(key, f"{show(v)}: must be an array")
            return []
        return v

    def objects(self, key: str) -> list[tuple[int, dict, str]]:
        """(index, object, JSON path) of the top-level array ``key``'s objects."""
        return list(self.entries(self.items(key), key))

    def index(self, obj: dict, key: str, array: str, where: str, required: bool = False) -> int | None:
        """``obj[key]`` when it is an index into the top-level ``array``; None otherwise (a problem when present or
        ``required``)."""
        if key not in obj:
            if required:
                self.bad(f"{where}.{key}", "missing (required)")
            return None
        v = obj[key]
        n = len(self.items(array))
        if not is_int(v) or not 0 <= v < n:
            self.bad(f"{where}.{key}", f"{show(v)} is not an index into {array} ({n} entries)")
            return None
        return v

    def node_ref(self, v: Any, where: str, allow_minus_one: bool = False) -> None:
        """A problem at ``where`` unless ``v`` is a node index (or -1 where that means none)."""
        n = len(self.items("nodes"))
        if allow_minus_one and is_int(v) and v == -1:
            return
        if not is_int(v) or not 0 <= v < n:
            self.bad(where, f"{show(v)} is not a node index ({n} nodes)")
