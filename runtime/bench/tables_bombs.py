"""``facepuppet bench tables``: peak memory of refusing forged tables files, and the forgeries themselves.

Each forgery is built from a small, real tables file by rewriting members of
its archive; the big ones are streamed through the zip writer, so building a
file that inflates to gigabytes costs a few megabytes of memory. The tests
(``tests/runtime/test_tables_limits.py``) use the same builders.

The benchmark loads each forgery in a child process (so one's peak does not
hide another's) and reports the child's peak RSS and what it said.
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from facepuppet.runtime.bench.registry import register_bench

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


_CHILD = """
import resource, sys
import facepuppet.runtime.model.character  # registers the kind
from facepuppet.runtime.files.tables import load_tables
try:
    load_tables(sys.argv[1], "character")
    said = "loaded"
except Exception as exc:
    said = f"{type(exc).__name__}: {exc}"
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
print(said)
"""


def _load_in_child(path: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True, check=False)
    lines = done.stdout.splitlines()
    if done.returncode != 0 or len(lines) < 2:
        return {"error": done.stderr[-500:]}
    return {"peak_rss_mb": float(lines[0]), "said": lines[1][:300], "file_bytes": path.stat().st_size}


def bench_tables(args: argparse.Namespace) -> dict:
    """Forge a section bomb and a padded manifest from ``args.character``; load each in a child process."""
    src = Path(args.character)
    n_bytes = int(args.inflate_mb * 1e6)
    results = {"inflate_bytes": n_bytes, "source": str(src), "baseline": _load_in_child(src)}
    with tempfile.TemporaryDirectory() as tmp:
        section = sorted(read_manifest(src)["sections"])[-1]
        cases = {
            "section_bomb": lambda p: inflating_section(src, p, section, n_bytes),
            "consistent_section_bomb": lambda p: inflating_section(src, p, section, n_bytes, consistent=True),
            "padded_manifest": lambda p: padded_manifest(src, p, n_bytes),
        }
        for name, build in cases.items():
            path = build(Path(tmp) / f"{name}.npz")
            results[name] = _load_in_child(path)
            path.unlink()
            print(f"{name:24s} {results[name].get('peak_rss_mb', float('nan')):8.1f} MB peak RSS  "
                  f"{results[name].get('said', results[name].get('error', ''))[:100]}")
    return results


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-c", "--character", required=True, help="a small character .npz to forge from")
    parser.add_argument("--inflate-mb", type=float, default=2100.0,
                        help="how far each forgery inflates, MB (default 2100: the issue's 2 MB bomb)")


register_bench("tables", bench_tables, "peak memory of refusing forged tables files (zip bombs, padded manifests)",
               _add_arguments)
