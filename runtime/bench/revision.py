"""Another revision's code, run by this environment's Python: a git worktree of it and an import shim.

``make bench-check`` measures the working tree against an earlier commit in one sitting. Building a second
virtual environment for the old commit would take minutes and could pick up other versions of NumPy or
moderngl; instead the old tree is checked out beside (``git worktree add``) and imported by the same
interpreter through a *shim*: a folder holding a ``facepuppet`` package whose parts are links into that tree,
laid out as the tree's own ``pyproject.toml`` maps them (``[tool.setuptools.package-dir]``: ``facepuppet`` from
``runtime/_top``, ``facepuppet.runtime`` from ``runtime/``, ...), put first on ``PYTHONPATH``.

The editable install of this environment is an import finder consulted after ``sys.path``: it would still find a
module the old tree lacks, in the current tree, and mix the two versions. The shim's ``sitecustomize.py``
removes that finder at start-up, in every process started with the shim's environment (the latency bench's
sender and receiver processes too), so a module is the old tree's or is not found. :func:`check_shim` proves
which files are imported.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

from facepuppet.runtime.errors import UsageError

PACKAGE = "facepuppet"
#: what :func:`check_shim` imports and locates
CHECKED = ("facepuppet", "facepuppet.runtime", "facepuppet.offline", "facepuppet.shaders")

_SITECUSTOMIZE = '''\
"""Written by facepuppet's bench-check: this interpreter imports facepuppet only from the folder of this file
(the editable install's finder, which would find what that tree lacks in another tree, is removed)."""
import sys

sys.meta_path[:] = [f for f in sys.meta_path
                    if not (getattr(f, "__module__", "").startswith("__editable__") and "facepuppet" in f.__module__)]
'''


class RevisionError(UsageError):
    """A revision cannot be checked out or imported as asked; the message says which and why."""


def git(repo: str | os.PathLike, *args: str) -> str:
    """``git -C repo ARGS``'s output, stripped; RevisionError with git's own message when it fails."""
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise RevisionError(f"git {' '.join(args)}: {done.stderr.strip() or f'exit code {done.returncode}'}")
    return done.stdout.strip()


def resolve(repo: str | os.PathLike, rev: str) -> str:
    """The full commit hash ``rev`` names in ``repo``."""
    return git(repo, "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")


def describe(repo: str | os.PathLike, rev: str, width: int = 72) -> str:
    """``"abc1234 subject line"`` of a commit, cut to ``width`` characters."""
    text = git(repo, "log", "-1", "--format=%h %s", rev)
    return text if len(text) <= width else text[:width - 3] + "..."


def add_worktree(repo: str | os.PathLike, rev: str, folder: str | os.PathLike) -> Path:
    """Check ``rev`` out into ``folder`` (detached; a worktree left there by an earlier sitting is replaced)."""
    folder = Path(folder).resolve()
    remove_worktree(repo, folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    git(repo, "worktree", "add", "--detach", "--force", str(folder), resolve(repo, rev))
    return folder


def remove_worktree(repo: str | os.PathLike, folder: str | os.PathLike) -> None:
    """Remove the worktree at ``folder`` if there is one, and forget worktrees whose folder is gone."""
    folder = Path(folder).resolve()
    if folder.exists():
        git(repo, "worktree", "remove", "--force", str(folder))
    git(repo, "worktree", "prune")


def package_dirs(tree: str | os.PathLike) -> dict[str, Path]:
    """Package name -> folder in ``tree``, as its ``pyproject.toml`` maps them (``[tool.setuptools.package-dir]``);
    a tree without that table holds the package in ``tree/facepuppet``."""
    tree = Path(tree)
    try:
        project = tomllib.loads((tree / "pyproject.toml").read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise RevisionError(f"{tree / 'pyproject.toml'}: cannot be read ({exc})") from None
    mapping = project.get("tool", {}).get("setuptools", {}).get("package-dir", {})
    if not mapping:
        return {PACKAGE: tree / PACKAGE}
    dirs = {name: tree / folder for name, folder in mapping.items() if name.split(".")[0] == PACKAGE}
    deep = [name for name in dirs if name.count(".") > 1]
    if PACKAGE not in dirs or deep:
        raise RevisionError(f"{tree / 'pyproject.toml'}: tool.setuptools.package-dir: expected {PACKAGE!r} and its "
                            f"direct subpackages, found {sorted(dirs)}")
    return dirs


def make_shim(tree: str | os.PathLike, shim: str | os.PathLike) -> Path:
    """A folder that, first on ``PYTHONPATH``, makes ``import facepuppet`` import ``tree``'s code (see the module
    doc). Made afresh (an earlier shim there is replaced); returns ``shim``."""
    tree, shim = Path(tree).resolve(), Path(shim)
    dirs = package_dirs(tree)
    package = shim / PACKAGE
    if shim.exists():  # ours, from an earlier sitting: links, and the files written here (never followed)
        shutil.rmtree(shim)
    package.parent.mkdir(parents=True, exist_ok=True)
    top = dirs.pop(PACKAGE)
    if not dirs:  # the package is one folder of the tree
        package.symlink_to(top, target_is_directory=True)
    else:
        package.mkdir()
        for entry in sorted(top.iterdir()):
            if entry.name != "__pycache__":
                (package / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
        for name, folder in dirs.items():
            (package / name.split(".")[1]).symlink_to(folder, target_is_directory=True)
    (shim / "sitecustomize.py").write_text(_SITECUSTOMIZE, encoding="utf-8")
    return shim


def shim_env(shim: str | os.PathLike, env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) with ``shim`` first on ``PYTHONPATH``."""
    env = dict(os.environ if env is None else env)
    rest = env.get("PYTHONPATH")
    env["PYTHONPATH"] = str(Path(shim).resolve()) + (os.pathsep + rest if rest else "")
    return env


def imported_from(shim: str | os.PathLike, modules: tuple[str, ...] = CHECKED,
                  python: str = sys.executable) -> dict[str, str | None]:
    """Module -> the real path (links resolved) of the file or folder a Python started with the shim's
    environment imports it from; None for a module it cannot find."""
    probe = ("import importlib.util, json, os, sys\n"
             "found = {}\n"
             "for name in sys.argv[1:]:\n"
             "    try:\n"
             "        spec = importlib.util.find_spec(name)\n"
             "    except ImportError:\n"
             "        spec = None\n"
             "    where = None if spec is None else spec.origin if spec.has_location else list(spec.submodule_search_locations)[0]\n"  # noqa: E501
             "    found[name] = None if where is None else os.path.realpath(where)\n"
             "print(json.dumps(found))\n")
    done = subprocess.run([python, "-c", probe, *modules], capture_output=True, text=True, env=shim_env(shim),
                          cwd=str(Path(shim).resolve()))
    if done.returncode != 0:
        raise RevisionError(f"{shim}: Python cannot import through this shim: {done.stderr.strip()[-800:]}")
    return json.loads(done.stdout)


def check_shim(shim: str | os.PathLike, tree: str | os.PathLike, python: str = sys.executable) -> dict[str, str]:
    """Module -> real path of each :data:`CHECKED` module imported through ``shim``, each checked to be in ``tree``."""
    tree = Path(tree).resolve()
    found = imported_from(shim, CHECKED, python)
    wrong = {name: where for name, where in found.items()
             if where is None or not Path(where).is_relative_to(tree)}
    if wrong:
        raise RevisionError(f"{shim}: expected facepuppet's code from {tree}, found " +
                            ", ".join(f"{name} from {where}" for name, where in wrong.items()))
    return found
