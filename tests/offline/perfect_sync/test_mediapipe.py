"""perfect-sync on a face of another topology the project was not tuned on: the MediaPipe canonical face
(468 vertices, a face mask with open eyes and lips that touch, no shapes), imported from the data kit."""

import numpy as np
import pytest

from facepuppet.runtime.mapping.channels import canonical

from facepuppet.offline.io.rig_import import import_rig
from facepuppet.offline.perfect_sync import evaluate
from facepuppet.offline.perfect_sync.commands import perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.source import fit_kit_source
from tests.conftest import need_shared

pytestmark = [pytest.mark.data, pytest.mark.slow]  # the ICT fit


@pytest.fixture(scope="module")
def synced():
    face = import_rig(need_shared("mediapipe", "canonical_face_model.obj"), None)
    source = fit_kit_source(need_shared("ict-facekit"))
    return face, perfect_sync(face, source)


def test_mediapipe_face_gets_the_arkit_shapes_that_open_and_close_what_they_should(synced):
    face, (out, report, points) = synced
    assert face.n_shapes == 0 and out.n_shapes == 51
    assert report["implausible_shapes"] == []  # its jawOpen moves the chin 1.3 inner-eye distances, ICT's 1.1
    # its one skin boundary is the mask's border (its centre is the face's centre): not a hole in the face
    assert not [d for d in report["doubts"] if "hole" in d["why"]], report["doubts"]
    names = [canonical(n) for n in out.shape_names]
    dense = out.dense_deltas()
    v = out.vertices.astype(np.float64)
    f = find_face(out)
    up_axis = f.frame[1]
    for side, key in (("L", "eyeBlinkLeft"), ("R", "eyeBlinkRight")):
        rest, shut = evaluate.mid_lid_gap(out, f, points, side, dense[names.index(key)])
        assert rest > 0 and shut < 0.25 * rest, (side, rest, shut)
    d = dense[names.index("jawOpen")]
    up, low = points.vertex("lip_upper_inner"), points.vertex("lip_lower_inner")
    rest_gap = (v[up] - v[low]) @ up_axis
    open_gap = (v[up] + d[up] - v[low] - d[low]) @ up_axis
    es = np.linalg.norm(v[points.vertex("eye_inner_L")] - v[points.vertex("eye_inner_R")])
    assert open_gap > rest_gap + 0.3 * es  # the lips part: the lower lip drops well below the upper
    assert d[low] @ up_axis < 0 and abs(d[up] @ up_axis) < 0.2 * abs(d[low] @ up_axis)  # the jaw, not the nose
    # the top of the face does not move with the jaw
    top = f.skin[(v[f.skin] @ up_axis) > np.percentile(v[f.skin] @ up_axis, 80)]
    assert np.abs(d[top]).max() < 0.05 * es
