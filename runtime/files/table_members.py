"""The arrays of a tables file read from its zip archive: decompressed in bounded chunks, sizes checked against
the manifest and a limit before anything is allocated, ``.npy`` headers parsed without ever unpickling.
"""

from __future__ import annotations

import math
import os
import zipfile
from typing import IO

import numpy as np

from facepuppet.runtime.files.tables_error import TablesError

READ_CHUNK = 1 << 20  # decompress members this much at a time


def member_stream(archive: zipfile.ZipFile, member: str, path: str | os.PathLike, field_name: str) -> IO[bytes]:
    """Open one archive member for streaming; TablesError on a damaged archive."""
    try:
        return archive.open(member)
    except Exception as exc:  # BadZipFile, NotImplementedError (encrypted/unknown method), OSError
        raise TablesError(path, field_name, f"cannot be read, the file is damaged ({exc})") from None


def read_exact(stream: IO[bytes], buffer: memoryview, path: str | os.PathLike, field_name: str) -> None:
    """Fill ``buffer`` from ``stream`` in chunks of at most READ_CHUNK bytes."""
    done = 0
    total = len(buffer)
    try:
        while done < total:
            got = stream.readinto(buffer[done:done + min(READ_CHUNK, total - done)])
            if not got:
                raise TablesError(path, field_name, f"ends after {done} of {total} bytes; truncated?")
            done += got
    except TablesError:
        raise
    except Exception as exc:  # zlib.error, BadZipFile (CRC), EOFError on garbled data
        raise TablesError(path, field_name, f"cannot be read, the file is damaged ({exc})") from None


def read_header(stream: IO[bytes], path: str | os.PathLike, field_name: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """The ``.npy`` header of a member: (shape, fortran order, dtype); never unpickles."""
    try:
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(stream)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(stream)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except Exception as exc:  # ValueError on a bad header, zlib.error on garbled data
        raise TablesError(path, field_name, f"is not a valid array ({exc})") from None
    if dtype.hasobject:
        raise TablesError(path, field_name, "holds pickled Python objects; tables files are never unpickled")
    return shape, fortran, dtype


def read_member(archive: zipfile.ZipFile, member: str, path: str | os.PathLike, field_name: str, *,
                limit: int, expect: tuple[list, str] | None = None) -> np.ndarray:
    """One member's array, decompressed in bounded chunks.

    ``expect`` is the (shape, dtype) the manifest declares: the member's
    header must agree before its data is read. ``limit`` bounds the bytes
    the array may hold. The zip entry's declared size must be the header
    plus the data, so a member that would inflate past it is refused unread.
    """
    declared = archive.getinfo(member).file_size
    if declared > limit + 4096:
        raise TablesError(path, field_name, f"declares {declared} bytes uncompressed, more than the "
                                            f"limit of {limit} bytes")
    with member_stream(archive, member, path, field_name) as stream:
        shape, fortran, dtype = read_header(stream, path, field_name)
        if expect is not None and (list(shape) != expect[0] or dtype.name != expect[1]):
            raise TablesError(path, field_name,
                              f"manifest says shape {expect[0]} dtype {expect[1]}, "
                              f"archive holds shape {list(shape)} dtype {dtype.name}")
        count = math.prod(shape)
        nbytes = count * dtype.itemsize
        if nbytes > limit:
            raise TablesError(path, field_name, f"shape {list(shape)} {dtype.name} is {nbytes} bytes, more than "
                                                f"the limit of {limit} bytes")
        header = stream.tell() if stream.seekable() else None
        if header is not None and declared != header + nbytes:
            raise TablesError(path, field_name, f"the archive entry holds {declared} bytes, but a {list(shape)} "
                                                f"{dtype.name} array needs {header + nbytes}")
        arr = np.empty(count, dtype=dtype)
        read_exact(stream, memoryview(arr.view(np.uint8).reshape(-1)), path, field_name)
        try:
            if stream.read(1):
                raise TablesError(path, field_name, "holds more bytes than its array")
        except TablesError:
            raise
        except Exception as exc:  # CRC check at the end of the entry
            raise TablesError(path, field_name, f"cannot be read, the file is damaged ({exc})") from None
    if fortran:
        return arr.reshape(shape[::-1]).transpose()
    return arr.reshape(shape)
