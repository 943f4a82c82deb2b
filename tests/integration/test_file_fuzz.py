"""File fuzz: every reader, on truncations, bit flips and type swaps of real files, refuses in our own words.

A reader may read a mutant or refuse it with a FacepuppetError (or a
subclass) whose message names the file; a traceback of any other type, a
refusal that loses the path, or a NumPy RuntimeWarning on the console is a
finding. Cases are seeded (the same on every run) and few: the whole module
takes a few seconds. The small files are made by the project's own writers
where it has one (tables, sessions, TRC, C3D, CSV markers), by hand in the
format otherwise; the data kit's files follow in the ``data`` tests.

The glTF path has its own tests below: the files ``export-character`` writes
and the kit's VRMs, mutated, each checked by ``check_gltf`` (which must list,
never raise) and read or refused by the importer; and every hostile file of
:mod:`facepuppet.offline.io.gltf_bombs`, which the importer must refuse naming
it, run in a child process bounded in memory and time
(:mod:`helpers.gltf_fuzz`).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.bench.tables_bombs import read_manifest, with_manifest
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.inputs.audio import read_wav
from facepuppet.runtime.live.config import load_live_config
from facepuppet.runtime.model.character import Character
from facepuppet.runtime.recording.livelinkface_csv import read_llf_csv
from facepuppet.runtime.recording.replay_source import open_recording
from facepuppet.runtime.recording.session import SessionWriter

from facepuppet.offline.io import gltf_bombs
from helpers.file_fuzz import check_reader, repacked_json_swaps, swap_session_header
from helpers.gltf_fuzz import forged_findings, read_and_check
from helpers.gltf_writer import glb_chunks

V1 = Path(__file__).resolve().parents[1] / "runtime" / "files" / "data" / "tables_v1"
SEED = 17


def session_bytes(tmp: Path, info: dict | None = None) -> bytes:
    path = tmp / "take.fps"
    with SessionWriter(path, info=info if info is not None else {"fps": 60, "input": "vmc"},
                       overwrite=True) as writer:
        for i in range(20):
            writer.write_frame(Frame(t=i / 60, source="vmc", channels=("jawOpen", "eyeBlinkLeft"),
                                     weights=np.array([i / 20, 0.5], np.float32),
                                     head_rotation=np.array([0, 0, 0, 1], np.float32)))
    return path.read_bytes()


def header_swaps(data: bytes):
    header = {"format": "facepuppet session", "created": "now", "facepuppet_version": "0", "info": {"fps": 60}}
    cases = [[1, 2], "text", 3, None]
    cases += [{**header, "info": v} for v in ("a string", [1], 5, None)]
    cases += [{**header, "info": {"fps": v}} for v in (None, [60], "abc", -1, 1e300, {"a": 1})]
    for case in cases:
        yield f"header {case!r}", swap_session_header(data, json.dumps(case).encode())
    yield "header not UTF-8", swap_session_header(data, b"\xff\xfe{}")


def llf_csv_bytes() -> bytes:
    names = ["EyeBlinkLeft", "JawOpen", "MouthSmileLeft", "HeadYaw", "HeadPitch", "HeadRoll"]
    lines = ["Timecode,BlendShapeCount," + ",".join(names)]
    for i in range(12):
        lines.append(f"10:20:30:{i}.{i * 7 % 1000:03d},61," + ",".join(f"{(i + k) % 10 / 10:.3f}"
                                                                        for k in range(len(names))))
    return ("\n".join(lines) + "\n").encode()


def toml_bytes() -> bytes:
    return b"""[filter.eyes]
