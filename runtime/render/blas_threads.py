"""Limit the OpenBLAS libraries already loaded in this process to a number of threads.

Why the live loop needs it: the CPU deformation path sums blendshape deltas
with BLAS ``saxpy`` (:mod:`~facepuppet.runtime.render.cpu_deform`), and OpenBLAS splits a
long ``saxpy`` across its worker threads. On a 2-core machine where Mesa's
llvmpipe rasteriser threads, the UDP receiver and the tracker already compete
for the cores, those workers wait on each other: the same deformation that
takes ~2 ms took 100-600 ms now and then (measured: p99 460 ms over 40 calls
under load with the default thread count, 4.8 ms with one thread).

No dependency: the libraries are found in ``/proc/self/maps`` (Linux) and
their own ``*openblas*_set_num_threads`` entry points are called through
:mod:`ctypes` (NumPy and SciPy wheels each bundle one, with prefixed and
suffixed symbol names). Anywhere this cannot work (another OS, another BLAS)
it does nothing and says so in its return value; it never raises.
"""

from __future__ import annotations

import ctypes

_SET = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads64_",
        "openblas_set_num_threads")
_GET = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
        "openblas_get_num_threads")


def _loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS shared libraries mapped into this process (Linux; [] elsewhere)."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line.lower() and "/" in line}
    except OSError:
        return []
    return sorted(p for p in paths if ".so" in p)


def _entry(lib, names):
    for name in names:
        try:
            return getattr(lib, name)
        except AttributeError:
            continue
    return None


class BlasThreads:
    """Context manager: every loaded OpenBLAS runs ``n`` threads inside the block, as before after it.

    Parameters
    ----------
    n : int, threads per library (1 for the live loop)

    Attributes
    ----------
    limited : list of str, the libraries whose thread count was set (empty when none was found)
    """

    def __init__(self, n: int = 1) -> None:
        if int(n) < 1:
            raise ValueError(f"BlasThreads n: expected a positive thread count, got {n!r}")
        self.n = int(n)
        self.limited: list[str] = []
        self._restore: list[tuple] = []

    def __enter__(self) -> BlasThreads:
        for path in _loaded_openblas():
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            set_threads, get_threads = _entry(lib, _SET), _entry(lib, _GET)
            if set_threads is None or get_threads is None:
                continue
            get_threads.restype = ctypes.c_int
            set_threads.argtypes = [ctypes.c_int]
            before = int(get_threads())
            set_threads(self.n)
            self._restore.append((set_threads, before))
            self.limited.append(path.rsplit("/", 1)[-1])
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Give each library its thread count from before :meth:`__enter__` (idempotent)."""
        for set_threads, before in reversed(self._restore):
            set_threads(before)
        self._restore.clear()
