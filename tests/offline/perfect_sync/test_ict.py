"""perfect-sync on the ICT head and a stylised variant of known truth: errors, lids, lips, doubts, refusals."""

import json

import numpy as np
import pytest

from facepuppet.runtime.files.tables import TablesError
from facepuppet.runtime.mapping.channels import canonical

from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points, write_control_points
from facepuppet.offline.elastic.params import fit_character
from facepuppet.offline.kpls.targets import stylise
from facepuppet.offline.perfect_sync import evaluate
from facepuppet.offline.perfect_sync.commands import load_source, perfect_sync
from facepuppet.offline.perfect_sync.face import find_face
from facepuppet.offline.perfect_sync.lid_cover import ALLOWED
from facepuppet.offline.perfect_sync.proposal import doubts, read_landmarks
from tests.conftest import need_shared

pytestmark = pytest.mark.slow  # the ICT fit and two clones of 26k vertices


@pytest.fixture(scope="module")
def source(ict_character, tmp_path_factory):
    marks = json.loads(need_shared("ict-facekit", "vertex_indices.json").read_text(encoding="utf-8"))
    c = ict_character
    points = ict_control_points(marks["idx_to_landmark_verts"], c.vertices, c.triangles, main_front(c))
    path = tmp_path_factory.mktemp("ps") / "ict_elastic.npz"
    fit_character(c, points, with_muscles=False)[0].save(path)
    return load_source(path), path


def truth_errors(target, out, _added=None) -> dict:
    return evaluate.truth_errors(target, out, find_face(target))


def _renamed(character):
    """The character with its shapes renamed out of ARKit's names (so perfect-sync adds them all)."""
    return character.with_parts(shape_names=tuple(f"truth{i}" for i in range(character.n_shapes)),
                                expressions=None)


@pytest.fixture(scope="module")
def identical(ict_character, source):
    target = _renamed(ict_character)
    out, report, points = perfect_sync(target, source[0])
    return target, out, report, points


def test_identical_character_clones_with_small_error(identical, ict_character):
    target, out, report, _ = identical
    assert len(report["added"]) == 51 and report["kept"] == []
    assert report["implausible_shapes"] == [] and report["doubts"] == []
    errs = truth_errors(ict_character, out, report["added"])
    skin = [k for k in errs if not k.startswith("eyeLook")]
    # measured 9.8 % median without the eye looks (10.7 % with them), worst 25 % (the blinks, 16 % before
    # close_lids made the lids meet): the elastic model's own reconstruction error of ICT is 9.8 % (fit-elastic).
    # 11.4 % while the detected nose tip replaced the fitted one; 16.6 % (jawOpen 48 %) while the inner lips
    # were taken by distance alone (the lower lip's vertex as the upper point).
    assert np.median([errs[k] for k in skin]) < 0.11, errs
    assert max(errs.values()) < 0.30, errs


def test_cloned_blink_closes_the_lids_and_jaw_open_parts_the_lips(identical, ict_character, source):
    target, out, _, points = identical
    v = out.vertices.astype(np.float64)
    dense = out.dense_deltas()
    names = [canonical(n) for n in out.shape_names]
    for side, key in (("L", "eyeBlinkLeft"), ("R", "eyeBlinkRight")):
        up, low = points.vertex(f"lid_upper_inner_{side}"), points.vertex(f"lid_lower_inner_{side}")
        rest_gap = v[up, 1] - v[low, 1]
        d = dense[names.index(key)]
        gap = (v[up, 1] + d[up, 1]) - (v[low, 1] + d[low, 1])
        # 0.85 cm -> 0.44 cm at the inner lid points before close_lids (the eq. 6 compromise); now the lids meet
        assert rest_gap > 0.5 and abs(gap) < 0.1 * rest_gap, (side, rest_gap, gap)
        mid = evaluate.mid_lid_gap(out, find_face(out), points, side, d)
        assert mid[1] < 0.25 * mid[0], (side, mid)
    d = dense[names.index("jawOpen")]
    up, low = points.vertex("lip_upper"), points.vertex("lip_lower")
    assert (v[up, 1] + d[up, 1]) - (v[low, 1] + d[low, 1]) > (v[up, 1] - v[low, 1]) + 1.0  # cm


