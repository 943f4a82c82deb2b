"""Every public signature of runtime/ and offline/ carries type hints (parameters and return).

Public: a module-level function or a method of a module-level class whose names do not start with ``_``
(dunder methods of public classes count: ``__init__``, ``__call__``, ...). ``self``/``cls`` and a bare
``*``/``**`` need none. A new unannotated public function fails here, naming it.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _public(name: str) -> bool:
    return not name.startswith("_") or (name.startswith("__") and name.endswith("__"))


def _missing(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    args = fn.args
    params = args.posonlyargs + args.args + args.kwonlyargs
    if method and params and params[0].arg in ("self", "cls"):
        params = params[1:]
    if method and fn.name == "__new__" and params and params[0].arg == "cls":
        params = params[1:]
    out = [p.arg for p in params if p.annotation is None]
    out += [f"*{a.arg}" for a in (args.vararg, args.kwarg) if a is not None and a.annotation is None]
    if fn.returns is None:
        out.append("return")
    return out


def unannotated() -> list[str]:
    found = []
    for side in ("runtime", "offline"):
        for path in sorted((REPO / side).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            rel = path.relative_to(REPO).as_posix()
            for node in tree.body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _public(node.name):
                    if miss := _missing(node, method=False):
                        found.append(f"{rel}:{node.lineno} {node.name}: {', '.join(miss)}")
                elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                    for item in node.body:
                        if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and _public(item.name):
                            if miss := _missing(item, method=True):
                                found.append(f"{rel}:{item.lineno} {node.name}.{item.name}: {', '.join(miss)}")
    return found


def test_every_public_signature_is_annotated():
    missing = unannotated()
    assert missing == [], "public signatures without type hints:\n" + "\n".join(missing)


def test_the_check_sees_a_missing_hint(tmp_path):
    tree = ast.parse("def f(a, b: int) -> int:\n    return b\n\ndef g(c: int):\n    return c\n")
    f, g = tree.body
    assert _missing(f, method=False) == ["a"] and _missing(g, method=False) == ["return"]
