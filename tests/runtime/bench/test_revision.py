"""Another revision's code through an import shim: in a temporary clone of this repository with a throwaway
commit, each side imports its own tree (the editable install of this environment, which points elsewhere, never
fills in what a tree lacks), and the worktree of the older commit comes and goes cleanly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from facepuppet.runtime.bench import revision

from helpers.git_clones import REPO, THROWAWAY_VERSION, git, throwaway_clone


@pytest.fixture(scope="module")
def clone(tmp_path_factory) -> Path:
    return throwaway_clone(tmp_path_factory.mktemp("clone"))


def probe(shim: Path, code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], env=revision.shim_env(shim), cwd=str(shim),
                          capture_output=True, text=True, check=True).stdout.strip()


def test_each_side_imports_its_own_tree(clone, tmp_path):
    base = revision.add_worktree(clone, "HEAD~1", tmp_path / ".bench" / "base")
    try:
        assert revision.resolve(base, "HEAD") == revision.resolve(clone, "HEAD~1")
        shims = {"head": revision.make_shim(clone, tmp_path / ".bench" / "shim-head"),
                 "base": revision.make_shim(base, tmp_path / ".bench" / "shim-base")}
        trees = {"head": clone.resolve(), "base": base.resolve()}
        for side in ("head", "base"):
            found = revision.check_shim(shims[side], trees[side])
            assert set(found) == set(revision.CHECKED)
            assert all(Path(p).is_relative_to(trees[side]) for p in found.values())
        code = ("import facepuppet, importlib.util; print(facepuppet.__version__); "
                "print(importlib.util.find_spec('facepuppet.runtime.protocols') is not None)")
        head_version, head_protocols = probe(shims["head"], code).splitlines()
        base_version, base_protocols = probe(shims["base"], code).splitlines()
        assert head_version.startswith(THROWAWAY_VERSION) and not base_version.startswith(THROWAWAY_VERSION)
        # the throwaway commit deleted the module: the head side does not find it, not even through this
        # environment's editable install (whose tree has it); the base side finds it in its own tree
        assert (head_protocols, base_protocols) == ("False", "True")
        assert (REPO / "runtime" / "protocols.py").exists()
        # the command itself, as bench-check runs it
        done = subprocess.run([sys.executable, "-m", "facepuppet", "--version"], env=revision.shim_env(shims["head"]),
                              cwd=str(shims["head"]), capture_output=True, text=True)
        assert done.stdout.strip() == f"facepuppet {head_version}"
        with pytest.raises(revision.RevisionError, match="expected facepuppet's code from"):
            revision.check_shim(shims["head"], trees["base"])
    finally:
        revision.remove_worktree(clone, base)
    assert not base.exists() and str(base) not in git(clone, "worktree", "list")


def test_a_worktree_left_by_an_earlier_sitting_is_replaced(clone, tmp_path):
    folder = tmp_path / "base"
    revision.add_worktree(clone, "HEAD", folder)
    (folder / "left-over.txt").write_text("from the last sitting")
    revision.add_worktree(clone, "HEAD~1", folder)
    try:
        assert revision.resolve(folder, "HEAD") == revision.resolve(clone, "HEAD~1")
        assert not (folder / "left-over.txt").exists()
    finally:
        revision.remove_worktree(clone, folder)


def test_a_shim_made_again_replaces_its_links_and_never_touches_the_tree(clone, tmp_path):
    shim = revision.make_shim(clone, tmp_path / "shim")
    revision.make_shim(clone, shim)
    assert (shim / "facepuppet" / "runtime").is_symlink()
    assert (shim / "facepuppet" / "runtime").resolve() == (clone / "runtime").resolve()
    assert (shim / "facepuppet" / "__init__.py").resolve() == (clone / "runtime" / "_top" / "__init__.py").resolve()
    assert (clone / "runtime" / "frames.py").exists()


def test_a_tree_without_a_package_map_is_imported_from_its_facepuppet_folder(tmp_path):
    tree = tmp_path / "flat"
    (tree / "facepuppet" / "runtime").mkdir(parents=True)
    (tree / "pyproject.toml").write_text('[project]\nname = "facepuppet"\n')
    (tree / "facepuppet" / "__init__.py").write_text("")
    (tree / "facepuppet" / "runtime" / "__init__.py").write_text("")
    assert revision.package_dirs(tree) == {"facepuppet": tree / "facepuppet"}
    shim = revision.make_shim(tree, tmp_path / "shim")
    assert (shim / "facepuppet").is_symlink()
    found = revision.imported_from(shim, ("facepuppet", "facepuppet.runtime", "facepuppet.offline"))
    assert found["facepuppet.runtime"] == str((tree / "facepuppet" / "runtime" / "__init__.py").resolve())
    assert found["facepuppet.offline"] is None  # not in that tree, and not taken from the editable install


def test_unknown_revisions_and_unreadable_trees_are_refused(clone, tmp_path):
    with pytest.raises(revision.RevisionError, match="rev-parse"):
        revision.resolve(clone, "no-such-revision")
    (tmp_path / "pyproject.toml").write_text("[tool.setuptools.package-dir\n")
    with pytest.raises(revision.RevisionError, match="pyproject.toml: cannot be read"):
        revision.package_dirs(tmp_path)