def test_stylised_variant_of_known_truth(ict_character, source):
    variant = stylise(ict_character)
    out, report, _ = perfect_sync(_renamed(variant), source[0])
    errs = truth_errors(variant, out, report["added"])
    skin = {k: e for k, e in errs.items() if not k.startswith("eyeLook")}
    # measured: median 12.8 % without the eye looks (14.8 % with them), worst 31 % (mouthRollUpper)
    assert np.median(list(skin.values())) < 0.15, skin
    assert max(errs.values()) < 0.40, errs


def test_a_wider_shorter_deeper_variant_of_known_truth(ict_character, source):
    from facepuppet.offline.perfect_sync.bench import proportions

    variant = proportions(ict_character)  # x 1.15, y 0.9, z 1.05 about the pivot; true shapes A d
    out, report, points = perfect_sync(_renamed(variant), source[0])
    errs = truth_errors(variant, out)
    # measured 12.7 % median, worst 25 % (eyeBlinkRight). With one scale for all axes in the fit: 17.9 %,
    # eyeWide 56 % (5 of the 47 points on their vertex; now 46).
    assert np.median(list(errs.values())) < 0.15, errs
    assert max(errs.values()) < 0.40, errs


def test_doubt_report_fires_on_a_wrong_landmark_file(identical, source, tmp_path):
    target, _, _, points = identical
    names = list(points.names)
    verts = points.vertices.copy()
    i, j = names.index("eye_outer_L"), names.index("eye_outer_R")
    verts[i], verts[j] = verts[j], verts[i]  # left and right swapped
    k = names.index("brow_mid_L")
    verts[k] = int(np.argmin(target.vertices[:, 2]))  # the back of the head
    from facepuppet.offline.elastic.control_points import ControlPoints

    path = write_control_points(tmp_path / "wrong.json", ControlPoints(tuple(names), verts))
    face = find_face(target)
    found = doubts(read_landmarks(path, names, target.n_vertices), target.vertices, face)
    flagged = {n for d in found for n in d["points"]}
    assert {"eye_outer_L", "eye_outer_R", "brow_mid_L"} <= flagged, found
    clean = doubts(points, target.vertices, face)
    assert not {"eye_outer_L", "eye_outer_R", "brow_mid_L"} & {n for d in clean for n in d["points"]}


def test_landmarks_with_unknown_or_missing_points_are_refused(identical, source, tmp_path):
    target, _, _, points = identical
    from facepuppet.offline.elastic.control_points import ControlPoints

    extra = ControlPoints(points.names[:-1] + ("ear_L",), points.vertices)
    path = write_control_points(tmp_path / "bad.json", extra)
    with pytest.raises(ValueError, match=r"bad.json: points: unknown points \['ear_L'\]; missing points \['cheek_R'\]"):
        read_landmarks(path, points.names, target.n_vertices)


def test_a_source_of_the_wrong_kind_is_refused(ict_character_path):
    with pytest.raises(TablesError, match="kind"):
        load_source(ict_character_path)


def test_a_static_head_without_shapes_gets_all_51(ict_character, source, tmp_path):
    """import-rig head.obj with no shapes folder, then perfect-sync: the face found from the geometry alone."""
    from facepuppet.offline.io.rig_import import import_rig

    static = import_rig(need_shared("ict-facekit", "generic_neutral_mesh.obj"), None)
    assert static.n_shapes == 0
    out, report, _ = perfect_sync(static, source[0])
    assert report["face"]["evidence"] == "whole character"
    assert len(report["added"]) == 51 and out.n_shapes == 51
    assert out.shape_names[0] == "eyeBlinkLeft"  # Apple's spelling when the character has no convention
    errs = evaluate.truth_errors(ict_character, ict_character.with_parts(
        shape_names=_renamed(ict_character).shape_names + out.shape_names,
        delta_offsets=np.concatenate([ict_character.delta_offsets,
                                      ict_character.delta_offsets[-1] + out.delta_offsets[1:]]),
        delta_indices=np.concatenate([ict_character.delta_indices, out.delta_indices]),
        delta_positions=np.concatenate([ict_character.delta_positions, out.delta_positions]),
        delta_normals=np.concatenate([ict_character.delta_normals, out.delta_normals])), find_face(ict_character))
    assert np.median(list(errs.values())) < 0.13, errs


