"""A low-poly box head whose eyes and mouth are drawn on separate pieces in front of its skin (a second decal face
beside Godette, built here so that the decal rules are not fitted to one file).

The skin is a closed box of side 10 (8 x 8 quads a side) with a nose (its front centre pulled forward); each eye
is an iris disc (two rings of a fan, taller than wide) and a lash outline (a strip along an arc over the iris from
its inner to its outer corner) lying 0.1 in front of the box's front; the mouth is two thin strips (upper and lower
row) on one line below the nose (optionally meeting on a seam, and with a strip of upper teeth hidden behind the
skin above them). Stored with a glTF layout of one primitive, its skin split by a seam (copies of
the vertices of the box's right half), as glTF would hold it.
"""

from __future__ import annotations

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import Layout

from facepuppet.offline.elastic.clone import mesh_character

FRONT = 5.0  # the box's front face (z)
LIFT = 0.1  # the decals in front of it


def closed_box(n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A closed (welded) cube of side 10 about the origin, n x n quads a side, every face outward."""
    verts, tris = [], []
    g = np.linspace(-5, 5, n + 1)
    for axis in range(3):
        for sign in (-1.0, 1.0):
            base = len(verts)
            for a in g:
                for b in g:
                    p = [0.0, 0.0, 0.0]
                    p[axis], p[(axis + 1) % 3], p[(axis + 2) % 3] = 5 * sign, a, b
                    verts.append(p)
            for i in range(n):
                for j in range(n):
                    q = base + i * (n + 1) + j
                    t1, t2 = (q, q + n + 1, q + 1), (q + 1, q + n + 1, q + n + 2)
                    tris += [t1, t2] if sign > 0 else [t1[::-1], t2[::-1]]
    v, inverse = np.unique(np.round(np.array(verts), 6), axis=0, return_inverse=True)
    t = inverse.reshape(-1)[np.array(tris)]
    e1, e2 = v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]
    outward = (np.cross(e1, e2) * v[t].mean(1)).sum(1) > 0
    t[~outward] = t[~outward][:, ::-1]  # every face outward
    return v, t


def _disc(centre: tuple[float, float], rx: float, ry: float, rings: int = 2, sectors: int = 12):
    cx, cy = centre
    v = [(cx, cy, FRONT + LIFT)]
    for r in range(1, rings + 1):
        for k in range(sectors):
            a = 2 * np.pi * k / sectors
            v.append((cx + rx * r / rings * np.cos(a), cy + ry * r / rings * np.sin(a), FRONT + LIFT))
    t = []
    for k in range(sectors):
        t.append((0, 1 + k, 1 + (k + 1) % sectors))
    for r in range(1, rings):
        a0, a1 = 1 + (r - 1) * sectors, 1 + r * sectors
        for k in range(sectors):
            k1 = (k + 1) % sectors
            t += [(a0 + k, a1 + k, a1 + k1), (a0 + k, a1 + k1, a0 + k1)]
    return np.array(v), np.array(t)


def _strip(points: np.ndarray, thickness: float, z: float):
    """A strip of quads along ``points`` (k, 2), ``thickness`` tall (upwards), at depth ``z``."""
    k = len(points)
    lower = np.column_stack([points, np.full(k, z)])
    upper = lower + [0.0, thickness, 0.0]
    v = np.concatenate([lower, upper])
    t = []
    for i in range(k - 1):
        t += [(i, i + 1, k + i + 1), (i, k + i + 1, k + i)]
    return v, np.array(t)


def decal_box_head(seamed_lips: bool = False, teeth: bool = False) -> tuple[Character, dict]:
    """The box head with drawn eyes and mouth (see the module doc), and its pieces' vertices by name: "skin",
    "iris_L", "lash_L", "iris_R", "lash_R", "mouth" (the two strips; "mouth_upper" the upper one's top row,
    "mouth_lower" the lower one's bottom row; "lip_upper", "lip_lower" the strips).

    ``seamed_lips``: the strips at one depth, the upper one's lower edge on the lower one's upper edge (coincident
    copies, as Godette's); ``teeth``: a strip ("teeth") above the lips' seam and behind the box's front, hidden
    from the front at rest."""
    parts = [closed_box()]
    names = ["skin"]
    skin_v, _ = parts[0]
    nose = np.flatnonzero((np.abs(skin_v[:, 0]) < 1e-6) & (np.abs(skin_v[:, 1]) < 1e-6) & (skin_v[:, 2] > 4.9))
    skin_v[nose, 2] += 1.6
    for sign in (1.0, -1.0):  # the left eye, and its mirror image
        cx, cy = 2.4, 1.6
        arc = np.linspace(np.pi, 0, 9)  # inner corner (towards the nose), over the top, outer corner
        lash = _strip(np.column_stack([cx + 1.1 * np.cos(arc), cy - 0.1 + 1.25 * np.sin(arc)]), 0.3,
                      FRONT + 1.5 * LIFT)
        side = "L" if sign > 0 else "R"
        for name, (v, t) in ((f"iris_{side}", _disc((cx, cy), 0.8, 1.1)), (f"lash_{side}", lash)):
            v = v * [sign, 1.0, 1.0]
            parts.append((v, t if sign > 0 else t[:, ::-1]))
            names.append(name)
    line = np.column_stack([np.linspace(-1.2, 1.2, 7), np.full(7, -2.4)])
    parts.append(_strip(line, 0.04, FRONT + LIFT))
    parts.append(_strip(line - [0.0, 0.04], 0.04, FRONT + (1.0 if seamed_lips else 1.2) * LIFT))
    names += ["mouth_a", "mouth_b"]
    if teeth:
        parts.append(_strip(line * [0.9, 1.0] + [0.0, 0.02], 0.18, FRONT - 0.3 * LIFT))
        names.append("teeth")
    vs, ts, base, index = [], [], 0, {}
    for name, (v, t) in zip(names, parts):
        vs.append(v)
        ts.append(t + base)
        index[name] = np.arange(base, base + len(v))
        base += len(v)
    v = np.concatenate(vs).astype(np.float32)
    t = np.concatenate(ts)
    # a seam down the box: the triangles of its right half (x < 0, skin only) on copies of their vertices
    n_skin = len(parts[0][0])
    skin_t = np.arange(len(parts[0][1]))
    right = skin_t[v[t[skin_t]].mean(1)[:, 0] < -1e-6]
    used = np.unique(t[right])
    copy_of = np.full(len(v), -1)
    copy_of[used] = len(v) + np.arange(len(used))
    t[right] = copy_of[t[right]]
    v = np.concatenate([v, v[used]])
    assert n_skin < len(v)
    c = mesh_character(v, t.astype(np.uint32), "decal box head")
    c = c.with_parts(layout=Layout(mesh_names=("head",), primitives=np.array(
        [[0, c.n_vertices, 0, len(c.triangles), 0, 0]], np.int64)))
    index["lip_upper"], index["lip_lower"] = index.pop("mouth_a"), index.pop("mouth_b")
    mouth = np.concatenate([index["lip_upper"], index["lip_lower"]])
    index["mouth"] = mouth
    index["mouth_upper"] = mouth[v[mouth, 1] > -2.4 + 1e-3]  # the top row of the upper strip
    index["mouth_lower"] = mouth[v[mouth, 1] < -2.4 - 1e-3]  # the bottom row of the lower one
    return c, index
