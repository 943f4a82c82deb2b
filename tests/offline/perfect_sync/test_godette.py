"""perfect-sync on Godette (VRM 0.x, the data kit): shapes added under its convention, exported as
perfect-sync expressions and read back."""

import pytest

from facepuppet.runtime.mapping.channels import pascal

from facepuppet.offline.io.gltf.read import read_gltf
from facepuppet.offline.io.gltf.write import export_character
from facepuppet.offline.perfect_sync.commands import perfect_sync
from tests.conftest import need_shared

pytestmark = [pytest.mark.data, pytest.mark.slow]


@pytest.fixture(scope="module")
def synced(ict_character):
    import json

    from facepuppet.offline.elastic.commands import main_front
    from facepuppet.offline.elastic.control_points import ict_control_points
    from facepuppet.offline.elastic.params import fit_character

    marks = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    c = ict_character
    points = ict_control_points(marks["idx_to_landmark_verts"], c.vertices, c.triangles, main_front(c))
    source = fit_character(c, points, with_muscles=False)[0]
    godette = read_gltf(need_shared("gltf", "Godette_vrm_v4.vrm"))
    return godette, perfect_sync(godette, source)


def test_godette_perfect_sync_exports_and_reads_back_its_expressions(synced, tmp_path):
    godette, (out, report, _) = synced
    assert out.shape_names[:godette.n_shapes] == godette.shape_names  # its own shapes first, untouched
    added = out.shape_names[godette.n_shapes:]
    assert len(added) == 51 and added[0] == "eyeBlinkLeft"  # Godette has no ARKit names: Apple's spelling
    assert out.expressions.names == godette.expressions.names  # the binds still point at its own shapes
    assert report["face"]["evidence"] == "shapes" and report["face"]["skin_vertices"] == 91
    # the points go on her drawn features (eyes, mouth, brows); her coarse box skin cannot hold every pair
    # symmetrically (measured: jaw_chin_L/R doubted)
    assert len(report["doubts"]) <= 3
    # her features are decals moved by their own size (measured: jawOpen moves a vertex 0.09 face widths; 0.76,
    # implausible, while the skin's jaw was cloned from the misplaced points)
    assert report["implausible_shapes"] == []
    path = tmp_path / "godette_ps.vrm"
    export_character(out, path)
    back = read_gltf(path)
    assert back.shape_names == out.shape_names
    for name in added:
        assert pascal(name) in back.expressions.names, name  # VSeeFace / Warudo perfect-sync names


@pytest.mark.gl
def test_the_exported_perfect_sync_vrm_is_driven_by_arkit_pascal_case_over_vmc(synced, tmp_path):
    from helpers.vmc_run import drive, last_weights

    _, (out, _, _) = synced
    path = tmp_path / "godette_ps.vrm"
    export_character(out, path)
    back = read_gltf(path)
    result, log = drive(back, {"EyeBlinkLeft": 0.9, "JawOpen": 0.6, "MouthSmileRight": 0.3}, tmp_path)
    got = last_weights(back, result)
    assert got["eyeBlinkLeft"] == pytest.approx(0.9) and got["jawOpen"] == pytest.approx(0.6)
    assert got["mouthSmileRight"] == pytest.approx(0.3)
    assert got["eyeBlinkRight"] == 0.0 and got["mouthSmileLeft"] == 0.0
