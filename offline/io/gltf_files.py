"""The bytes of a glTF: the file given, and every buffer and image its URIs name, read under one set of rules.

An avatar is downloaded from strangers (VRoid Hub, Booth, Discord), so a ``.vrm`` / ``.glb`` / ``.gltf`` is
untrusted input. The importer (:mod:`.gltf_container`) and ``check-gltf`` (:mod:`.gltf_check`) read every byte
through here, so both refuse the same files with the same words:

* **Regular files only.** The file given and any file a URI names are opened non-blocking (opening a FIFO
  returns at once instead of waiting for a writer) and the opened descriptor is ``fstat``-ed: a FIFO, a
  device (``/dev/zero``), a socket or a folder is refused. What is checked is what is then read.
* **Sizes before reads.** From ``fstat``, before any byte is read: the file given holds at most
  :data:`MAX_FILE_BYTES`; a buffer's file holds at least its declared ``byteLength`` (which is at most
  :data:`MAX_FILE_BYTES`) and only that many bytes are read; an image file holds at most
  :data:`MAX_IMAGE_BYTES`.
* **Inside the model's folder.** A URI is a ``data:`` URI or a relative path: percent-decoded as UTF-8, it
  must not be absolute, carry a scheme or host (``http:``), hold a NUL byte or bytes that are not UTF-8.
  Symlinks and ``..`` are resolved, and the resolved file must lie inside the resolved folder of the glTF
  (a symlink inside the folder that points out of it is refused like ``../``): the importer must not read
  other files of the machine, nor reach the network.
* **Bounded ``data:`` URIs.** Only base64 is read; the decoded size follows from the text's length and is
  checked before decoding: at most the buffer's ``byteLength`` (and at least it), at most
  :data:`MAX_IMAGE_BYTES` for an image.

A refusal is a :class:`GltfError`: the glTF file, the JSON path of the field, the problem
(``avatar.gltf: buffers[0].uri: '../x.bin': the file must be inside the folder of the glTF (…)``).
"""

from __future__ import annotations

import base64
import binascii
import io
import os
import stat
import urllib.parse
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from facepuppet.runtime.errors import InputFileError

__all__ = ["GltfError", "MAX_FILE_BYTES", "MAX_IMAGE_BYTES", "Opened", "read_gltf_bytes", "read_buffer_uri",
           "open_image_uri"]

#: The largest glTF / GLB / VRM file read, and the largest buffer: a VRoid Studio avatar is 10-50 MB and the
#: heaviest avatars sold on Booth a few hundred MB; 1 GiB holds them all and is the character table's own
#: section cap (runtime/files/tables.MAX_SECTION_BYTES).
MAX_FILE_BYTES = 1 << 30
#: The largest image file or ``data:`` image read (compressed bytes): an 8192x8192 RGBA PNG of noise, the
#: worst a texture of the largest accepted size compresses to, is 268 MB.
MAX_IMAGE_BYTES = 272 << 20
_OPEN_FLAGS = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)  # not on Windows


class GltfError(InputFileError):
    """A glTF / GLB / VRM file cannot be read: the message names the file, the JSON field path and the problem."""

    def __init__(self, path: str | os.PathLike, where: str, problem: str) -> None:
        self.path, self.where, self.problem = str(path), where, problem
        super().__init__(f"{path}: {where}: {problem}" if where else f"{path}: {problem}")


@dataclass
class Opened:
    """An opened source of bytes: ``handle`` (binary, at offset 0), its ``size`` in bytes, the file read (None
    for a ``data:`` URI) and how messages name it (``"file 'a.png'"``, ``"the data URI"``)."""

    handle: BinaryIO
    size: int
    path: Path | None
    source: str

    def __enter__(self) -> Opened:
        return self

    def __exit__(self, *exc: object) -> None:
        self.handle.close()


def read_gltf_bytes(path: str | os.PathLike) -> bytes:
    """The bytes of the glTF / GLB / VRM file ``path``: a regular file of at most :data:`MAX_FILE_BYTES`.

    Raises FileNotFoundError when it is missing, :class:`GltfError` when it is not a regular file, is too large
    or cannot be read.
    """
    path = Path(path)
    try:
        fd = os.open(path, _OPEN_FLAGS)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: glTF file not found") from None
    except (OSError, ValueError) as exc:
        raise GltfError(path, "", f"cannot be opened ({_reason(exc)})") from None
    with _regular(fd, lambda problem: GltfError(path, "", problem)) as (handle, size):
        if size > MAX_FILE_BYTES:
            raise GltfError(path, "", f"{size} bytes, more than the {MAX_FILE_BYTES} a glTF file may have here")
        return _read_exactly(handle, size, lambda problem: GltfError(path, "", problem))


def read_buffer_uri(gltf_path: str | os.PathLike, uri: str, where: str, byte_length: int) -> tuple[bytes, Path | None]:
    """The ``byte_length`` bytes of buffer ``where`` (e.g. ``buffers[1]``) whose ``uri`` is given; the file read
    (None for a ``data:`` URI). The source must hold at least ``byte_length`` bytes (a ``data:`` URI exactly);
    refusals name ``where.uri`` or ``where.byteLength``."""
    gltf_path = Path(gltf_path)
    if not 1 <= byte_length <= MAX_FILE_BYTES:
        raise GltfError(gltf_path, f"{where}.byteLength",
                        f"{byte_length}: a buffer holds 1..{MAX_FILE_BYTES} bytes here")
    with _open_uri(gltf_path, uri, f"{where}.uri", byte_length, exact=True) as opened:
        if opened.size < byte_length:
            raise GltfError(gltf_path, f"{where}.byteLength",
                            f"{byte_length} bytes declared but {opened.source} has only {opened.size}")
        data = _read_exactly(opened.handle, byte_length, lambda p: GltfError(gltf_path, f"{where}.uri", p))
        return data, opened.path


