"""``facepuppet batch-compare`` as a real process (exit 0 / 1 / 2), and the job folders it refuses: a path
leading outside its folder, a weights file declaring a huge shape, manifest fields of the wrong kind."""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
from PIL import Image

from facepuppet.offline.batch.golden import compare_runs
from facepuppet.offline.batch.golden_jobs import JobFolderError
from helpers.batch_job_folders import edit_manifest, replay_job, write_take
from helpers.small_characters import sphere_character

pytestmark = [pytest.mark.gl, pytest.mark.slow]   # one headless replay, and the command's processes


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    root = tmp_path_factory.mktemp("golden_command")
    character = sphere_character().save(root / "sphere.npz")
    take = write_take(root / "take.fps", {"jawOpen": 0.8, "puff": 0.5})
    replay_job(root / "golden", "take-sphere", take, character)
    return root / "golden"


@pytest.fixture
def new(golden, tmp_path):
    """A copy of the golden run, to change."""
    shutil.copytree(golden, tmp_path / "new")
    return tmp_path / "new"


def batch_compare(*args):
    return subprocess.run([sys.executable, "-m", "facepuppet", "batch-compare", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_the_exit_code_says_whether_anything_changed(golden, new, tmp_path):
    same = batch_compare(new, golden)
    assert same.returncode == 0, same.stderr
    assert "batch-compare: 1 job, 0 changed beyond tolerance" in same.stdout
    frame = new / "take-sphere" / "frames" / "frame_00004.png"
    pixels = np.asarray(Image.open(frame).convert("RGB")).copy()
    pixels[20:40, 20:40] = (0, 255, 0)
    Image.fromarray(pixels).save(frame)
    changed = batch_compare(new, golden, "--out", tmp_path / "report")
    assert changed.returncode == 1, changed.stderr
    assert "take-sphere: frame 4: 9.77% of pixels over the level" in changed.stdout   # 400 of 64 x 64
    assert (tmp_path / "report" / "report.md").is_file()
    assert (tmp_path / "report" / "thumbs" / "0001_take-sphere_frame_00004.png").is_file()
    loose = batch_compare(new, golden, "--pixel-tol", "0.1")
    assert loose.returncode == 0, loose.stdout


def test_a_manifest_path_leading_outside_its_folder_is_refused_with_exit_2(new, tmp_path):
    np.save(tmp_path / "elsewhere.npy", np.zeros((12, 2), np.float32))   # a real file: only the place is wrong
    edit_manifest(new / "take-sphere", outputs={"weights": "../../elsewhere.npy"})
    result = batch_compare(new, new)
    assert result.returncode == 2 and result.stdout == ""
    assert "take-sphere/manifest.json: field outputs.weights: '../../elsewhere.npy' leads outside the job " \
           "folder" in result.stderr


def test_a_weights_file_declaring_a_huge_shape_is_refused_before_loading(new):
    path = new / "take-sphere" / "weights.npy"
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (2**40, 2)})
        f.write(b"\0" * 64)
    result = batch_compare(new, new)
    assert result.returncode == 2
    assert "take-sphere/weights.npy (outputs.weights): declares shape (1099511627776, 2)" in result.stderr


@pytest.mark.parametrize("outputs, message", [
    ({"frames": ["/etc/hostname"]}, r"field outputs.frames\[0\]: '/etc/hostname' is not a path relative"),
    ({"frames": ["frames/../../../x.png"]}, r"field outputs.frames\[0\]: .* leads outside the job folder"),
    ({"weights": "nothing.npy"}, r"field outputs.weights: 'nothing.npy' names no file in the job folder"),
    ({"weights": 3}, r"field outputs.weights: expected a string, found a number"),
    ({"frame_times": [0.0, "x"]}, r"field outputs.frame_times\[1\]: expected a finite number"),
])
def test_manifest_outputs_are_checked_naming_the_field(new, outputs, message):
    edit_manifest(new / "take-sphere", outputs=outputs)
    with pytest.raises(JobFolderError, match=r"take-sphere/manifest.json: " + message):
        compare_runs(new, new)


