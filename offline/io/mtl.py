"""Wavefront MTL reader: the few material values the character shader uses."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from facepuppet.runtime.files.input_files import regular_file

from facepuppet.offline.io.obj import ObjError

__all__ = ["MtlMaterial", "read_mtl"]


@dataclass(frozen=True)
class MtlMaterial:
    """One ``newmtl`` block.

    Attributes
    ----------
    name : str
    diffuse : tuple of 3 float, ``Kd``, RGB 0..1
    specular : tuple of 3 float, ``Ks``, RGB 0..1
    shininess : float, ``Ns`` (Phong exponent)
    """

    name: str
    diffuse: tuple[float, float, float] = (0.8, 0.8, 0.8)
    specular: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shininess: float = 10.0


def read_mtl(path: str | os.PathLike) -> dict[str, MtlMaterial]:
    """Materials of an MTL file by name; ``Kd``, ``Ks`` and ``Ns`` are read, other statements ignored.

    Raises
    ------
    FileNotFoundError
        the file does not exist.
    ObjError
        a value that is not a finite number, or a value before any ``newmtl`` (naming file and line).
    """
    path = regular_file(path, "MTL file")
    text = path.read_text(encoding="utf-8", errors="replace")
    materials: dict[str, MtlMaterial] = {}
    current: dict | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        key, args = fields[0], fields[1:]
        if key == "newmtl":
            if current is not None:
                materials[current["name"]] = MtlMaterial(**current)
            current = {"name": " ".join(args) or f"material{len(materials)}"}
        elif key in ("Kd", "Ks", "Ns"):
            if current is None:
                raise ObjError(path, number, f"'{key}' before any 'newmtl'")
            values = _numbers(path, number, line, args)
            if key == "Ns":
                current["shininess"] = values[0]
            else:  # one number means grey
                rgb = tuple(values[:3]) if len(values) >= 3 else (values[0],) * 3
                current["diffuse" if key == "Kd" else "specular"] = rgb
    if current is not None:
        materials[current["name"]] = MtlMaterial(**current)
    return materials


def _numbers(path, number: int, line: str, args: list[str]) -> list[float]:
    try:
        values = [float(a) for a in args]
    except ValueError:
        values = []
    if not values or not all(math.isfinite(v) for v in values):
        raise ObjError(path, number, f"expected finite numbers: '{line.strip()}'")
    return values
