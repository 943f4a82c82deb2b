"""A clone of this repository with a throwaway commit on top, for the tests of running another revision's code."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
THROWAWAY_VERSION = "0.0.0+throwaway"


def git(cwd: Path, *args: str) -> str:
    """``git -C cwd ARGS``'s output (a committer named, as a fresh machine has none)."""
    return subprocess.run(["git", "-C", str(cwd), "-c", "user.name=test", "-c", "user.email=test@example.org",
                           *args], check=True, capture_output=True, text=True).stdout.strip()


def throwaway_clone(folder: Path) -> Path:
    """``folder/repo``: a clone of this repository's HEAD with one more commit (a new version string,
    runtime/protocols.py deleted); skips without git or without the repository's history."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs git and this repository's history (a checkout, not an unpacked archive)")
    path = folder / "repo"
    subprocess.run(["git", "clone", "--quiet", str(REPO), str(path)], check=True)
    top = path / "runtime" / "_top" / "__init__.py"
    top.write_text(top.read_text().replace('__version__ = "', f'__version__ = "{THROWAWAY_VERSION}"  # was "', 1))
    (path / "runtime" / "protocols.py").unlink()
    git(path, "commit", "--quiet", "-am", "throwaway: another version, no protocols module")
    return path