def test_command_writes_the_character_and_refuses_bad_landmarks_writing_nothing(ict_character_path, source,
                                                                                  tmp_path, capsys):
    from facepuppet.runtime.cli import main
    from facepuppet.runtime.model.character import Character

    out, pics = tmp_path / "ps.npz", tmp_path / "pics"
    assert main(["perfect-sync", str(ict_character_path), "-o", str(out), "--source", str(source[1]),
                 "--pictures", str(pics)]) == 0
    ps = Character.load(out)
    assert ps.n_shapes == 57 + 2  # ICT's 57 kept (ARKit-named), browInnerUp and cheekPuff added (folded sides)
    assert (pics / "landmarks.png").stat().st_size > 1000 and (pics / "landmarks.json").exists()
    said = capsys.readouterr().out
    assert "0 doubtful proposal(s)" in said  # ICT's own head: its proposed points are its true ones
    assert "which is not a proof" in said and str(pics / "landmarks.png") in said  # and what was not checked
    again = tmp_path / "again.npz"
    assert main(["perfect-sync", str(ict_character_path), "-o", str(again), "--source", str(source[1]),
                 "--landmarks", str(pics / "landmarks.json"), "--replace"]) == 0
    replaced = Character.load(again)
    assert replaced.shape_names[:57] == ps.shape_names[:57]
    assert not np.allclose(replaced.dense_deltas()[14], ps.dense_deltas()[14])  # eyeBlink_L now the clone
    doc = json.loads((pics / "landmarks.json").read_text(encoding="utf-8"))
    doc["points"][0]["name"] = "ear_L"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc), encoding="utf-8")
    never = tmp_path / "never.npz"
    assert main(["perfect-sync", str(ict_character_path), "-o", str(never), "--source", str(source[1]),
                 "--landmarks", str(bad)]) == 2
    assert "unknown points ['ear_L']; missing points ['jaw_R']" in capsys.readouterr().err
    assert not never.exists()


def test_eye_looks_turn_the_eyeballs_rigidly(identical, ict_character):
    """ICT's own eyeLook shapes move the lids only; the cloned ones also turn the eyeball pieces (sclera, iris)."""
    _, out, _, points = identical
    c = ict_character
    v = out.vertices.astype(np.float64)
    dense = out.dense_deltas()
    names = [canonical(n) for n in out.shape_names]
    eye = {side: np.unique(c.triangles[np.isin(c.triangle_material, [c.material_names.index(f"M_Sclera{word}"),
                                                                      c.material_names.index(f"M_Iris{word}")])])
           for side, word in (("L", "Left"), ("R", "Right"))}
    front = {side: eye[side][np.argmax(v[eye[side], 2])] for side in eye}  # the pupil's centre
    expected = {"eyeLookUpLeft": ("L", 1, 1.0), "eyeLookDownLeft": ("L", 1, -1.0),
                "eyeLookOutLeft": ("L", 0, 1.0), "eyeLookInLeft": ("L", 0, -1.0),
                "eyeLookOutRight": ("R", 0, -1.0), "eyeLookInRight": ("R", 0, 1.0)}
    for key, (side, axis, sign) in expected.items():
        d = dense[names.index(key)]
        pupil = d[front[side]]
        assert sign * pupil[axis] > 0.3, (key, pupil)  # cm: 15-25 degrees on a 1.6 cm eye move it 0.4-0.7 cm
        other = "R" if side == "L" else "L"
        assert np.abs(d[eye[other]]).max() == 0.0, key
        p, q = v[eye[side]], v[eye[side]] + d[eye[side]]  # rigid: pairwise distances kept
        np.testing.assert_allclose(np.linalg.norm(q[1:] - q[0], axis=1), np.linalg.norm(p[1:] - p[0], axis=1),
                                   atol=1e-4)
    assert np.abs(dense[names.index("jawOpen")][eye["L"]]).max() == 0.0


def test_lower_teeth_follow_the_jaw_and_the_back_of_the_head_stays(identical, ict_character):
    _, out, _, _ = identical
    c = ict_character
    from facepuppet.offline.elastic.laplacian import components

    dense = out.dense_deltas()
    names = [canonical(n) for n in out.shape_names]
    _, comp = components(c.n_vertices, c.triangles)
    teeth = np.unique(comp[c.triangles[c.triangle_material == c.material_names.index("M_Teeth")]])
    jaw = dense[names.index("jawOpen")]
    for k in teeth:  # ICT: upper teeth centred near y = -2.3 cm, lower near y = -4 cm
        members = comp == k
        moved = np.linalg.norm(jaw[members], axis=1)
        if c.vertices[members, 1].mean() < -3.0:
            assert moved.min() > 0.5, k  # cm: the lower teeth drop with the jaw
        else:
            assert moved.max() == 0.0, k  # the upper teeth stay with the skull
    back = np.unique(c.triangles[c.triangle_material == c.material_names.index("M_BackHead")])
    back = back[c.vertices[back, 2] < -2.0]  # the back half of the cranium
    assert np.abs(dense[c.n_shapes:, back]).max() == 0.0


