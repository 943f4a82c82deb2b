"""JSON from strangers within limits (size, depth checked before parsing), and strict JSON out (no NaN)."""

from __future__ import annotations

import json
import math
import random

import numpy as np
import pytest

from facepuppet.runtime.files import json_limits
from facepuppet.runtime.files.json_limits import (
    JsonLimitError,
    JsonTextError,
    dumps_strict,
    loads_limited,
    nesting_depth,
)


def plain_depth(text: str) -> tuple[int, bool]:
    """The reference: the nesting depth a character loop following JSON's string rules finds, up to a
    backslash outside a string (where json.loads stops); and whether the text had none."""
    depth = deepest = 0
    inside = escaped = False
    for ch in text:
        if inside:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                inside = False
        elif ch == "\\":
            return deepest, False
        elif ch == '"':
            inside = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest, True


@pytest.mark.parametrize("chunk", [1, 3, 7, 1 << 20])
def test_the_depth_scan_agrees_with_a_plain_loop_across_chunk_boundaries(monkeypatch, chunk):
    monkeypatch.setattr(json_limits, "_CHUNK", chunk)
    rng = random.Random(chunk)
    for _ in range(4000 if chunk > 40 else 300):  # a chunk of a few bytes costs a NumPy pass per chunk
        text = "".join(rng.choice('[]{}"\\ab,:') for _ in range(rng.randint(0, 40)))
        depth, clean = plain_depth(text)
        found = nesting_depth(text)
        assert found == depth if clean else found >= depth, text
    # real JSON: escaped quotes and backslashes inside strings, brackets in strings
    for _ in range(300 if chunk > 40 else 30):
        value = rng.choice([[], {}, 'a\\"[', {"k\\\\": [["]\\\"{"]]}])
        for _ in range(rng.randint(0, 6)):
            value = [value, {'x"[': value}]
        text = json.dumps(value)
        assert nesting_depth(text) == plain_depth(text)[0] == nesting_depth(text.encode())


def test_a_long_run_of_unclosed_escaped_quotes_is_scanned_in_linear_time():
    """'"\\' repeated: a regex skipping strings tried each quote to the end (quadratic); the scan is one pass."""
    assert nesting_depth(b'["' + b'\\"' * 500_000) == 1


def test_deep_json_is_refused_naming_where_not_a_recursion_error():
    deep = "[" * 100_000 + "]" * 100_000
    with pytest.raises(JsonLimitError, match=r"^take\.fps: HEADER: nests 100000 levels deep; at most 64 allowed$"):
        loads_limited(deep, "take.fps: HEADER")
    assert loads_limited("[" * 64 + "]" * 64, "x") == eval("[" * 64 + "]" * 64)
    with pytest.raises(JsonLimitError, match="nests 65 levels"):
        loads_limited(("[" * 65 + "]" * 65).encode(), "x")


def test_size_and_syntax_are_refused_naming_where():
    with pytest.raises(JsonLimitError, match=r"^m\.json: 101 bytes of JSON; at most 100 allowed$"):
        loads_limited(b" " * 99 + b"{}", "m.json", max_bytes=100)
    for bad in (b"{", b"\xff{}", b"[1,]", b"1" * 5000):
        with pytest.raises(JsonTextError, match=r"^m\.json: is not valid UTF-8 JSON") as info:
            loads_limited(bad, "m.json")
        assert not isinstance(info.value, JsonLimitError)


def _strict(text: str):
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


def test_strict_dumps_writes_null_for_every_non_finite_float():
    value = {"a": math.nan, "b": [1.5, -math.inf, np.float32("nan"), np.float64(2.0)], "c": (np.int64(3), math.inf),
             "d": {"e": float("nan"), "f": "NaN"}}
    text = dumps_strict(value, sort_keys=True)
    assert _strict(text) == {"a": None, "b": [1.5, None, None, 2.0], "c": [3, None], "d": {"e": None, "f": "NaN"}}
    with pytest.raises(ValueError, match="not JSON: NaN"):
        _strict(json.dumps(value["d"]))  # what plain json.dumps writes
