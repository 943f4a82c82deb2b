"""JSON from files a stranger may hand us, read within stated limits; JSON we write, readable by strict parsers.

Reading. Python's ``json`` decoder recurses once per nested list or object, so text nested 100,000 deep
(a few hundred kB) ends in a RecursionError instead of a refusal, and a size nobody checked is parsed in full
before anything looks at it. :func:`loads_limited` checks the size, then the nesting depth with a scan that
never parses (:func:`nesting_depth`, linear in the text and bounded in memory), and only then hands the text
to ``json.loads``. Every reader of a stranger's JSON (a tables manifest, a session file's header and JSON
records, a manipulation script) goes through it, so one limit holds everywhere.

Writing. ``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which are not JSON: strict parsers
(JavaScript's ``JSON.parse``, ``jq``, most other languages) refuse the whole document. :func:`dumps_strict`
writes ``null`` for every non-finite float, so "missing" stays readable everywhere.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from facepuppet.runtime.errors import InputFileError

MAX_DEPTH = 64  # nesting of lists and objects: the project's own files nest a handful of levels
MAX_BYTES = 16 << 20  # the largest JSON text read by default: far beyond a header, a layout or a state
_CHUNK = 1 << 20  # bytes scanned at a time by nesting_depth (bounds its temporary arrays)

_QUOTE, _BACKSLASH = ord('"'), ord("\\")
_OPEN = np.frombuffer(b"[{", np.uint8)
_CLOSE = np.frombuffer(b"]}", np.uint8)


class JsonTextError(InputFileError):
    """JSON text that cannot be read: ``where`` it is, and the ``problem`` (a caller with its own error type
    words its message from them)."""

    def __init__(self, where: str, problem: str) -> None:
        self.where, self.problem = where, problem
        super().__init__(f"{where}: {problem}")


class JsonLimitError(JsonTextError):
    """JSON text over a stated limit (its size or nesting depth), refused before it was parsed."""


def nesting_depth(text: bytes | str) -> int:
    """How deeply lists and objects nest in JSON ``text`` (brackets inside strings left out), without parsing.

    Linear in the text, in chunks of ``_CHUNK`` bytes. A quote counts unless an odd run of backslashes
    precedes it, the rule inside JSON strings; outside them a backslash is invalid JSON, where ``json.loads``
    stops, so the depth counted up to the first error is exact and the whole text's is an upper bound.
    UTF-8 is scanned as bytes: no byte of a multi-byte character is a quote, a backslash or a bracket.
    """
    raw = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else bytes(text)
    depth = deepest = 0
    in_string = False  # the chunk starts inside a string
    escaping = False  # the chunk starts right after an odd run of backslashes
    for start in range(0, len(raw), _CHUNK):
        b = np.frombuffer(raw, np.uint8, count=min(_CHUNK, len(raw) - start), offset=start)
        n = len(b)
        backslash = b == _BACKSLASH
        index = np.arange(n, dtype=np.int32)
        # for each byte, the length of the run of backslashes ending at it (0 when it is none)
        last_other = np.maximum.accumulate(np.where(backslash, -1, index))
        run = index - last_other
        odd_run = (run & 1).astype(bool)
        odd_run[last_other == -1] ^= escaping  # a run that began in the previous chunk
        escaped = np.empty(n, bool)
        escaped[0] = escaping
        escaped[1:] = odd_run[:-1]
        quote = (b == _QUOTE) & ~escaped
        inside = (np.cumsum(quote, dtype=np.int32) & 1).astype(bool) ^ in_string
        step = np.isin(b, _OPEN).astype(np.int8) - np.isin(b, _CLOSE).astype(np.int8)
        step[inside] = 0
        levels = np.cumsum(step, dtype=np.int32)
        deepest = max(deepest, depth + int(levels.max()))
        depth += int(levels[-1])
        in_string = bool(inside[-1])
        escaping = bool(odd_run[-1])
    return deepest


def loads_limited(text: bytes | str, where: str, *, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH) -> Any:
    """Parse JSON ``text`` once its size and nesting depth are within the limits.

    Parameters
    ----------
    text : bytes (UTF-8) or str
    where : str, the file and the part of it that holds ``text`` (``"take.fps: LAYOUT record at byte
        offset 355"``), the start of every message
    max_bytes, max_depth : int, the limits (the UTF-8 size; nesting of lists and objects)

    Raises
    ------
    JsonLimitError
        when the text is over a limit.
    JsonTextError
        when it is not UTF-8 JSON (both are InputFileErrors, so ValueErrors too).
    """
    size = len(text.encode("utf-8", "surrogatepass")) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise JsonLimitError(where, f"{size} bytes of JSON; at most {max_bytes} allowed")
    if size > max_depth:  # a text of n bytes nests at most n deep
        depth = nesting_depth(text)
        if depth > max_depth:
            raise JsonLimitError(where, f"nests {depth} levels deep; at most {max_depth} allowed")
    try:
        return json.loads(text.decode("utf-8") if isinstance(text, (bytes, bytearray, memoryview)) else text)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:  # ValueError: JSON, and over-long ints
        raise JsonTextError(where, f"is not valid UTF-8 JSON ({exc})") from None


def finite_or_null(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, infinities, NumPy's too) replaced by None, in dicts, lists
    and tuples at any depth; NumPy scalars become Python numbers."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def dumps_strict(value: Any, **kwargs: Any) -> str:
    """JSON text of ``value`` that strict parsers accept: non-finite floats written as ``null``
    (:func:`finite_or_null`), ``allow_nan=False`` so that nothing else slips through; ``kwargs`` go to
    ``json.dumps`` (``sort_keys``, ``indent``)."""
    return json.dumps(finite_or_null(value), allow_nan=False, **kwargs)