def test_a_hole_in_the_cheek_is_doubted(identical):
    target, _, _, points = identical
    v = target.vertices.astype(np.float64)
    cheek = v[points.vertex("cheek_L")]
    t = target.triangles
    hole = (np.linalg.norm(v[t].mean(1) - cheek, axis=1) < 0.6)  # cm: a hole about 1 cm across
    holed = target.with_parts(triangles=t[~hole], triangle_material=target.triangle_material[~hole],
                              layout=None, normals=None)
    face = find_face(holed)
    found = [d for d in doubts(points, holed.vertices, face) if "hole" in d["why"]]
    assert [d["points"] for d in found] == [["cheek_L"]], found
    assert not [d for d in doubts(points, target.vertices, find_face(target)) if "hole" in d["why"]]


def test_identical_character_reproduces_the_source_model_exactly(identical, source, ict_character):
    """On the source's own head the proposal finds the source's 47 vertices and the clone is the source's
    own elastic reconstruction (zero error beyond the model's), except the blinks, whose lids close_lids
    makes meet, the lid skin kept out of the eyeballs (only ever farther out) and the skin within 2 cm of the
    gums and teeth (kept out of them). (Before the fitted nose tip was kept, the detected one moved a vertex:
    5.4 % median.)"""
    from facepuppet.offline.perfect_sync.transfer import fold_source

    target, out, _, points = identical
    model = source[0]
    np.testing.assert_array_equal(points.vertices, model.arrays["control_vertices"])
    keys, params = fold_source(model)
    c = ict_character
    v = c.vertices
    skin = find_face(c).skin
    # the lids pass over the eyeballs: the skin within 2.5 cm of an eyeball's centre may be put out of it
    centres = [v[np.unique(c.triangles[c.triangle_material == c.material_names.index(f"M_Sclera{w}")])].mean(0)
               for w in ("Left", "Right")]
    near = [np.linalg.norm(v[skin] - e, axis=1) < 2.5 for e in centres]
    # and the outer skin over the gums and teeth may be kept out of them
    from scipy.spatial import cKDTree

    inner = np.unique(c.triangles[np.isin(c.triangle_material, [c.material_names.index("M_GumsTongue"),
                                                                 c.material_names.index("M_Teeth")])])
    over_mouth = cKDTree(v[inner]).query(v[skin])[0] < 2.0
    far = ~(near[0] | near[1] | over_mouth)
    dense = out.dense_deltas()[target.n_shapes:]
    for key, p, d in zip(keys, params, dense):
        if key.startswith("eyeBlink"):
            continue
        pos, _ = model.deform(p, v, np.tile([0, 0, 1.0], (len(v), 1)))
        ref = (pos - v)[skin]
        tol = 1e-4 * max(np.abs(ref).max(), 1e-6)
        np.testing.assert_allclose(d[skin][far], ref[far], atol=tol, err_msg=key)
        for e, m in zip(centres, near):  # near the eyes only ever farther out of the eyeball
            out_r = np.linalg.norm(v[skin][m] + d[skin][m] - e, axis=1)
            ref_r = np.linalg.norm(v[skin][m] + ref[m] - e, axis=1)
            assert (out_r >= ref_r - tol).all(), key


def test_the_closed_lids_cover_the_eyeball(identical, ict_character):
    """The cloned blink's upper lid comes down in front of the eyeball, not through it: after the blink each vertex
    of the eyeball's front half (sclera and iris) has skin in front of it within 1.5 mm across the face. Measured
    8 of 785 uncovered per eye (at the corners); 164 before the lids were pushed out of the eyeball (the cornea
    showed through the closed lid)."""
    from scipy.spatial import cKDTree

    _, out, _, _ = identical
    c = ict_character
    v = out.vertices.astype(np.float64)
    dense = out.dense_deltas()
    names = [canonical(n) for n in out.shape_names]
    skin = find_face(out).skin
    for word, key in (("Left", "eyeBlinkLeft"), ("Right", "eyeBlinkRight")):
        eye = np.unique(c.triangles[np.isin(c.triangle_material, [c.material_names.index(f"M_Iris{word}"),
                                                                   c.material_names.index(f"M_Sclera{word}")])])
        p = v + dense[names.index(key)]
        front = eye[p[eye, 2] > np.median(p[eye, 2])]
        tree = cKDTree(p[skin, :2])
        uncovered = 0
        for i, near in zip(front, tree.query_ball_point(p[front, :2], 0.15)):
            z = p[skin[near], 2]
            z = z[z > p[i, 2] - 1.0]  # the lid in front, not the socket behind the eye
            uncovered += int(not len(z) or z.max() < p[i, 2])
        assert uncovered < 0.03 * len(front), (word, uncovered, len(front))