min_cutoff = 3.0
beta = 1.5
[filter.head]
min_cutoff = 1.0
[tracking_loss]
timeout_s = 0.5
ease_out_s = 0.6
[calibration]
capture_s = 0.5
[channels.jawOpen]
gain = 1.3
clamp = [0.0, 1.0]
"""


def wav_bytes(dtype: str) -> bytes:
    from scipy.io import wavfile

    t = np.arange(800) / 8000
    tone = 0.3 * np.sin(2 * np.pi * 220 * t)
    samples = (tone * 32767).astype(np.int16) if dtype == "int16" else tone.astype(np.float32)
    buf = io.BytesIO()
    wavfile.write(buf, 8000, samples)
    return buf.getvalue()


def obj_bytes() -> bytes:
    return b"""mtllib face.mtl
o face
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl M_Face
f 1/1 2/2 3/3
usemtl M_Teeth
f 1/1 3/3 4/4
"""


def mtl_bytes() -> bytes:
    return b"""newmtl M_Face
Kd 0.8 0.6 0.5
Ks 0.1 0.1 0.1
Ns 16
newmtl M_Teeth
Kd 0.9 0.9 0.9
Ns 32
"""


def capture():
    from facepuppet.offline.io.capture import Capture

    rng = np.random.default_rng(3)
    markers = rng.normal(size=(15, 5, 3)).astype(np.float32)
    markers[4, 2] = np.nan
    return Capture(markers=markers, names=tuple(f"M{i}" for i in range(5)), rate=60.0, units="mm")


def capture_bytes(tmp: Path, kind: str) -> bytes:
    from facepuppet.offline.io import capture as cap

    path = tmp / f"take.{kind}"
    {"trc": cap.write_trc, "c3d": cap.write_c3d, "csv": cap.write_csv}[kind](path, capture())
    return path.read_bytes()


def tables_swaps(src: Path, tmp: Path):
    manifest = read_manifest(src)
    for key in sorted(manifest):
        for value in ([1], 2.5, "s", None, {"a": [1]}):
            forged = dict(manifest, **{key: value})
            out = with_manifest(src, tmp / "swap.npz", json.dumps(forged).encode())
            yield f"manifest {key} = {value!r}", out.read_bytes()


def glb_parts() -> tuple[dict, bytes]:
    """A small VRM 0.x GLB's JSON and BIN: skinned triangle, two morph targets (one sparse), a PNG texture,
    expressions, humanoid, MToon; made with the tests' own writer."""
    from PIL import Image

    from helpers.gltf_writer import GltfBuilder

    b = GltfBuilder()
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    sparse = b.sparse(np.array([1], np.uint16), np.array([[0, 0, 0.5]], np.float32))
    png = io.BytesIO()
    Image.fromarray(np.array([[[255, 0, 0, 255], [0, 0, 255, 128]]], np.uint8), "RGBA").save(png, "PNG")
    prim = {"attributes": {"POSITION": b.accessor(tri, minmax=True),
                           "NORMAL": b.accessor(np.tile(np.float32([0, 0, 1]), (3, 1))),
                           "TEXCOORD_0": b.accessor(np.array([[0, 0], [65535, 0], [0, 65535]], np.uint16),
                                                    normalized=True),
                           "JOINTS_0": b.accessor(np.array([[0, 1, 0, 0]] * 3, np.uint8)),
                           "WEIGHTS_0": b.accessor(np.array([[0.5, 0.5, 0, 0]] * 3, np.float32))},
            "indices": b.accessor(np.array([0, 1, 2], np.uint16)), "material": 0,
            "targets": [{"POSITION": b.accessor(None, kind="VEC3", dtype="float32", count=3, sparse=sparse)},
                        {"POSITION": b.accessor(tri * np.float32(0.1))}]}
    b.doc.update(
        scene=0, scenes=[{"nodes": [0, 1]}], extensionsUsed=["VRM", "KHR_texture_transform"],
        nodes=[{"mesh": 0, "skin": 0, "name": "body"}, {"name": "hips", "children": [2], "translation": [0, 1, 0]},
               {"name": "head", "rotation": [0, 0, 0.6, 0.8], "scale": [1, 2, 1]}],
        skins=[{"joints": [1, 2], "inverseBindMatrices": b.accessor(
            np.tile(np.eye(4, dtype=np.float32).reshape(1, 16), (2, 1)), kind="MAT4")}],
        meshes=[{"name": "face", "primitives": [prim], "extras": {"targetNames": ["blink", "wide"]}}],
        materials=[{"name": "skin", "alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {
            "index": 0, "extensions": {"KHR_texture_transform": {"scale": [2, 2]}}}}}],
        images=[{"bufferView": b.view(png.getvalue()), "mimeType": "image/png"}],
        samplers=[{"magFilter": 9728}], textures=[{"source": 0, "sampler": 0}],
        extensions={"VRM": {
            "meta": {"title": "t", "author": "a", "licenseName": "CC0"},
            "humanoid": {"humanBones": [{"bone": "hips", "node": 1}, {"bone": "head", "node": 2}]},
            "materialProperties": [{"name": "skin", "shader": "VRM/MToon",
                                    "floatProperties": {"_ShadeShift": 0.1, "_ShadeToony": 0.5},
                                    "vectorProperties": {"_ShadeColor": [0.5, 0.5, 0.5, 1]}}],
            "blendShapeMaster": {"blendShapeGroups": [
                {"name": "Blink", "presetName": "blink", "binds": [{"mesh": 0, "index": 0, "weight": 100}]},
                {"name": "x", "presetName": "unknown", "isBinary": True,
                 "binds": [{"mesh": 0, "index": 1, "weight": 40}]}]}}})
    return dict(b.doc, buffers=[{"byteLength": len(b.blob)}]), b.padded_blob()


