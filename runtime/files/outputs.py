"""One policy for what a command writes: refuse what exists, check first, write atomically.

Every command's output options (``-o/--output``, ``--record``, ``--dump-weights``,
``--json``, ``--save-controls``, ``--gestures-out``, ``--video``: files; ``--out``, ``--pictures``:
folders) follow the same rules:

* an existing output file, or an existing non-empty output folder, is refused
  with a message naming the option and ``--force``, before any work is done
  (:func:`check_outputs`, called by ``cli.main`` for every command, so a command
  that runs for a minute fails in its first millisecond instead);
* an output whose folder does not exist, that is a folder where a file is
  expected (or the reverse), or that two options name alike, is refused the same way;
* files are written atomically: into a temporary file in the same folder, then
  ``os.replace`` (:func:`atomic_path`, :class:`OutputSet` for a command with
  several outputs: all are renamed into place only once every one is written,
  so a failure leaves none of them half-written or alone);
* what is sent rather than written (``--vmc-out``, ``--llf-out``, ``--events-out``, ``--stream``,
  ``--virtual-camera``: :data:`SENT_OUTPUTS`) has no file to refuse; its option group checks it;
* ``run --record`` is the exception to atomic writing: a recording is appended as
  the run goes so that a crash keeps what was recorded; it is still refused
  when it exists, unless ``--force``.

A command with outputs the options do not name (``clone-elastic`` writes a
character beside its elastic table) declares them with
``parser.set_defaults(derived_outputs=lambda args: [...])``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from facepuppet.runtime.errors import FacepuppetError

#: option dest -> what it names
OUTPUT_OPTIONS: dict[str, str] = {
    "output": "file", "record": "file", "dump_weights": "file", "json": "file", "save_controls": "file",
    "gestures_out": "file", "video": "file", "out": "dir", "pictures": "dir",
}


#: option dest -> where it goes, for the outputs that are not files: nothing on disk to refuse or write
#: atomically; each is checked by its own option group before any work (an address, a URL, a device) and none
#: of them listens (run's inputs listen, on 127.0.0.1 unless --listen names another address)
SENT_OUTPUTS: dict[str, str] = {
    "vmc_out": "udp", "llf_out": "udp", "events_out": "udp", "stream": "url (udp://, srt://)",
    "virtual_camera": "device (v4l2loopback)",
}


class OutputError(FacepuppetError, ValueError):
    """An output a command was asked to write cannot be written as asked (exists, no folder, ...)."""


def output_actions(parser: argparse.ArgumentParser) -> list[tuple[str, str, str]]:
    """(dest, kind, option string) of each output option of ``parser``."""
    found = []
    for action in parser._actions:
        kind = OUTPUT_OPTIONS.get(action.dest)
        if kind is not None and action.option_strings:
            found.append((action.dest, kind, max(action.option_strings, key=len)))
    return found


def add_output_policy(parser: argparse.ArgumentParser) -> None:
    """Give a command with output options ``--force`` and the list :func:`check_outputs` walks."""
    outputs = output_actions(parser)
    if not outputs:
        return
    if not any("--force" in a.option_strings for a in parser._actions):
        parser.add_argument("--force", action="store_true",
                            help="overwrite existing outputs (default: refuse them, before any work)")
    parser.set_defaults(outputs_=tuple(outputs))


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, each output of the parsed command that cannot be written as asked.

    Raises
    ------
    OutputError
        naming the option and path: exists (pass --force), its folder is missing, a folder where a file
        goes (or the reverse), or two outputs are one path.
    """
    force = bool(getattr(args, "force", False))
    seen: dict[Path, str] = {}
    named = [(flag, kind, getattr(args, dest, None)) for dest, kind, flag in getattr(args, "outputs_", ())]
    derived = getattr(args, "derived_outputs", None)
    if derived is not None:
        named += [("(written beside -o)", "file", p) for p in derived(args)]
    for flag, kind, value in named:
        if value is None:
            continue
        path = Path(value)
        key = path.resolve()
        if key in seen:
            raise OutputError(f"{flag} {path}: the same path as {seen[key]}; give each output its own path")
        seen[key] = flag
        check_path(flag, kind, path, force)


def check_path(flag: str, kind: str, path: Path, force: bool) -> None:
    """Refuse one output ``path`` (``kind`` "file" or "dir") of option ``flag``; see :func:`check_outputs`."""
    if kind == "dir":
        if path.exists() and not path.is_dir():
            raise OutputError(f"{flag} {path}: exists and is not a folder")
        if path.is_dir() and any(path.iterdir()) and not force:
            raise OutputError(f"{flag} {path}: the folder exists and is not empty; pass --force to write into it "
                              "(files of the same names are replaced), or name a new folder")
        return
    if path.is_dir():
        raise OutputError(f"{flag} {path}: is a folder; name a file")
    parent = path.parent
    if not parent.is_dir():
        raise OutputError(f"{flag} {path}: the folder {parent} does not exist")
    if path.exists() and not force:
        raise OutputError(f"{flag} {path}: exists; pass --force to overwrite it (nothing was written)")
    if not os.access(parent, os.W_OK):
        raise OutputError(f"{flag} {path}: the folder {parent} is not writable")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()   # read once, at import: os.umask can only be read by setting it


def _temp_beside(path: Path) -> Path:
    """A new, empty temporary file in ``path``'s folder, with the same suffix (readers pick formats by it),
    with the permissions a plain ``open(path, "w")`` would give (mkstemp's are 0600)."""
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent or ".")
    os.close(fd)
    os.chmod(name, 0o666 & ~_UMASK)
    return Path(name)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Write a file atomically: yields a temporary path beside ``path``; on success it replaces ``path``.

    On an exception the temporary file is removed and ``path`` is left as it was.
    """
    final = Path(path)
    temp = _temp_beside(final)
    try:
        yield temp
        os.replace(temp, final)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temp.unlink()
        raise


class OutputSet:
    """Several outputs of one command, renamed into place together at the end (or none of them).

    ``path(final)`` gives the temporary path to write ``final`` to; leaving the ``with`` block normally
    renames every temporary file onto its final path; an exception removes them all.
    """

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []

    def path(self, final: str | os.PathLike) -> Path:
        final = Path(final)
        temp = _temp_beside(final)
        self._pending.append((temp, final))
        return temp

    def commit(self) -> None:
        for temp, final in self._pending:
            os.replace(temp, final)
        self._pending.clear()

    def abort(self) -> None:
        for temp, _ in self._pending:
            with contextlib.suppress(FileNotFoundError):
                temp.unlink()
        self._pending.clear()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type: type | None, *rest: object) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


def write_atomic(path: str | os.PathLike, write: Callable[[Path], object]) -> Path:
    """``write(temp_path)`` then rename onto ``path``; returns ``path``."""
    with atomic_path(path) as temp:
        write(temp)
    return Path(path)