@pytest.mark.parametrize("fields, message", [
    ({"format": "other"}, r"field format: expected 'facepuppet-batch-job'"),
    ({"version": 2}, r"field version: expected 1"),
    ({"job": "another"}, r"field job: expected the folder's name 'take-sphere'"),
    ({"channels": "jawOpen"}, r"field channels: expected a list, found a string"),
    ({"channels": ["jawOpen", "jawOpen"]}, r"field channels: names a channel twice"),
    ({"inputs": {"take.fps": "abc"}}, r"field inputs\[.take.fps.\]: expected a sha256 digest"),
    ({"path": "vulkan"}, r"field path: expected one of cpu, gpu"),
])
def test_manifest_fields_are_checked_naming_the_field(new, fields, message):
    edit_manifest(new / "take-sphere", **fields)
    with pytest.raises(JobFolderError, match=r"take-sphere/manifest.json: " + message):
        compare_runs(new, new)


def test_links_leading_outside_are_refused(new, tmp_path):
    outside = tmp_path / "outside"
    shutil.copytree(new / "take-sphere", outside)
    weights = new / "take-sphere" / "weights.npy"
    weights.unlink()
    os.symlink(outside / "weights.npy", weights)   # the manifest's name is fine; the file it reaches is not
    with pytest.raises(JobFolderError, match=r"field outputs.weights: 'weights.npy' leads outside the job folder"):
        compare_runs(new, new)
    weights.unlink()
    shutil.copy(outside / "weights.npy", weights)
    os.symlink(outside, new / "linked")
    with pytest.raises(JobFolderError, match=r"new/linked: the job folder leads outside .*new \(a link\)"):
        compare_runs(new, new)


def test_weights_that_do_not_match_the_manifest_are_refused(new):
    path = new / "take-sphere" / "weights.npy"
    np.save(path, np.zeros((12, 3), np.float32))
    with pytest.raises(JobFolderError, match=r"expected shape \(n_ticks, 2\) .* found \(12, 3\)"):
        compare_runs(new, new)
    np.save(path, np.zeros((12, 2), np.float64))
    with pytest.raises(JobFolderError, match=r"expected little-endian float32 in C order, found float64"):
        compare_runs(new, new)
    np.save(path, np.array([{"a": 1}], dtype=object))
    with pytest.raises(JobFolderError, match=r"expected little-endian float32 in C order, found object"):
        compare_runs(new, new)
    np.save(path, np.zeros((12, 2), np.float32))
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size - 8)
    with pytest.raises(JobFolderError, match=r"bytes, but its header declares"):
        compare_runs(new, new)


def test_a_bad_option_and_a_missing_run_exit_2(golden, tmp_path):
    bad = batch_compare(golden, golden, "--pixel-tol", "2")
    assert bad.returncode == 2 and "--pixel-tol 2.0: expected a fraction of the pixels, in [0, 1]" in bad.stderr
    missing = batch_compare(tmp_path / "nowhere", golden)
    assert missing.returncode == 2 and "nowhere: expected a folder of batch jobs, found nothing" in missing.stderr


def _png_declaring(width: int, height: int) -> bytes:
    """A PNG whose header declares ``width`` x ``height`` RGB pixels, with almost no data behind it."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))


def test_a_frame_declaring_too_many_pixels_is_refused_before_decoding(new):
    frame = new / "take-sphere" / "frames" / "frame_00003.png"
    frame.write_bytes(_png_declaring(100_000, 100_000))
    with pytest.raises(JobFolderError, match=r"frame_00003.png: 100000x100000 pixels; a frame is at most"):
        compare_runs(new, new)
    frame.write_bytes(b"not a png")
    with pytest.raises(JobFolderError, match=r"frame_00003.png: not a readable PNG"):
        compare_runs(new, new)