def glb_bytes(tmp: Path) -> bytes:
    from helpers.gltf_writer import write_glb

    doc, blob = glb_parts()
    return write_glb(tmp / "avatar.vrm", doc, blob).read_bytes()


def glb_json_swaps(tmp: Path):
    doc, blob = glb_parts()
    yield from repacked_json_swaps(json.dumps(doc).encode(), lambda text: _glb_with_json(text, blob), SEED, n=40)


def _glb_with_json(text: bytes, blob: bytes) -> bytes:
    """A GLB around raw JSON text (kept as it is, even when it is no longer JSON) and the BIN chunk."""
    import struct

    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def gltf_json_bytes() -> bytes:
    import base64

    doc, blob = glb_parts()
    doc["buffers"] = [{"byteLength": len(blob), "uri": "data:application/gltf-buffer;base64,"
                       + base64.b64encode(blob).decode()}]
    return json.dumps(doc).encode()


MARKERS = ("M0", "M1", "M2", "M3")


def json_bytes(value) -> bytes:
    return json.dumps(value, indent=1).encode()


def landmarks_json() -> bytes:
    return json_bytes({"idx_to_landmark_verts": [(7 * i) % 90 for i in range(68)]})


def _readers(tmp: Path):
    """{name: (read, real bytes, suffix, extra cases)}, built lazily per test."""
    pytest.importorskip("c3d")
    from facepuppet.runtime.actuation.manipulation import read_script

    from facepuppet.offline.actuation.transfer import read_landmarks, read_override
    from facepuppet.offline.elastic.control_points import read_control_points
    from facepuppet.offline.gestures.commands import load_landmarks
    from facepuppet.offline.io.capture import read_c3d, read_csv, read_trc
    from facepuppet.offline.io.gltf.read import read_gltf
    from facepuppet.offline.io.mtl import read_mtl
    from facepuppet.offline.io.obj import read_obj
    from facepuppet.offline.io.rig_import import read_ict_landmarks
    from facepuppet.offline.kpls.pairs import read_pairing

    return {
        "tables(character)": (Character.load, (V1 / "character.npz").read_bytes(), ".npz",
                              lambda: tables_swaps(V1 / "character.npz", tmp)),
        "tables(actor)": (Actor.load, (V1 / "actor.npz").read_bytes(), ".npz",
                          lambda: tables_swaps(V1 / "actor.npz", tmp)),
        "session": (open_recording, session_bytes(tmp), ".fps", lambda: header_swaps(session_bytes(tmp))),
        "trc": (read_trc, capture_bytes(tmp, "trc"), ".trc", tuple),
        "c3d": (read_c3d, capture_bytes(tmp, "c3d"), ".c3d", tuple),
        "csv markers": (read_csv, capture_bytes(tmp, "csv"), ".csv", tuple),
        "obj": (read_obj, obj_bytes(), ".obj", tuple),
        "mtl": (read_mtl, mtl_bytes(), ".mtl", tuple),
        "wav int16": (read_wav, wav_bytes("int16"), ".wav", tuple),
        "wav float": (read_wav, wav_bytes("float32"), ".wav", tuple),
        "toml config": (load_live_config, toml_bytes(), ".toml", tuple),
        "live link face csv": (read_llf_csv, llf_csv_bytes(), ".csv", tuple),
        "glb/vrm": (read_gltf, glb_bytes(tmp), ".vrm", lambda: glb_json_swaps(tmp)),
        "gltf json": (read_gltf, gltf_json_bytes(), ".gltf", tuple),
        "control points json": (lambda p: read_control_points(p, 90), json_bytes(
            {"format": "facepuppet-control-points", "version": 1,
             "points": [{"name": n, "vertex": 3 + 5 * i} for i, n in enumerate(("nose_tip", "forehead", "chin"))]}),
            ".json", tuple),
        "markers-to-mesh json": (lambda p: read_override(p, MARKERS, 90), json_bytes({"M0": 3, "M2": 40}), ".json",
                                 tuple),
        "landmarks json": (lambda p: read_landmarks(p, 90), landmarks_json(), ".json", tuple),
        "ict landmarks json": (lambda p: read_ict_landmarks(p, 90), landmarks_json(), ".json", tuple),
        "detail landmarks json": (load_landmarks, landmarks_json(), ".json", tuple),
        "pairing text": (read_pairing, b"# source,target\njawOpen,JawOpen\n\nmouthSmileLeft, Smile_L  # left\n", ".txt",
                         tuple),
        "manipulate script json": (lambda p: read_script(p, MARKERS), json_bytes(
            [{"pin": "M0"}, {"drag": "M1", "to": [0.1, 2, -3], "steps": 4}, {"drag": "M2", "pixels": [5, -2]},
             {"unpin": "M0"}, {"reset": True}]), ".json", tuple),
    }


