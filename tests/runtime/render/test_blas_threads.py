"""BlasThreads: the loaded OpenBLAS libraries run n threads inside the block and their old count after."""

from __future__ import annotations

import ctypes

import pytest
import scipy.linalg.blas  # noqa: F401  (loads SciPy's OpenBLAS, as the CPU deformer does)

from facepuppet.runtime.render.blas_threads import BlasThreads


def thread_counts() -> dict[str, int]:
    """Each mapped OpenBLAS's own thread count, read through its get_num_threads symbol."""
    counts = {}
    with open("/proc/self/maps") as f:
        paths = {line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line}
    for path in paths:
        lib = ctypes.CDLL(path)
        for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                     "openblas_get_num_threads"):
            if hasattr(lib, name):
                counts[path.rsplit("/", 1)[-1]] = int(getattr(lib, name)())
                break
    return counts


def test_threads_limited_inside_and_restored_after():
    before = thread_counts()
    if not before:
        pytest.skip("no OpenBLAS mapped in this process (another BLAS build)")
    with BlasThreads(1) as limit:
        assert sorted(limit.limited) == sorted(before)
        assert thread_counts() == {name: 1 for name in before}
    assert thread_counts() == before
    limit.close()  # a second close changes nothing
    assert thread_counts() == before


def test_bad_count_is_refused():
    with pytest.raises(ValueError, match="positive thread count, got 0"):
        BlasThreads(0)
