"""Long offline commands report progress through runtime.progress.Progress: a line with a count and an
estimate on a terminal, nothing of it when stderr is not one (their result lines stay)."""

from __future__ import annotations

import io
import sys

import numpy as np
import pytest

from facepuppet.runtime import cli


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _rig(tmp_path, n_shapes=5):
    grid = np.array([[x, y, 0.0] for y in range(4) for x in range(4)])
    quads = [(r * 4 + c + 1, r * 4 + c + 2, r * 4 + c + 6, r * 4 + c + 5) for r in range(3) for c in range(3)]

    def text(v):
        return "\n".join([f"v {x} {y} {z}" for x, y, z in v] + [f"f {a} {b} {c} {d}" for a, b, c, d in quads]) + "\n"
    (tmp_path / "neutral.obj").write_text(text(grid))
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    for k in range(n_shapes):
        moved = grid.copy()
        moved[k + 5, 2] += 0.5
        (shapes / f"s{k}.obj").write_text(text(moved))
    return tmp_path / "neutral.obj", shapes


@pytest.mark.parametrize("terminal", [True, False])
def test_import_rig_progress_on_a_terminal_only(tmp_path, monkeypatch, capsys, terminal):
    neutral, shapes = _rig(tmp_path)
    err = Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["import-rig", str(neutral), str(shapes), "-o", str(tmp_path / "c.npz")]) == 0
    text = err.getvalue()
    if terminal:
        assert "\rimport-rig: " in text and "/5 shapes" in text and text.endswith("\n")
    else:
        assert "\r" not in text and "import-rig:" not in text


@pytest.mark.parametrize("terminal", [True, False])
def test_import_rig_gltf_progress_per_mesh_on_a_terminal_only(tmp_path, monkeypatch, capsys, terminal):
    from helpers.gltf_writer import GltfBuilder

    b = GltfBuilder()
    pos = b.accessor(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32))
    b.doc.update(meshes=[{"name": f"m{i}", "primitives": [{"attributes": {"POSITION": pos}}]} for i in range(3)],
                 nodes=[{"mesh": i} for i in range(3)], scenes=[{"nodes": [0, 1, 2]}])
    err = Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["import-rig", str(b.write_glb(tmp_path / "a.glb")), "-o", str(tmp_path / "c.npz")]) == 0
    text = err.getvalue()
    if terminal:
        assert "\rimport-rig: " in text and "3/3 meshes" in text and text.endswith("\n")
    else:
        assert "\r" not in text and "import-rig:" not in text
    assert "9 vertices, 3 triangles" in capsys.readouterr().out


@pytest.mark.parametrize("terminal", [True, False])
def test_train_actor_progress_and_its_reports(tmp_path, monkeypatch, terminal):
    from facepuppet.offline.actuation.synthetic_capture import synthetic_capture
    from facepuppet.offline.io.capture import write_trc

    cap, _ = synthetic_capture(n_frames=400, n_markers=16, k=3, seed=2)
    take = write_trc(tmp_path / "take.trc", cap)
    err = Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["train-actor", str(take), "-o", str(tmp_path / "actor.npz"), "--k", "3"]) == 0
    text = err.getvalue()
    assert "  stabilise: head markers (found): " in text and "rigidity: distance SD up to" in text  # always
    if terminal:
        assert "\rtrain-actor: " in text and "/3 stages" in text
    else:
        assert "\r" not in text and "train-actor:" not in text