READERS = ["tables(character)", "tables(actor)", "session", "trc", "c3d", "csv markers", "obj", "mtl",
           "wav int16", "wav float", "toml config", "live link face csv", "glb/vrm", "gltf json",
           "control points json", "markers-to-mesh json", "landmarks json", "ict landmarks json",
           "detail landmarks json", "pairing text", "manipulate script json"]


@pytest.mark.parametrize("name", READERS)
def test_every_mutant_of_a_small_real_file_is_read_or_refused_naming_the_file(tmp_path, name):
    read, real, suffix, extra = _readers(tmp_path)[name]
    assert read is not None
    findings = check_reader(read, real, tmp_path, suffix, SEED + READERS.index(name), extra=extra())
    assert not findings, f"{len(findings)} findings for {name}:\n" + "\n".join(findings[:15])


def _head_lines(path: Path, n: int) -> bytes:
    """The first ``n`` lines of a kit file (a real file, cut short so each case reads quickly)."""
    with open(path, "rb") as handle:
        return b"".join(handle.readline() for _ in range(n))


KIT = {  # name: (path under ../shared/data, how much of it, reader name in _readers)
    "markers/animface_jaw.trc": (60, "trc"),
    "markers/animface_jaw.c3d": (None, "c3d"),
    "tracker/livelinkface_myslate_3.csv": (40, "live link face csv"),
    "speech/arctic_a0007.wav": (None, "wav int16"),
    "mediapipe/canonical_face_model.obj": (None, "obj"),
    "ict-facekit/ICTFaceModelMaterial.mtl": (None, "mtl"),
    "gltf/Godette_vrm_v4.vrm": (None, "glb/vrm"),
    "gltf/subdivision_shapekey_modifier_vrm1.vrm": (None, "glb/vrm"),
    "gltf/SimpleMorph.gltf": (None, "gltf json"),
}


