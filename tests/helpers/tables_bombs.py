"""Forged tables files that try to make the loader do unbounded work (for the tables tests and the bomb figure).

Each is built from a small, real tables file by rewriting members of its
archive; the big ones are streamed through the zip writer, so building a
file that inflates to gigabytes costs a few megabytes of memory.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

MANIFEST = "__manifest__.npy"


def npy_header(shape: tuple[int, ...], dtype: str) -> bytes:
    """The ``.npy`` header of an array of ``shape`` and ``dtype`` (what precedes its data)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                               "shape": shape})
    return buf.getvalue()


def read_manifest(path: Path) -> dict:
    with zipfile.ZipFile(path) as archive:
        raw = np.lib.format.read_array(io.BytesIO(archive.read(MANIFEST)), allow_pickle=False)
    return json.loads(raw.tobytes())


def manifest_member(text: bytes) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.frombuffer(text, np.uint8))
    return buf.getvalue()


def copy_with(src: Path, dst: Path, replace: dict[str, bytes | tuple[bytes, int]]) -> Path:
    """Copy a tables archive, replacing members: ``{member: bytes}`` or ``{member: (header, n_zero_bytes)}``.

    A ``(header, n)`` member is the header followed by ``n`` zero bytes,
    deflated as it is written (a zip bomb when ``n`` is large).
    """
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.namelist():
            new = replace.get(item, zin.read(item))
            if isinstance(new, tuple):
                header, n_zeros = new
                zeros = bytes(1 << 20)
                with zout.open(item, "w", force_zip64=True) as member:
                    member.write(header)
                    left = n_zeros
                    while left > 0:
                        member.write(zeros[:min(left, len(zeros))])
                        left -= len(zeros)
            else:
                zout.writestr(item, new)
    return dst


def inflating_section(src: Path, dst: Path, section: str, n_bytes: int, *, consistent: bool = False) -> Path:
    """``section`` replaced by ``n_bytes`` of zeros (float32) whose ``.npy`` header says so.

    ``consistent``: the manifest is rewritten to declare the big shape too, as a
    careful forger would; otherwise it keeps the small shape it had.
    """
    shape = (n_bytes // 4,)
    replace: dict[str, bytes | tuple[bytes, int]] = {f"{section}.npy": (npy_header(shape, "float32"), shape[0] * 4)}
    if consistent:
        manifest = read_manifest(src)
        manifest["sections"][section] = {"shape": list(shape), "dtype": "float32",
                                         "kind": manifest["sections"][section].get("kind", "")}
        replace[MANIFEST] = manifest_member(json.dumps(manifest).encode())
    return copy_with(src, dst, replace)


def padded_manifest(src: Path, dst: Path, n_spaces: int) -> Path:
    """The manifest followed by ``n_spaces`` spaces (still valid JSON)."""
    text = json.dumps(read_manifest(src)).encode()
    header = npy_header((len(text) + n_spaces,), "uint8")
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.namelist():
            if item != MANIFEST:
                zout.writestr(item, zin.read(item))
                continue
            spaces = b" " * (1 << 20)
            with zout.open(item, "w", force_zip64=True) as member:
                member.write(header + text)
                left = n_spaces
                while left > 0:
                    member.write(spaces[:min(left, len(spaces))])
                    left -= len(spaces)
    return dst


def with_manifest(src: Path, dst: Path, manifest_text: bytes) -> Path:
    """The archive with its manifest replaced by ``manifest_text`` (any bytes)."""
    return copy_with(src, dst, {MANIFEST: manifest_member(manifest_text)})
