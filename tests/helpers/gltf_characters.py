"""Small characters with all four glTF/VRM parts, built in code, and an independent glTF accessor decoder.

The decoder reads what pygltflib parsed (JSON object model, binary blob) and
decodes accessors with NumPy itself (byteStride, sparse), so the export tests
do not read the exporter's output through the exporter's own code.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import ALPHA_MODES, SHADING, Expressions, Layout, Look, Skeleton

#: Humanoid chain: (name, parent name, local translation). Node 0 is the root.
BONES = (
    ("hips", None, (0.0, 1.0, 0.0)), ("spine", "hips", (0.0, 0.1, 0.0)), ("neck", "spine", (0.0, 0.4, 0.0)),
    ("head", "neck", (0.0, 0.1, 0.02)),
    ("leftUpperLeg", "hips", (0.1, -0.05, 0.0)), ("leftLowerLeg", "leftUpperLeg", (0.0, -0.45, 0.0)),
    ("leftFoot", "leftLowerLeg", (0.0, -0.45, 0.0)),
    ("rightUpperLeg", "hips", (-0.1, -0.05, 0.0)), ("rightLowerLeg", "rightUpperLeg", (0.0, -0.45, 0.0)),
    ("rightFoot", "rightLowerLeg", (0.0, -0.45, 0.0)),
    ("leftUpperArm", "spine", (0.2, 0.35, 0.0)), ("leftLowerArm", "leftUpperArm", (0.25, 0.0, 0.0)),
    ("leftHand", "leftLowerArm", (0.25, 0.0, 0.0)),
    ("rightUpperArm", "spine", (-0.2, 0.35, 0.0)), ("rightLowerArm", "rightUpperArm", (-0.25, 0.0, 0.0)),
    ("rightHand", "rightLowerArm", (-0.25, 0.0, 0.0)),
)
SHEARED = "hat"  # a child of the head whose rest matrix has a shear, which no glTF node transform can hold
FEATHER = "feather"  # a child of the hat, turned and offset (only when a test asks for it)


def _rest(mesh_nodes: bool = False, feather: bool = False) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    extra = ("BodyNode", "FaceNode") if mesh_nodes else ()
    names = tuple(b[0] for b in BONES) + (SHEARED,) + extra + ((FEATHER,) if feather else ())
    parent = np.array([-1 if p is None else names.index(p) for _, p, _ in BONES] + [names.index("head")]
                      + [-1] * len(extra) + ([names.index(SHEARED)] if feather else []), np.int32)
    rest = np.tile(np.eye(4, dtype=np.float32), (len(names), 1, 1))
    for j, (_, _, t) in enumerate(BONES):
        rest[j, :3, 3] = t
    c, s = np.cos(0.3), np.sin(0.3)  # the neck turned 0.3 rad about +x, scaled 1.1: a TRS node
    rest[names.index("neck"), :3, :3] = 1.1 * np.array([[1, 0, 0], [0, c, -s], [0, s, c]], np.float32)
    hat = np.eye(4, dtype=np.float32)
    hat[0, 1] = 0.25  # shear
    hat[:3, 3] = (0.0, 0.12, 0.0)
    rest[names.index(SHEARED)] = hat
    if feather:
        c2, s2 = np.cos(0.5), np.sin(0.5)
        rest[names.index(FEATHER), :3, :3] = np.array([[c2, -s2, 0], [s2, c2, 0], [0, 0, 1]], np.float32)
        rest[names.index(FEATHER), :3, 3] = (0.05, 0.04, -0.02)
    return names, parent, rest


def parts_character(units: str = "m", source_format: str = "vrm0", turned: bool = True,
                    mesh_nodes: bool = False, face_on: str | None = None) -> Character:
    """Two meshes: ``Body`` (8 vertices over hips/spine, one primitive) and ``Face`` (6 vertices on the head,
    two primitives sharing them, two materials); four shapes (``Blink`` on the face, ``jawOpen`` an ARKit
    name without an expression, ``Spanning`` on both meshes, ``Still`` that moves nothing); three materials
    (textured lit with a UV transform, toon MASK double-sided, unlit BLEND emissive); two textures; three
    expressions (preset Blink, preset A binary, custom Smirk with overrideBlink block).

    ``mesh_nodes``: the skeleton also has the two nodes that held the meshes in the file (``BodyNode``,
    ``FaceNode``), named in ``source.mesh_nodes``, with ``source.mesh_from_file`` = [1, 0] (the file had
    the meshes the other way round) and a first-person annotation of the face in the raw extension.

    ``face_on``: the face's vertices follow this node instead of the head: ``hat`` (sheared) or ``feather`` (a
    node added under the hat); with ``mesh_nodes`` that node held the face in the file (an unskinned mesh)."""
    rng = np.random.default_rng(7)
    names, parent, rest = _rest(mesh_nodes, feather=face_on == FEATHER)
    head = names.index("head")
    body = rng.uniform(-0.3, 0.3, (8, 3)) + (0, 1.2, 0)
    face = rng.uniform(-0.08, 0.08, (6, 3)) + (0, 1.65, 0.05)
    v = np.vstack([body, face]).astype(np.float32)
    tri_body = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6], [5, 7, 6], [2, 3, 4]], np.uint32)
    tri_face1 = np.array([[8, 9, 10], [9, 11, 10]], np.uint32)
    tri_face2 = np.array([[10, 11, 12], [11, 13, 12]], np.uint32)
    triangles = np.vstack([tri_body, tri_face1, tri_face2])
    material = np.array([0] * 5 + [1] * 2 + [2] * 2, np.uint16)
    nodes = np.zeros((14, 4), np.uint16)
    weights = np.zeros((14, 4), np.float32)
    nodes[:8, 0], nodes[:8, 1] = 0, 1  # hips and spine, mixed
    w = rng.uniform(0.2, 0.8, 8)
    weights[:8, 0], weights[:8, 1] = w, 1 - w
    nodes[8:, 0], weights[8:, 0] = head if face_on is None else names.index(face_on), 1.0
    # shapes: CSR
    shapes = ("Blink", "jawOpen", "Spanning", "Still")
    idx = [np.array([8, 9], np.uint32), np.array([11], np.uint32), np.array([2, 12], np.uint32),
           np.zeros(0, np.uint32)]
    offsets = np.cumsum([0] + [len(i) for i in idx]).astype(np.int64)
    dpos = rng.normal(0, 0.01, (int(offsets[-1]), 3)).astype(np.float32)
    dnrm = rng.normal(0, 0.05, (int(offsets[-1]), 3)).astype(np.float32)
    tex0 = rng.integers(0, 256, (3, 4, 4), dtype=np.uint8)  # 4 wide, 3 high
    tex1 = rng.integers(0, 256, (2, 2, 4), dtype=np.uint8)
    pixels = np.vstack([tex0.reshape(-1, 4), tex1.reshape(-1, 4)])
    info = np.array([[0, 4, 3, 9729, 9987, 10497, 33071], [12, 2, 2, 9728, 9728, 33648, 10497]], np.int32)
    shading = np.zeros((3, 8), np.float32)
    shading[1] = (SHADING["toon"], 1, 0.4, 0.2, 0.3, -0.1, 0.8, 0)
    shading[2, 0] = SHADING["unlit"]
    look = Look(
        uv=rng.uniform(0, 1, (14, 2)).astype(np.float32),
        base_color=np.array([[1, 0.9, 0.8, 1], [0.5, 0.6, 0.7, 1], [1, 1, 1, 0.5]], np.float32),
        emissive=np.array([[0, 0, 0], [0, 0, 0], [0.2, 0.1, 0]], np.float32),
        alpha=np.array([[ALPHA_MODES["OPAQUE"], 0.5], [ALPHA_MODES["MASK"], 0.3], [ALPHA_MODES["BLEND"], 0.5]],
                       np.float32),
        shading=shading, texture=np.array([0, -1, 1], np.int32),
        uv_transform=np.array([[0.1, 0.2, 0.0, 0.5, 0.5], [0, 0, 0, 1, 1], [0, 0, 0, 1, 1]], np.float32),
        texture_names=("skin_tex", "blush_tex"), texture_info=info, texture_pixels=pixels)
    expressions = Expressions(
        names=("Blink", "A", "Smirk"), presets=("Blink", "A", ""),
        offsets=np.array([0, 1, 2, 4], np.int64), bind_shape=np.array([0, 2, 1, 0], np.uint32),
        bind_weight=np.array([1.0, 0.5, 0.25, 0.75], np.float32),
        flags=np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 2]], np.int32))
    layout = Layout(("Body", "Face"), np.array([[0, 8, 0, 5, 0, 0], [8, 6, 5, 2, 1, 1], [8, 6, 7, 2, 1, 2]],
                                               np.int64))
    # the file's node order was different: stored node s was file node 2 s + 1
    node_from_file = [2 * s + 1 for s in range(len(names))]
    raw = {"firstPerson": {"firstPersonBone": node_from_file[head], "firstPersonBoneOffset": {"x": 0, "y": 0.06,
                                                                                                "z": 0},
                           "meshAnnotations": [{"mesh": 0, "firstPersonFlag": "Auto"}]},
           "secondaryAnimation": {"boneGroups": [{"comment": "hat", "bones": [node_from_file[len(names) - 1], 999],
                                                  "center": -1, "colliderGroups": [0, 1]}],
                                  "colliderGroups": [{"node": node_from_file[head], "colliders": []},
                                                     {"node": 998, "colliders": []}]},
           "humanoid": {"armStretch": 0.05}} if source_format == "vrm0" else {
           "firstPerson": {"meshAnnotations": [{"node": 3, "type": "auto"}]},
           "lookAt": {"type": "bone", "offsetFromHeadBone": [0, 0.06, 0]}}
    meta = ({"title": "Quad", "author": "Someone", "licenseName": "CC_BY", "version": "1", "texture": 5}
            if source_format == "vrm0" else {"name": "Quad", "authors": ["Someone"],
                                             "licenseUrl": "https://example.org/l", "thumbnailImage": 3})
    source = {"format": source_format, "file": "quad.vrm", "turned_y180": turned and source_format == "vrm0",
              "meta": meta, "credits": "Quad by Someone, CC BY", "vrm_extension": raw, "node_from_file": node_from_file}
    if mesh_nodes:
        source["mesh_nodes"] = [names.index("BodyNode"), names.index(face_on or "FaceNode")]
        source["mesh_from_file"] = [1, 0]
        face_file_node = node_from_file[names.index(face_on or "FaceNode")]
        raw["firstPerson"]["meshAnnotations"] = ([{"mesh": 0, "firstPersonFlag": "ThirdPersonOnly"}]
                                                 if source_format == "vrm0" else
                                                 [{"node": face_file_node, "type": "thirdPersonOnly"}])
    scale = {"m": 1.0, "cm": 100.0, "mm": 1000.0}[units]
    rest = rest.copy()
    rest[:, :3, 3] *= scale
    return Character(
        name="quad", units=units, vertices=(v * scale).astype(np.float32), triangles=triangles,
        triangle_material=material, vertex_color=np.ones((14, 3), np.float32), material_names=("skin", "toon", "blush"),
        material_params=np.array([[0.05, 18, 0, 0]] * 3, np.float32), pivot=np.zeros(3, np.float32),
        shape_names=shapes, delta_offsets=offsets, delta_indices=np.concatenate(idx),
        delta_positions=dpos * scale, delta_normals=dnrm,
        metadata={"settings": {"source": source, "name": "quad"}},
        skeleton=Skeleton(names, parent, rest, nodes, weights, {b[0]: j for j, b in enumerate(BONES)}),
        look=look, expressions=expressions, layout=layout)


# -- decoding -----------------------------------------------------------------------------------
_DT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_W = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def view_bytes(gltf, blob: bytes, index: int) -> bytes:
    v = gltf.bufferViews[index]
    off = v.byteOffset or 0
    return blob[off:off + v.byteLength]


def decode(gltf, blob: bytes, index: int) -> np.ndarray:
    """Accessor ``index`` of a pygltflib GLTF2 as (count, width) float64 (or int64), sparse applied."""
    a = gltf.accessors[index]
    dt = np.dtype(_DT[a.componentType])
    w = _W[a.type]
    out = np.zeros((a.count, w), np.float64 if dt.kind == "f" else np.int64)
    if a.bufferView is not None:
        raw = view_bytes(gltf, blob, a.bufferView)
        stride = gltf.bufferViews[a.bufferView].byteStride or dt.itemsize * w
        off = a.byteOffset or 0
        for i in range(a.count):
            row = raw[off + i * stride: off + i * stride + dt.itemsize * w]
            out[i] = np.frombuffer(row, dt)
    if a.sparse is not None:
        s = a.sparse
        idt = np.dtype(_DT[s.indices.componentType])
        idx = np.frombuffer(view_bytes(gltf, blob, s.indices.bufferView), idt, count=s.count,
                            offset=s.indices.byteOffset or 0)
        vals = np.frombuffer(view_bytes(gltf, blob, s.values.bufferView), dt, count=s.count * w,
                             offset=s.values.byteOffset or 0).reshape(s.count, w)
        out[idx.astype(np.int64)] = vals
    return out


def node_local(node) -> np.ndarray:
    """A pygltflib node's local matrix (4, 4) float64 from its matrix (column-major) or TRS (spec 5.25)."""
    if node.matrix is not None:
        return np.asarray(node.matrix, np.float64).reshape(4, 4).T
    t = np.asarray(node.translation or [0, 0, 0], np.float64)
    x, y, z, w = node.rotation or [0, 0, 0, 1]
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    s = np.asarray(node.scale or [1, 1, 1], np.float64)
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def node_worlds(gltf) -> np.ndarray:
    """World matrices of every node of a pygltflib GLTF2 (walking children from the scene roots)."""
    out = np.tile(np.eye(4), (len(gltf.nodes), 1, 1))

    def walk(i: int, parent: np.ndarray) -> None:
        out[i] = parent @ node_local(gltf.nodes[i])
        for ch in gltf.nodes[i].children or []:
            walk(ch, out[i])
    for root in gltf.scenes[gltf.scene or 0].nodes:
        walk(root, np.eye(4))
    return out