@pytest.mark.data
@pytest.mark.parametrize("name", sorted(KIT))
def test_every_mutant_of_a_data_kit_file_is_read_or_refused_naming_the_file(tmp_path, name):
    from conftest import need_shared

    path = need_shared(*name.split("/"))
    lines, reader = KIT[name]
    real = path.read_bytes() if lines is None else _head_lines(path, lines)
    read, _, suffix, _ = _readers(tmp_path)[reader]
    findings = check_reader(read, real, tmp_path, suffix, SEED, n=5)
    assert not findings, f"{len(findings)} findings for {name}:\n" + "\n".join(findings[:15])


# -- the glTF path: check_gltf and the importer ---------------------------------------------------------------
WRITTEN = ("vrm0", "vrm1", "glb", "gltf")


def exported(tmp: Path, fmt: str) -> Path:
    """The tests' small character with all four parts as ``export-character`` writes it in ``fmt``."""
    from facepuppet.offline.io.gltf.write import export_character
    from helpers.gltf_characters import parts_character

    path = tmp / ("exported" + {"vrm0": ".vrm", "vrm1": ".vrm", "glb": ".glb", "gltf": ".gltf"}[fmt])
    character = parts_character(source_format="vrm1" if fmt == "vrm1" else "vrm0")
    export_character(character, path, vrm=int(fmt[3]) if fmt.startswith("vrm") else None)
    return path


def glb_swaps(data: bytes, seed: int, n: int):
    """Type swaps of a GLB's JSON chunk, repacked around its BIN chunk."""
    doc, blob = glb_chunks(data)
    return repacked_json_swaps(json.dumps(doc).encode(), lambda text: _glb_with_json(text, blob or b""), seed, n=n)


@pytest.mark.parametrize("fmt", WRITTEN)
def test_every_mutant_of_a_gltf_the_project_writes_is_checked_and_read_or_refused_naming_the_file(tmp_path, fmt):
    path = exported(tmp_path, fmt)
    real = path.read_bytes()
    seed = SEED + 100 + WRITTEN.index(fmt)
    extra = glb_swaps(real, seed, 20) if real[:4] == b"glTF" else ()
    findings = check_reader(read_and_check, real, tmp_path, path.suffix, seed, n=10, extra=extra)
    assert not findings, f"{len(findings)} findings for {fmt}:\n" + "\n".join(findings[:15])


@pytest.mark.data
@pytest.mark.parametrize("name", ["Godette_vrm_v4.vrm", "VRMC_vrm_expressions_isBinary_Overrides.vrm"])
def test_every_mutant_of_a_data_kit_vrm_is_checked_and_read_or_refused_naming_the_file(tmp_path, name):
    from conftest import need_shared

    real = need_shared("gltf", name).read_bytes()
    findings = check_reader(read_and_check, real, tmp_path, ".vrm", SEED, n=4, extra=glb_swaps(real, SEED, 12))
    assert not findings, f"{len(findings)} findings for {name}:\n" + "\n".join(findings[:15])


@pytest.fixture(scope="module")
def forged(tmp_path_factory) -> dict[str, list[str]]:
    """{case: findings} of every forged hostile glTF, run once per test process."""
    return forged_findings(list(gltf_bombs.FORGERIES), tmp_path_factory.mktemp("forged"))


@pytest.mark.parametrize("case", list(gltf_bombs.FORGERIES))
def test_every_forged_hostile_gltf_is_refused_by_the_importer_naming_the_file_and_checked_without_raising(
        forged, case):
    assert forged[case] == [], f"{case}: " + "; ".join(forged[case])
