"""Load one GLSL program per file, with includes, defines and file-named errors.

A program file holds both stages behind ``#ifdef VERTEX_SHADER`` /
``#ifdef FRAGMENT_SHADER`` guards. The loader

* keeps the file's own ``#version`` line (or injects ``#version 330 core``),
* injects ``#define VERTEX_SHADER`` or ``#define FRAGMENT_SHADER`` and the
  caller's defines,
* expands ``#include "name.glsl"`` recursively (a cycle is an error), and
* writes ``#line LINE FILE_ID`` directives, one id per file, so that the
  driver's ``ID:LINE(COL): error: ...`` messages map back to the real file.

Compile and link errors raise :class:`ShaderError` naming file and line.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING

import moderngl

from facepuppet.runtime.errors import FacepuppetError

if TYPE_CHECKING:
    import os

DEFAULT_VERSION = "#version 330 core"

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_VERSION = re.compile(r"^\s*#\s*version\b")
# Mesa/llvmpipe: "0:12(5): error: ..."; NVIDIA: "0(12) : error ..."; both carry the file id first.
_MESA_LOCATION = re.compile(r"(?m)^\s*(\d+):(\d+)\((\d+)\):\s*(.*)$")
_NVIDIA_LOCATION = re.compile(r"(?m)^\s*(\d+)\((\d+)\)\s*:\s*(.*)$")


class ShaderError(FacepuppetError, RuntimeError):
    """A shader file is missing, has an include cycle, or fails to compile or link."""


class _Source:
    """One stage's source being assembled, with the file table for #line ids."""

    def __init__(self, search_path: Path):
        self.search_path = search_path
        self.file_ids: dict[str, int] = {}
        self.lines: list[str] = []

    def file_id(self, name: str) -> int:
        return self.file_ids.setdefault(name, len(self.file_ids))

    def names_by_id(self) -> dict[int, str]:
        return {i: n for n, i in self.file_ids.items()}


def _shader_root(search_path) -> Path:
    if search_path is not None:
        return Path(search_path)
    return Path(str(files("facepuppet.shaders")))


def _read(root: Path, name: str, included_from: str | None = None) -> list[str]:
    path = root / name
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        where = f" (included from {included_from})" if included_from else ""
        raise ShaderError(f"shader file {name!r} not found in {root}{where}") from None


def _expand(src: _Source, name: str, stack: tuple[str, ...], lines: list[str] | None = None) -> None:
    """Append ``name``'s lines to ``src.lines`` with includes expanded and #line directives."""
    if name in stack:
        chain = " -> ".join(stack + (name,))
        raise ShaderError(f"include cycle in shaders: {chain}")
    if lines is None:
        lines = _read(src.search_path, name, stack[-1] if stack else None)
    fid = src.file_id(name)
    src.lines.append(f"#line 1 {fid}")
    for number, line in enumerate(lines, start=1):
        match = _INCLUDE.match(line)
        if match:
            _expand(src, match.group(1), stack + (name,))
            src.lines.append(f"#line {number + 1} {fid}")
        elif _VERSION.match(line):
            src.lines.append("")  # the version line was hoisted to the top
        else:
            src.lines.append(line)


def preprocess(
    name: str, stage: str, defines: Mapping[str, object] | None = None,
    search_path: str | os.PathLike | None = None,
) -> tuple[str, dict[int, str]]:
    """Source of one stage of a program file.

    Parameters
    ----------
    name : str, file name under the shader directory, e.g. "face.glsl"
    stage : str, "VERTEX_SHADER" or "FRAGMENT_SHADER" (defined for the stage)
    defines : mapping of str to value, each written as ``#define KEY VALUE``
    search_path : path-like or None; default the ``facepuppet.shaders`` package

    Returns
    -------
    source : str
    file_names : dict of int file id -> file name, for mapping error messages
    """
    root = _shader_root(search_path)
    lines = _read(root, name)
    version = next((ln.strip() for ln in lines if _VERSION.match(ln)), DEFAULT_VERSION)
    src = _Source(root)
    header = [version, f"#define {stage} 1"]
    for key, value in (defines or {}).items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", str(key)):
            raise ShaderError(f"define name {key!r} for {name} is not a GLSL identifier")
        header.append(f"#define {key} {value}")
    src.lines = header
    _expand(src, name, (), lines)
    return "\n".join(src.lines) + "\n", src.names_by_id()


def _locate(log: str, file_names: dict[int, str]) -> str:
    """Rewrite ``ID:LINE(COL)`` locations of a driver log as ``file:LINE:COL``."""
    out = []
    for raw in log.strip().splitlines():
        m = _MESA_LOCATION.match(raw)
        if m:
            fid, line, col, text = int(m.group(1)), m.group(2), m.group(3), m.group(4)
            out.append(f"{file_names.get(fid, f'<file {fid}>')}:{line}:{col}: {text}")
            continue
        m = _NVIDIA_LOCATION.match(raw)
        if m:
            fid, line, text = int(m.group(1)), m.group(2), m.group(3)
            out.append(f"{file_names.get(fid, f'<file {fid}>')}:{line}: {text}")
            continue
        out.append(raw)
    return "\n".join(out)


def load_program(
    ctx: moderngl.Context,
    name: str,
    defines: Mapping[str, object] | None = None,
    search_path: str | os.PathLike | None = None,
    varyings: tuple[str, ...] = (),
) -> moderngl.Program:
    """Compile and link the program in shader file ``name``.

    Parameters
    ----------
    ctx : moderngl.Context
    name : str, e.g. "face.glsl"
    defines : mapping or None, injected as ``#define KEY VALUE`` in both stages
    search_path : path-like or None; default the installed ``facepuppet.shaders`` package
    varyings : tuple of str, transform-feedback outputs (tests read deformed vertices back)

    Raises
    ------
    ShaderError
        The file or an include is missing, includes form a cycle, or the
        driver rejects the source; the message names the file and line.
    """
    vertex, file_names = preprocess(name, "VERTEX_SHADER", defines, search_path)
    fragment, _ = preprocess(name, "FRAGMENT_SHADER", defines, search_path)
    try:
        return ctx.program(
            vertex_shader=vertex,
            fragment_shader=None if varyings else fragment,
            varyings=varyings,
        )
    except moderngl.Error as exc:
        # Both stages expand the same includes in the same order, so file ids agree.
        raise ShaderError(f"shader {name} failed to build:\n{_locate(str(exc), file_names)}") from None