def open_image_uri(gltf_path: str | os.PathLike, uri: str, where: str) -> Opened:
    """The image named by ``uri`` (field ``where``), opened, at most :data:`MAX_IMAGE_BYTES`; use it in a
    ``with``. Nothing is read yet from a file, so a reader can take just the image's header first."""
    return _open_uri(Path(gltf_path), uri, where, MAX_IMAGE_BYTES, exact=False)


def _open_uri(gltf_path: Path, uri: str, where: str, limit: int, *, exact: bool) -> Opened:
    """``uri`` opened under the module's rules; ``limit``: the most bytes it may hold (a file larger than that is
    refused unless ``exact``, where it is read only up to ``limit``; a ``data:`` URI never holds more)."""

    def refuse(problem: str) -> GltfError:
        return GltfError(gltf_path, where, problem)

    shown = _show(uri)
    if "\x00" in uri:
        raise refuse(f"{shown}: holds a NUL character, which no file name has")
    if uri.startswith("data:"):
        return _open_data_uri(uri, limit, refuse)
    parsed = urllib.parse.urlsplit(uri)
    if parsed.scheme or parsed.netloc:
        raise refuse(f"{shown}: only relative file names and data: URIs are read, not URLs")
    try:
        rel = urllib.parse.unquote(parsed.path, errors="strict")
        rel.encode("utf-8")
    except UnicodeError:
        raise refuse(f"{shown}: not a UTF-8 file name once its %-escapes are decoded") from None
    if "\x00" in rel:
        raise refuse(f"{shown}: holds a NUL character (%00), which no file name has")
    if not rel:
        raise refuse(f"{shown}: names no file")
    try:
        folder = gltf_path.resolve().parent
        target = (folder / rel).resolve()
    except (OSError, RuntimeError) as exc:  # RuntimeError: a symlink loop (Python < 3.13)
        raise refuse(f"{shown}: the path cannot be resolved ({_reason(exc)})") from None
    if Path(rel).is_absolute() or not target.is_relative_to(folder):
        raise refuse(f"{shown}: the file must be inside the folder of the glTF ({folder})")
    try:
        # the resolved path has no symlink left; O_NOFOLLOW keeps one from appearing there before the open
        fd = os.open(target, _OPEN_FLAGS | getattr(os, "O_NOFOLLOW", 0))
    except OSError as exc:
        raise refuse(f"{shown}: cannot read {target}: {_reason(exc)}") from None
    with _regular(fd, lambda problem: refuse(f"{shown}: {target} {problem}"), keep_open=True) as (handle, size):
        if size > limit and not exact:
            raise refuse(f"{shown}: {size} bytes, more than the {limit} read for one image")
    return Opened(handle, size, target, f"file {rel!r}")


def _open_data_uri(uri: str, limit: int, refuse) -> Opened:
    """A base64 ``data:`` URI decoded, its decoded size checked against ``limit`` from its length first."""
    head, sep, payload = uri.partition(",")
    if not sep or not head.endswith(";base64"):
        raise refuse("a data URI must be base64 (data:<type>;base64,<data>)")
    # base64 with validate=True has no whitespace: 4 characters per 3 bytes, less the '=' padding
    size = len(payload) // 4 * 3 - (2 if payload.endswith("==") else 1 if payload.endswith("=") else 0)
    if size > limit:
        raise refuse(f"a data URI of {size} bytes, more than the {limit} it may hold here")
    try:
        data = base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise refuse(f"not valid base64 ({exc})") from None
    return Opened(io.BytesIO(data), len(data), None, "the data URI")


@contextmanager
def _regular(fd: int, refuse, keep_open: bool = False) -> Iterator[tuple[BinaryIO, int]]:
    """(file object, size) of the opened descriptor ``fd``, refused (``refuse(problem)`` raised) unless it is a
    regular file; the file is closed when the block ends, or only when it raises if ``keep_open``."""
    try:
        mode = os.fstat(fd)
        if not stat.S_ISREG(mode.st_mode):   # checked on the descriptor: a folder cannot even be wrapped as a file
            raise refuse(f"is {_kind(mode.st_mode)}, not a regular file")
        handle = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    try:
        yield handle, mode.st_size
    except BaseException:
        handle.close()
        raise
    if not keep_open:
        handle.close()


def _read_exactly(handle: BinaryIO, n: int, refuse) -> bytes:
    """``n`` bytes from ``handle`` (a file that shrank while read is refused)."""
    try:
        data = handle.read(n)
    except OSError as exc:
        raise refuse(f"cannot be read ({_reason(exc)})") from None
    if len(data) < n:
        raise refuse(f"{len(data)} bytes read of the {n} expected (the file changed while read)")
    return data


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a plain file"


def _reason(exc: Exception) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)


def _show(uri: str) -> str:
    """``uri`` as messages quote it: repr, cut at 80 characters."""
    text = repr(uri)
    return text if len(text) <= 80 else text[:77] + "..."
