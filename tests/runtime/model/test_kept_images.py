"""The image files a character keeps whole: saved and loaded byte for byte, bounded per image and in all.

The forged tables are written from a real saved character by the tables bomb helpers (the members replaced
by a header and zeros, deflated as they are written); the refusal of a section past its bound comes before
its bytes are allocated, which tracemalloc's peak shows.
"""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.bench.tables_bombs import MANIFEST, copy_with, manifest_member, npy_header, read_manifest
from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.kept_images import MAX_IMAGE_BYTES, MAX_TOTAL_BYTES, KeptImages

V1 = Path(__file__).resolve().parents[1] / "files" / "data" / "tables_v1" / "character.npz"


def with_kept(tmp_path: Path, images: list[bytes]) -> Path:
    c = Character.load(V1).with_parts(kept_images=KeptImages.of(images))
    return c.save(tmp_path / "kept.npz")


def test_kept_images_save_and_load_byte_for_byte(tmp_path):
    rng = np.random.default_rng(3)
    images = [rng.integers(0, 256, 5000, dtype=np.uint8).tobytes(), b"", b"\x89PNG\r\n\x1a\nsmall"]
    back = Character.load(with_kept(tmp_path, images))
    assert [back.kept_images.image(i) for i in range(len(back.kept_images))] == images
    assert Character.load(V1).kept_images is None  # a character without them has neither section


def forged(tmp_path: Path, offsets: list[int]) -> Path:
    """A saved character whose kept images are ``offsets[-1]`` zero bytes cut at ``offsets``, consistently
    declared in its manifest (as a careful forger would)."""
    src = with_kept(tmp_path, [b"x"])
    n = offsets[-1]
    manifest = read_manifest(src)
    manifest["sections"]["kept_image_bytes"]["shape"] = [n]
    manifest["sections"]["kept_image_offsets"]["shape"] = [len(offsets)]
    manifest["dims"]["n_kept_bytes"], manifest["dims"]["n_kept_images"] = n, len(offsets) - 1
    off = np.asarray(offsets, np.int64)
    return copy_with(src, tmp_path / "forged.npz", {
        MANIFEST: manifest_member(json.dumps(manifest).encode()),
        "kept_image_offsets.npy": npy_header(off.shape, "int64") + off.tobytes(),
        "kept_image_bytes.npy": (npy_header((n,), "uint8"), n)})


def test_kept_images_past_the_total_bound_are_refused_before_they_are_read(tmp_path):
    path = forged(tmp_path, [0, MAX_IMAGE_BYTES, MAX_TOTAL_BYTES + 1])
    assert path.stat().st_size < MAX_TOTAL_BYTES // 100
    tracemalloc.start()
    try:
        with pytest.raises(TablesError, match=r"forged\.npz: kept_image_bytes: .*more than the limit of "
                                              rf"{MAX_TOTAL_BYTES} bytes"):
            Character.load(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20, f"the loader held {peak} bytes for a refused file"


def test_a_kept_image_past_its_bound_is_refused_naming_the_field(tmp_path):
    path = forged(tmp_path, [0, 16, MAX_IMAGE_BYTES + 17])
    with pytest.raises(TablesError, match=rf"forged\.npz: kept_image_offsets: kept image 1 is {MAX_IMAGE_BYTES + 1} "
                                          rf"bytes, more than the limit of {MAX_IMAGE_BYTES} bytes per image"):
        Character.load(path)


def test_offsets_that_do_not_cut_the_bytes_are_refused(tmp_path):
    path = forged(tmp_path, [0, 40, 30])
    with pytest.raises(TablesError, match=r"forged\.npz: kept_image_offsets: must start at 0, never decrease"):
        Character.load(path)


def test_kept_images_past_the_bounds_are_refused_in_memory():
    with pytest.raises(TablesError, match=r"kept_image_offsets: kept image 0 is .* per image"):
        KeptImages.of([bytes(MAX_IMAGE_BYTES + 1)])
