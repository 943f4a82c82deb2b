"""The glTF path under fuzz: each file read by the importer and checked by ``check_gltf``; the forged hostile files
run in a child process that a hang or a memory bomb cannot take the test run with.

``read_and_check(path)`` is a reader for :func:`helpers.file_fuzz.check_reader`:
``check_gltf`` must return its list of problems and never raise, then
``read_gltf`` may read the file or refuse it with the project's error naming
it. ``forged_findings(cases, folder)`` forges each case of
:mod:`facepuppet.offline.io.gltf_bombs` and runs it in a child process where
the importer must *refuse* it (a FacepuppetError naming the file) and
``check_gltf`` must return at least one problem, and neither may open a file outside the model's
folder (an audit hook sees every file the child opens); the child's address space is capped and each case
has a deadline, so a case that still allocates gigabytes is reported as a
MemoryError and one that hangs as a hang (the child is then killed and a new
one takes the remaining cases).
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
import warnings
from pathlib import Path

from facepuppet.runtime.errors import FacepuppetError

from facepuppet.offline.io import gltf_bombs
from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf_check import check_gltf

#: A case still unanswered after this long hangs (a guard, not a speed limit: the bench measures time).
CASE_DEADLINE_S = 60.0
#: Address space a child may add to what it holds after its imports (so a memory bomb fails fast, in the child).
CHILD_EXTRA_MB = 1024


class CheckGltfRaised(Exception):
    """``check_gltf`` raised (or returned something other than a list of problems) instead of listing them."""


def checked(path: Path) -> list[str]:
    """``check_gltf(path)``, which must return a list of strings whatever the file holds."""
    try:
        problems = check_gltf(path)
    except Exception as exc:  # noqa: BLE001 - re-raised as a finding naming check_gltf
        raise CheckGltfRaised(f"check_gltf raised {type(exc).__name__}: {str(exc)[:200]}") from exc
    if not (isinstance(problems, list) and all(isinstance(p, str) for p in problems)):
        raise CheckGltfRaised(f"check_gltf returned {type(problems).__name__}, not a list of problems")
    return problems


def read_and_check(path: Path) -> None:
    """The reader of the glTF fuzz: ``check_gltf`` lists (never raises), then ``read_gltf`` reads or refuses."""
    checked(path)
    read_gltf(path)


def outside(path: Path) -> set[str]:
    """The files a forged case at ``path`` (in ``<folder>/model/``) points at outside its model's folder: what no
    reader may open."""
    folder = path.parent.parent
    return {os.path.realpath(p) for p in (folder / "SECRET.bin", folder / "outside" / "secret.bin", "/etc/passwd",
                                          "/dev/zero")}


def refused_and_checked(path: Path, opened: list[str] | None = None) -> list[str]:
    """What is wrong with the two readers on a forged hostile file: the importer must refuse it with the
    project's error naming it; ``check_gltf`` must list the problems (one at least); no RuntimeWarning may
    leak; neither may open a file outside the model's folder (``opened``: the real paths of the files
    opened, filled by an audit hook)."""
    findings = []
    forbidden = outside(path)

    def opened_outside(reader: str) -> None:
        if opened is not None:
            findings.extend(f"{reader} opened {p}, outside the model's folder" for p in sorted(set(opened) & forbidden))
            opened.clear()

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if not checked(path):
                findings.append("check_gltf found no problem: it must say why the importer refuses the file")
        except CheckGltfRaised as exc:
            findings.append(str(exc))
        opened_outside("check_gltf")
        try:
            read_gltf(path)
            findings.append("read_gltf read it: not refused")
        except FacepuppetError as exc:
            if str(path) not in str(exc):
                findings.append(f"read_gltf refused without the path: {type(exc).__name__}: {str(exc)[:200]}")
        except Exception as exc:  # noqa: BLE001 - a finding
            findings.append(f"read_gltf raised {type(exc).__name__}: {str(exc)[:200]}")
        opened_outside("read_gltf")
    findings += [f"RuntimeWarning leaked: {w.message}" for w in caught if issubclass(w.category, RuntimeWarning)]
    return findings


_CHILD = """
import json, os, resource, sys
from pathlib import Path
from helpers.gltf_fuzz import refused_and_checked
opened = []

def audit(event, args):
    if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
        try:
            opened.append(os.path.realpath(args[0]))
        except (OSError, ValueError):
            pass

sys.addaudithook(audit)
with open("/proc/self/status") as status:
    held_kb = next(int(line.split()[1]) for line in status if line.startswith("VmSize:"))
limit = (held_kb + int(sys.argv[1]) * 1024) * 1024
resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
print("ready", flush=True)
for line in sys.stdin:
    name, path = json.loads(line)
    try:
        opened.clear()
        found = refused_and_checked(Path(path), opened)
    except BaseException as exc:  # what escaped both readers' checks (MemoryError in a C call, ...)
        found = [f"escaped: {type(exc).__name__}: {str(exc)[:200]}"]
    print(json.dumps([name, found]), flush=True)
"""


def _child() -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                        os.environ.get("PYTHONPATH", "")]))
    env.pop("FACEPUPPET_DEBUG", None)
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(CHILD_EXTRA_MB)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if child.stdout.readline().strip() != "ready":
        child.kill()
        raise RuntimeError(f"the fuzz child did not start: {child.stderr.read()[-500:]}")
    return child


def _answer(child: subprocess.Popen, deadline: float) -> str | None:
    """The child's next line, or None when it has said nothing by ``deadline`` (or has died)."""
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        ready, _, _ = select.select([child.stdout], [], [], left)
        if ready:
            line = child.stdout.readline()
            return line or None


def forged_findings(cases: list[str], folder: Path) -> dict[str, list[str]]:
    """{case: findings} for each forged case of :mod:`gltf_bombs` (forged under ``folder``), run in a child."""
    paths = {name: str(gltf_bombs.FORGERIES[name](folder / name)) for name in cases}
    out: dict[str, list[str]] = {}
    todo = list(cases)
    while todo:
        child = _child()
        try:
            try:
                child.stdin.write("".join(json.dumps([name, paths[name]]) + "\n" for name in todo))
                child.stdin.close()
            except BrokenPipeError:
                pass  # it died at once: the first case says so below
            while todo:
                name = todo[0]
                line = _answer(child, time.monotonic() + CASE_DEADLINE_S)
                if line is None:
                    state = "hangs" if child.poll() is None else f"killed the child (exit {child.poll()})"
                    out[name] = [f"{state}: no answer within {CASE_DEADLINE_S:g} s"]
                    todo.pop(0)
                    break  # a fresh child for the rest
                answered, found = json.loads(line)
                out[answered] = found
                todo.remove(answered)
        finally:
            child.kill()
            child.wait()
            child.stdout.close()
            child.stderr.close()
    return out