def test_the_gums_stay_behind_the_cheeks(identical, ict_character):
    """The elastic clone of mouthFunnel and jawForward pulls the skin beside the nose back further than the true
    shapes do, and the gums came through it (dark patches beside the nostrils in the contact sheet). Now the outer
    skin (facing forward) within 12 mm outside the gums' front at rest ends up more than 0.2 mm inside it (signed
    distance to the nearest front gum triangle, along its normal) far less often; the contact sheet shows no gums."""
    from facepuppet.offline.perfect_sync.triangles import nearest_triangles

    _, out, _, _ = identical
    c = ict_character
    v = out.vertices.astype(np.float64)
    dense = out.dense_deltas()
    names = [canonical(n) for n in out.shape_names]
    skin = find_face(out).skin
    from facepuppet.runtime.model.geometry import vertex_normals

    gum_t = c.triangles[c.triangle_material == c.material_names.index("M_GumsTongue")].astype(np.int64)
    gv = c.vertices.astype(np.float64)
    gum_t = gum_t[np.cross(gv[gum_t[:, 1]] - gv[gum_t[:, 0]], gv[gum_t[:, 2]] - gv[gum_t[:, 0]])[:, 2] > 0]  # front
    outer = skin[vertex_normals(c.vertices, c.triangles)[skin, 2] > 0.3]

    def signed(p, d):
        q = p + d  # the gums' own shaped place (they follow the jaw or stay)
        t, bary, _ = nearest_triangles(p_skin := q[outer], q, gum_t)
        tri = q[gum_t[t]]
        closest = (bary[:, :, None] * tri).sum(1)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return ((p_skin - closest) * n).sum(1), np.linalg.norm(p_skin - closest, axis=1)

    rest, dist = signed(v, 0.0)
    watch = (rest > 0) & (dist < 1.2)  # cm: the outer skin over the gums
    assert watch.sum() > 100
    inside = {}
    for key in ("mouthFunnel", "jawForward"):
        now, _ = signed(v, dense[names.index(key)])
        inside[key] = int((now[watch] < -0.02).sum())
    # measured 78 and 34 (185 and 34 before the outer skin was kept out of the gums' front; the rest, which the
    # push does not reach, lie in the nostrils and along the lips, where the nearest-triangle sign is no guide)
    assert inside["mouthFunnel"] < 120 and inside["jawForward"] <= 34, inside


def test_command_on_a_character_without_a_face_names_the_file_and_writes_nothing(source, tmp_path, capsys):
    """A VRM's title may say nothing ("undefined" in two of the kit's files): the refusal names the file too."""
    from facepuppet.runtime.cli import main

    from facepuppet.offline.elastic.clone import mesh_character
    from helpers.decal_heads import closed_box

    v, t = closed_box()
    path = mesh_character(v.astype(np.float32), t.astype(np.uint32), "undefined").save(tmp_path / "box.npz")
    out = tmp_path / "never.npz"
    assert main(["perfect-sync", str(path), "-o", str(out), "--source", str(source[1])]) == 2
    err = capsys.readouterr().err
    assert f"{path} ('undefined'): no recognisable face" in err, err
    assert not out.exists()


def test_the_closed_lids_leave_no_pinholes(identical):
    """Seen from the front, each cloned blink's closed lid covers the eye's opening as the true blink does
    (:mod:`.lid_cover`: the true blinks show their shadow mesh along the lid line, 2.7 % and 1.4 % of the opening).
    Measured before the lids kept a tenth of the ball's radius clear of it and the tear film and shadow mesh
    slid over the ball: 17.8 % and 17.4 % (the sclera and the shadow mesh came through as dark pinholes above
    the lid line, though every vertex of the lid was outside the ball), and perfect-sync said nothing."""
    _, _, report, _ = identical
    assert set(report["lid_cover"]) == {"eyeBlinkLeft", "eyeBlinkRight"}
    for key, c in report["lid_cover"].items():
        assert c["fraction"] <= ALLOWED, (key, c)
    assert report["open_blinks"] == []
