"""The shape of the tree: ``runtime/`` never imports ``offline/`` (a stage machine may install the runtime
only), and the project's own modules are imported at the top of each file, so the import graph is what the
tops of the files say (a function may import only optional extras, GL, and the few heavy offline modules a
command loads when it runs).
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Function-local imports of the project's own modules that stay: each pulls in GL (moderngl, glfw, a
# context), an optional extra (imgui-bundle), or a heavy part of SciPy that a command loads only when run.
LOCAL_IMPORTS_ALLOWED = (
    "facepuppet.runtime.render",   # moderngl: a command's GL is opened only when it draws
    "facepuppet.runtime.panel",    # imgui-bundle, the optional extra 'panel'
    "facepuppet.offline.actuation.train",  # scipy.signal/stats: loaded by train-actor and its bench only
    "facepuppet.offline.gestures",  # scipy.signal/ndimage: loaded by the gesture commands only
    "facepuppet.offline.elastic.pictures",  # GL pictures
    "facepuppet.offline.perfect_sync.pictures",  # GL pictures
    "facepuppet.offline.actuation.pictures",  # GL pictures
)


def _imports(path: Path):
    """(line, module, nested in a function) of every import of ``path``, TYPE_CHECKING blocks left out."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped.update(id(n) for child in node.body for n in ast.walk(child))
    nested = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            nested.update(id(n) for child in node.body for n in ast.walk(child))
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.lineno, node.module, id(node) in nested
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, id(node) in nested


def _modules(side: str):
    return sorted(p for p in (REPO / side).rglob("*.py") if "__pycache__" not in p.parts)


def test_runtime_never_imports_offline():
    found = [f"{p.relative_to(REPO)}:{line} imports {module}"
             for p in _modules("runtime") for line, module, _ in _imports(p)
             if module == "facepuppet.offline" or module.startswith("facepuppet.offline.")]
    assert found == [], "runtime/ must not import offline/:\n" + "\n".join(found)


def test_the_projects_modules_are_imported_at_the_top():
    found = [f"{p.relative_to(REPO)}:{line} imports {module} inside a function"
             for side in ("runtime", "offline") for p in _modules(side)
             for line, module, nested in _imports(p)
             if nested and module.startswith("facepuppet") and not module.startswith(LOCAL_IMPORTS_ALLOWED)]
    assert found == [], ("import the project's own modules at the top of the file (a function may import only "
                         "GL, optional extras and the heavy modules listed in LOCAL_IMPORTS_ALLOWED):\n"
                         + "\n".join(found))


def test_the_checks_see_what_they_look_for(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("from typing import TYPE_CHECKING\nimport facepuppet.runtime.frames\n"
                      "if TYPE_CHECKING:\n    from facepuppet.offline.io import obj\n"
                      "def f():\n    from facepuppet.runtime.live import loop\n    return loop\n")
    got = list(_imports(source))
    assert (2, "facepuppet.runtime.frames", False) in got
    assert (6, "facepuppet.runtime.live", True) in got
    assert not any(module.startswith("facepuppet.offline") for _, module, _ in got)  # TYPE_CHECKING: not run
