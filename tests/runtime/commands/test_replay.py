"""Replay through the real frame loop and the real FaceRenderer on EGL: determinism and the command."""

from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.commands.options import parse_size
from facepuppet.runtime.commands.replay import register
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.live.loop import FrameLoop, RecordedClock
from facepuppet.runtime.live.sinks import PngSink, WeightLog
from facepuppet.runtime.model.character import Character, sparse_deltas
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv
from facepuppet.runtime.recording.replay_source import ReplaySource
from facepuppet.runtime.recording.session import SessionWriter

from conftest import need_shared
from helpers.logs import logged

MYSLATE = ("tracker", "livelinkface_myslate_3.csv")
N_TICKS = 30
W, H = 320, 240


def _replay(ctx, character, frames, out_dir, path):
    from facepuppet.runtime.render.renderer import FaceRenderer

    renderer = FaceRenderer(ctx, character, W, H, path=path, log=lambda s: None)
    weights, messages = WeightLog(), []
    loop = FrameLoop(character.shape_names, renderer, RecordedClock(), observers=[weights, PngSink(out_dir)],
                     log=messages.append)
    result = loop.run(ReplaySource(frames), duration=(N_TICKS - 1) / 60)
    renderer.close()
    assert ctx.error == "GL_NO_ERROR"
    return weights, result, messages


def _pngs(out_dir):
    return [p.read_bytes() for p in sorted(out_dir.glob("frame_*.png"))]


@pytest.mark.slow
@pytest.mark.parametrize("path", ["gpu", "cpu"])
def test_replaying_twice_gives_bit_identical_weights_and_images(egl_ctx, ict_character, tmp_path, path):
    csv_path = need_shared(*MYSLATE)
    frames = read_llf_csv(csv_path)
    w1, r1, messages = _replay(egl_ctx, ict_character, frames, tmp_path / "a", path)
    w2, r2, _ = _replay(egl_ctx, ict_character, frames, tmp_path / "b", path)
    assert r1.n_ticks == r2.n_ticks == N_TICKS and r1.counters == r2.counters
    assert w1.array.tobytes() == w2.array.tobytes()
    png1, png2 = _pngs(tmp_path / "a"), _pngs(tmp_path / "b")
    assert len(png1) == N_TICKS and png1 == png2
    # The rig's jawOpen follows the CSV's JawOpen column (read here by header name): tick k shows the
    # newest row with t <= k/60, or the previous one when none arrived.
    with open(csv_path, newline="") as f:
        jaw = np.array([r["JawOpen"] for r in csv.DictReader(f)], dtype=np.float32)
    times = np.array([fr.t for fr in frames])
    rows = np.searchsorted(times, np.arange(N_TICKS) / 60, side="right") - 1
    jaw_col = ict_character.shape_names.index("jawOpen")
    np.testing.assert_array_equal(w1.array[:, jaw_col], jaw[rows])
    # Something is drawn and it moves: the face is not the background, and frames differ.
    first = np.asarray(Image.open(tmp_path / "a" / "frame_00000.png"))
    last = np.asarray(Image.open(tmp_path / "a" / f"frame_{N_TICKS - 1:05d}.png"))
    assert first.shape == (H, W, 3) and len(np.unique(first.reshape(-1, 3), axis=0)) > 50
    assert np.any(first != last)
    # Channels the ICT rig lacks are reported once, by name.
    assert len(messages) == 1 and "TongueOut" in messages[0]


def _tiny_character() -> Character:
    """A curved 20x20 grid facing +z (cm) with two shapes; small enough to keep the command test fast."""
    n = 20
    u, v = np.meshgrid(np.linspace(-5, 5, n), np.linspace(-5, 5, n))
    verts = np.c_[u.ravel(), v.ravel(), (3.0 - 0.05 * (u**2 + v**2)).ravel()].astype(np.float32)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.r_[np.c_[a, b, d], np.c_[a, d, c]].astype(np.uint32)
    dense = np.zeros((2, len(verts), 3), np.float32)
    dense[0, verts[:, 1] < 0, 1] = -3.0  # jawOpen: the lower half drops
    dense[1, (verts[:, 1] > 0) & (verts[:, 0] > 0), 2] = 2.0  # eyeBlink_L
    offsets, indices, positions = sparse_deltas(dense)
    return Character(
        name="tiny", units="cm", vertices=verts, triangles=tris, triangle_material=np.zeros(len(tris), np.uint16),
        vertex_color=np.full((len(verts), 3), 0.6, np.float32), material_names=("skin",),
        material_params=np.array([[0.2, 16.0, 0.0, 0.0]], np.float32), pivot=np.zeros(3, np.float32),
        shape_names=("jawOpen", "eyeBlink_L"), delta_offsets=offsets, delta_indices=indices,
        delta_positions=positions, delta_normals=np.zeros_like(positions),
    )


def _command(argv):
    parser = argparse.ArgumentParser(prog="facepuppet")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.mark.data
def test_replay_command_headless_writes_pngs_and_a_session_replays_like_its_csv(egl_ctx, tmp_path, capsys):
    csv_path = need_shared(*MYSLATE)
    char_path = _tiny_character().save(tmp_path / "tiny.npz")
    # the same frames, recorded into a session file
    session_path = tmp_path / "take.fps"
    with SessionWriter(session_path) as w:
        for f in read_llf_csv(csv_path):
            w.write_frame(f)
    for name, rec in (("csv", csv_path), ("session", session_path)):
        with logged() as lines:
            rc = _command(["replay", str(rec), "-c", str(char_path), "--headless", "--out", str(tmp_path / name),
                           "--size", "160x120", "--duration", "0.25", "--path", "cpu", "--stats"])
        assert rc == 0
        out = "\n".join(lines)
        assert out.count("channel map (livelinkface_csv)") == 1 and "TongueOut" in out
        assert "16 ticks at 59.94 fps" in out and "gpu_finish" in out  # the take's own rate (NTSC 60)
    assert _pngs(tmp_path / "csv") == _pngs(tmp_path / "session") and len(_pngs(tmp_path / "csv")) == 16


def test_replay_command_rejects_what_it_cannot_play(tmp_path):
    bogus = tmp_path / "notes.txt"
    bogus.write_text("hello\n")
    char_path = _tiny_character().save(tmp_path / "tiny.npz")
    with pytest.raises(ValueError, match="notes.txt: not a recording"):
        _command(["replay", str(bogus), "-c", str(char_path), "--headless"])
    with pytest.raises(ValueError, match="--size: expected WIDTHxHEIGHT"):
        parse_size("1280by720")
    assert parse_size("320x240") == (320, 240)


@pytest.mark.gl
def test_replay_stats_json_is_strict_json(egl_ctx, tmp_path, capsys):
    """``replay --stats`` prints its counters and timings as JSON that a strict parser reads (no NaN)."""
    char_path = _tiny_character().save(tmp_path / "tiny.npz")
    session_path = tmp_path / "take.fps"
    with SessionWriter(session_path) as w:
        for k in range(5):
            w.write_frame(Frame(t=k / 60, source="test", channels=("jawOpen",),
                                weights=np.array([0.1 * k], np.float32)))
    assert _command(["replay", str(session_path), "-c", str(char_path), "--headless", "--size", "32x24",
                     "--stats"]) == 0

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    line = next(s for s in capsys.readouterr().out.splitlines() if s.startswith("{"))
    stats = json.loads(line, parse_constant=refuse)
    assert stats["n_ticks"] > 0 and "timings_ms" in stats
