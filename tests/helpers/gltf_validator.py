"""The Khronos glTF-Validator (npm ``gltf-validator``) run on real files through ``gltf_validate.mjs``.

The validator is the reference for what a valid glTF 2.0 file is; it runs in node from the repository's
``node_modules`` (``make setup`` installs it with ``npm ci``). A test that needs it skips, saying why, only
when node or the package is absent.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = Path(__file__).with_name("gltf_validate.mjs")
ERROR, WARNING = 0, 1


def need_validator() -> None:
    """Skip (saying why) when node or node_modules/gltf-validator is absent."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed here; the glTF-Validator runs in node (make setup)")
    if not (REPO / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("node_modules/gltf-validator is absent (make setup runs npm ci)")


def validate(*paths: Path) -> list[dict]:
    """The validator's report of each file: {file, numErrors, numWarnings, messages [{code, severity, pointer,
    message}]}, in the order given."""
    need_validator()
    out = subprocess.run(["node", str(SCRIPT), *map(str, paths)], cwd=REPO, capture_output=True, text=True,
                         timeout=600, check=False)
    if out.returncode != 0:
        raise AssertionError(f"gltf_validate.mjs failed ({out.returncode}): {out.stderr[-2000:]}")
    return [json.loads(line) for line in out.stdout.splitlines() if line.strip()]


def codes(report: dict, severity: int) -> Counter:
    """How many messages of each code at ``severity`` (ERROR, WARNING) the report has."""
    return Counter(m["code"] for m in report["messages"] if m["severity"] == severity)


def problems(report: dict, severity: int) -> list[str]:
    """The messages at ``severity`` as 'CODE at POINTER: message' lines (for assertion messages)."""
    return [f"{m['code']} at {m['pointer']}: {m['message']}" for m in report["messages"] if m["severity"] == severity]
