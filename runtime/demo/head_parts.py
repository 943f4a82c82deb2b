"""Geometry of the procedural demo head: skin surface, eyes, lids, teeth, mouth.

Each function returns a :class:`Part`: local vertices (cm, y up, x = the
character's left, looking along +z), counter-clockwise triangles seen from
outside, linear-RGB vertex colours, a material name per triangle, and the
parameters the expression shapes in :mod:`demo_head` need (grid coordinates,
lid angles). The skin is a star-shaped surface around ``ORIGIN``: along each
ray the distance is a smooth union of a cranium, a tilted jaw ellipsoid and
a neck cylinder, then the face is sculpted with Gaussian bumps along +z.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from facepuppet.runtime.model.geometry import smoothstep

ORIGIN = np.array([0.0, -1.5, -0.5])  # ray origin of the skin surface, cm
MOUTH_Y = -6.4  # target height of the lip line, cm
MOUTH_HALF_WIDTH = 2.45  # x of the mouth corners, cm
EYE_RADIUS = 1.15  # eyeball radius, cm
EYE_XY = (3.0, 0.55)  # |x| and y of the eyeball centres, cm
EYE_Z = 7.1  # z of the eyeball centres, cm
JAW_HINGE = np.array([0.0, -2.4, -0.8])  # jaw rotation centre (an x axis through it), cm
LID_CORNER = np.radians(64.0)  # half-angle where the lid margins meet
LID_UPPER = np.radians(27.0)  # upper margin elevation at the lid centre
LID_LOWER = np.radians(-20.0)  # lower margin elevation at the lid centre
LID_TOP = np.radians(80.0)  # elevation of the lid edge hidden in the skin

SKIN = np.array([0.62, 0.36, 0.25])
LIPS = np.array([0.46, 0.13, 0.12])
BROW = np.array([0.045, 0.025, 0.015])


@dataclass
class Part:
    """One piece of the demo head before assembly.

    Attributes
    ----------
    vertices : ndarray of shape (n, 3), float64, cm
    triangles : ndarray of shape (m, 3), int64, local indices, counter-clockwise
    colors : ndarray of shape (n, 3), float64, linear RGB
    materials : ndarray of shape (m,), str, material name per triangle
    params : dict of str to ndarray of shape (n, ...), per-vertex parameters
    """

    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray
    materials: np.ndarray
    params: dict = field(default_factory=dict)


def gauss(x: np.ndarray, y: np.ndarray, cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
    """Unnormalised 2-D Gaussian bump, 1 at (cx, cy)."""
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


def _grid_triangles(idx: np.ndarray, wrap: bool) -> np.ndarray:
    """Two triangles per quad of an index grid (rows, cols); rows go up, columns go left-to-right."""
    cols = idx.shape[1] if wrap else idx.shape[1] - 1
    a = idx[:-1, :cols]
    b = np.roll(idx, -1, axis=1)[:-1, :cols]
    c = np.roll(idx, -1, axis=1)[1:, :cols]
    d = idx[1:, :cols]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])


def orient_outward(vertices: np.ndarray, triangles: np.ndarray, centre: np.ndarray, each: bool = False) -> np.ndarray:
    """Triangles turned to face away from ``centre``.

    With ``each`` every triangle is turned on its own (right for convex
    pieces); otherwise the whole mesh flips if most of it faces inwards.
    """
    v = vertices[triangles]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    facing = np.sum(normal * (v.mean(axis=1) - centre), axis=1)
    flip = facing < 0 if each else np.full(len(triangles), facing.sum() < 0)
    out = triangles.copy()
    out[flip] = out[flip, ::-1]
    return out


# -- skin -------------------------------------------------------------------
def _ray_ellipsoid(d, centre, axes, tilt=0.0):
    """Far distance from ORIGIN along unit rays ``d`` (n, 3) to an ellipsoid tilted by ``tilt`` about x."""
    c, s = np.cos(tilt), np.sin(tilt)
    rot = np.array([[1, 0, 0], [0, c, s], [0, -s, c]])  # into the ellipsoid frame
    o = (rot @ (ORIGIN - centre)) / axes
    dd = (d @ rot.T) / axes
    a = np.sum(dd * dd, axis=1)
    b = 2 * dd @ o
    cc = o @ o - 1.0
    return (-b + np.sqrt(np.maximum(b * b - 4 * a * cc, 0.0))) / (2 * a)


def _ray_neck(d, x_radius=5.0, z_radius=5.3, z_centre=-1.8, y_bottom=-19.0):
    """Distance along rays to an elliptic neck cylinder capped at ``y_bottom`` (open upwards: +inf)."""
    o = np.array([ORIGIN[0] / x_radius, (ORIGIN[2] - z_centre) / z_radius])
    dd = np.stack([d[:, 0] / x_radius, d[:, 2] / z_radius], axis=1)
    a = np.maximum(np.sum(dd * dd, axis=1), 1e-12)
    b = 2 * dd @ o
    cc = o @ o - 1.0
    side = (-b + np.sqrt(b * b - 4 * a * cc)) / (2 * a)
    cap = np.where(d[:, 1] < -1e-9, (y_bottom - ORIGIN[1]) / np.minimum(d[:, 1], -1e-9), np.inf)
    up = smoothstep(0.0, -0.35, d[:, 1])  # the neck only exists below the origin
    return np.minimum(side, cap) * up


def _smooth_max(a, b, k):
    return 0.5 * (a + b + np.sqrt((a - b) ** 2 + k * k))


def _skin_distance(d):
    """Distance from ORIGIN along unit rays (n, 3) to the unsculpted skin, cm."""
    cranium = _ray_ellipsoid(d, np.array([0.0, 0.9, -0.6]), np.array([7.6, 10.4, 9.7]))
    jaw = _ray_ellipsoid(d, np.array([0.0, -5.4, 2.0]), np.array([5.9, 6.3, 6.4]), tilt=np.radians(-28))
    return _smooth_max(_smooth_max(cranium, jaw, 1.6), _ray_neck(d), 2.2)


def _face_relief(x, y, rel, inside, front):
    """Displacement along +z (cm) that sculpts the face; ``rel`` is height above the lip line."""
    ax = np.abs(x)
    h = 0.55 * np.exp(-(((y - 2.7 - 0.06 * x * x) / 0.9) ** 2)) * smoothstep(6.0, 4.5, ax)  # brow ridge
    h -= 0.35 * gauss(x, y, 0.0, 1.3, 0.9, 0.8)  # nasion
    for side in (-1.0, 1.0):
        h -= 1.05 * gauss(x, y, side * (EYE_XY[0] - 0.05), EYE_XY[1] - 0.1, 1.35, 1.0)  # eye socket
        h += 0.4 * gauss(x, y, side * 4.6, EYE_XY[1], 0.8, 1.5)  # lateral orbital rim
        h += 0.55 * gauss(x, y, side * 3.9, -2.3, 1.6, 1.3)  # cheekbone
        h += 0.75 * gauss(x, y, side * 1.25, -3.45, 0.5, 0.45)  # nose wing
        h -= 0.35 * gauss(x, y, side * 2.7, -4.6, 0.5, 1.4)  # nasolabial fold
    t = np.clip((1.4 - y) / 4.9, 0.0, 1.0)  # 0 at the nasion, 1 at the tip
    height = (0.45 + 1.55 * t**1.6) * smoothstep(-4.7, -3.6, y) * smoothstep(2.4, 1.2, y)
    width = 0.55 + 0.55 * t**2
    h += height * np.exp(-((x / width) ** 2))  # nose
    h += 0.7 * gauss(x, y, 0.0, MOUTH_Y, 2.6, 2.2)  # muzzle over the teeth
    h += 0.38 * inside * gauss(x * 0.5, rel, 0.0, 0.5, 1.0, 0.38)  # upper lip
    h += 0.42 * inside * gauss(x * 0.5, rel, 0.0, -0.55, 1.0, 0.45)  # lower lip
    h -= 0.22 * inside * np.exp(-((rel / 0.16) ** 2))  # lips meet, rolled in
    h -= 0.12 * gauss(x, rel, 0.0, 1.1, 0.3, 0.4)  # philtrum
    h -= 0.3 * gauss(x, rel, 0.0, -1.55, 1.4, 0.35)  # chin crease
    h += 0.6 * gauss(x, y, 0.0, -9.9, 1.5, 1.1)  # chin
    return h * front


def _lip_mask(x, rel):
    """1 on the lips, 0 off them, soft at the border."""
    top = 0.78 * np.sqrt(np.clip(1 - (x / 2.7) ** 2, 0, 1)) - 0.12 * np.exp(-((x / 0.35) ** 2))
    bottom = -0.95 * np.clip(1 - (x / 2.6) ** 2, 0, 1) ** 0.6
    return smoothstep(0.1, -0.06, rel - top) * smoothstep(-0.1, 0.06, rel - bottom) * smoothstep(2.75, 2.35, np.abs(x))


def _brow_mask(x, y):
    ax = np.abs(x)
    centre = 2.55 + 0.35 * np.sin(np.pi * np.clip((ax - 0.9) / 4.6, 0, 1))
    half = 0.34 - 0.12 * np.clip((ax - 1.0) / 4.4, 0, 1)
    along = smoothstep(0.8, 1.2, ax) * smoothstep(5.7, 5.2, ax)
    return along * smoothstep(half + 0.15, half - 0.15, np.abs(y - centre))


def skin(n_cols: int = 108, n_rows: int = 100) -> Part:
    """The head, face and neck stub as one grid with a slit between the lips.

    Returns a part whose params are ``rel`` (height above the lip line, cm),
    ``lower`` (True under the lip line, including the slit's lower copies),
    ``mouth`` (True for the slit vertices of both lips) and ``base`` (the
    surface before the face relief, (n, 3) cm).
    """
    t = np.linspace(-1.0, 1.0, n_cols, endpoint=False)
    az = np.pi * (0.5 * t + 0.5 * t**3)  # denser columns on the face
    el = np.linspace(-np.pi / 2, np.pi / 2, n_rows + 2)[1:-1]
    EL, AZ = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(EL) * np.sin(AZ), np.sin(EL), np.cos(EL) * np.cos(AZ)], -1).reshape(-1, 3)
    grid = (ORIGIN + _skin_distance(d)[:, None] * d).reshape(n_rows, n_cols, 3)
    # the lip line is the row nearest MOUTH_Y on the front column
    front_col = n_cols // 2
    row_m = int(np.argmin(np.abs(grid[:, front_col, 1] - MOUTH_Y)))
    slit_y = grid[row_m, :, 1]
    rel = grid[..., 1] - slit_y[None, :]
    x, y, z = grid[..., 0], grid[..., 1], grid[..., 2]
    front = smoothstep(0.25, 0.6, np.cos(AZ)) * smoothstep(-1.0, -0.2, np.sin(EL) - 0.0) * (z > 0)
    inside = smoothstep(MOUTH_HALF_WIDTH + 0.4, MOUTH_HALF_WIDTH - 0.2, np.abs(x))
    sculpted = grid.copy()
    sculpted[..., 2] += _face_relief(x, y, rel, inside, front)
    # slit: duplicate the lip-line vertices strictly between the corners
    slit_cols = np.flatnonzero(np.abs(grid[row_m, :, 0]) < MOUTH_HALF_WIDTH)
    slit_cols = slit_cols[np.abs(grid[row_m, slit_cols, 0]) < MOUTH_HALF_WIDTH - 1e-6]
    slit_cols = slit_cols[(slit_cols > 0) & (grid[row_m, slit_cols, 2] > 0)]
    n_grid = n_rows * n_cols
    idx = np.arange(n_grid).reshape(n_rows, n_cols)
    dup = np.full(n_cols, -1)
    dup[slit_cols] = n_grid + np.arange(len(slit_cols))
    bottom_pole, top_pole = n_grid + len(slit_cols), n_grid + len(slit_cols) + 1
    tris = _grid_triangles(idx, wrap=True)
    below = idx.copy()  # the quads under the lip line use the lower copies
    below[row_m, slit_cols] = dup[slit_cols]
    lower_band = _grid_triangles(below[row_m - 1 : row_m + 1], wrap=True)
    in_band = (tris.min(axis=1) >= idx[row_m - 1, 0]) & (tris.max(axis=1) <= idx[row_m, -1])
    tris = np.concatenate([tris[~in_band], lower_band])
    ring0, ring1 = idx[0], idx[-1]
    fan_bottom = np.stack([np.full(n_cols, bottom_pole), np.roll(ring0, -1), ring0], -1)
    fan_top = np.stack([np.full(n_cols, top_pole), ring1, np.roll(ring1, -1)], -1)
    tris = np.concatenate([tris, fan_bottom, fan_top])
    flat = sculpted.reshape(-1, 3)
    pole_dirs = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    poles = ORIGIN + _skin_distance(pole_dirs)[:, None] * pole_dirs
    vertices = np.concatenate([flat, flat[idx[row_m, slit_cols]], poles])
    base = np.concatenate([grid.reshape(-1, 3), grid[row_m, slit_cols], poles])
    rel_all = np.concatenate([rel.reshape(-1), np.zeros(len(slit_cols)), [-20.0, 20.0]])
    lower = np.concatenate([(rel < -1e-9).reshape(-1), np.ones(len(slit_cols), bool), [True, False]])
    mouth = np.zeros(len(vertices), bool)
    mouth[idx[row_m, slit_cols]] = True
    mouth[dup[slit_cols]] = True
    tris = orient_outward(vertices, tris, ORIGIN)
    # colours: skin, lips, brows, a little blush and darker nostrils
    vx, vy = vertices[:, 0], vertices[:, 1]
    fr = np.concatenate([front.reshape(-1), np.zeros(len(slit_cols) + 2)])
    lip = _lip_mask(vx, rel_all) * (fr > 0)
    brow = _brow_mask(vx, vy) * fr
    colors = np.tile(SKIN, (len(vertices), 1))
    blush = sum(gauss(vx, vy, s * 3.8, -2.6, 1.5, 1.2) for s in (-1, 1)) * fr
    colors *= (1 + 0.25 * blush[:, None] * np.array([0.3, -0.35, -0.3]))
    nostril = sum(gauss(vx, vy, s * 0.62, -4.15, 0.28, 0.2) for s in (-1, 1)) * fr
    colors *= 1 - 0.85 * np.clip(nostril, 0, 1)[:, None]
    colors = colors * (1 - lip[:, None]) + LIPS * lip[:, None]
    colors = colors * (1 - brow[:, None]) + BROW * brow[:, None]
    materials = np.where(lip[tris].mean(axis=1) > 0.5, "lips", "skin")
    params = {
        "rel": rel_all, "lower": lower, "mouth": mouth, "base": base, "front": fr,
        "slit_upper": idx[row_m, slit_cols], "slit_lower": dup[slit_cols],
        "corners": (idx[row_m, slit_cols[0] - 1], idx[row_m, slit_cols[-1] + 1]),
    }
    return Part(vertices, tris, colors, materials, params)


# -- eyes -------------------------------------------------------------------
def eye_centre(side: float) -> np.ndarray:
    """Centre of the eyeball on ``side`` (+1 the character's left, -1 right), cm."""
    return np.array([side * EYE_XY[0], EYE_XY[1], EYE_Z])


def eyeball(side: float, n_rings: int = 22, n_segments: int = 40) -> Part:
    """A sphere with its pole on +z: white, a blue iris disc and a black pupil."""
    # polar angle from +z, dense where the iris and pupil edges are
    theta = np.concatenate([[5, 9, 11, 16, 21, 25, 27, 29, 31, 36], np.linspace(44, 172, n_rings - 10)])
    theta = np.radians(theta)
    phi = np.linspace(0, 2 * np.pi, n_segments, endpoint=False)
    TH, PH = np.meshgrid(theta, phi, indexing="ij")
    unit = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1).reshape(-1, 3)
    unit = np.concatenate([unit, [[0, 0, 1.0], [0, 0, -1.0]]])
    idx = np.arange(len(theta) * n_segments).reshape(len(theta), n_segments)
    n = idx.size
    tris = _grid_triangles(idx, wrap=True)
    tris = np.concatenate([
        tris,
        np.stack([np.full(n_segments, n), idx[0], np.roll(idx[0], -1)], -1),
        np.stack([np.full(n_segments, n + 1), np.roll(idx[-1], -1), idx[-1]], -1),
    ])
    centre = eye_centre(side)
    vertices = centre + EYE_RADIUS * unit
    tris = orient_outward(vertices, tris, centre, each=True)
    ang = np.degrees(np.arccos(np.clip(unit[:, 2], -1, 1)))
    white = np.array([0.78, 0.74, 0.70]) * (1 - 0.25 * smoothstep(60, 140, ang))[:, None]
    iris = np.array([0.05, 0.16, 0.32]) * (0.6 + 0.4 * smoothstep(10, 24, ang))[:, None]
    colors = np.where((ang < 28.5)[:, None], iris, white)
    colors = np.where((ang < 10.0)[:, None], np.array([0.008, 0.008, 0.01]), colors)
    return Part(vertices, tris, colors, np.full(len(tris), "eye"))


def lid_margin(alpha: np.ndarray, upper: bool) -> np.ndarray:
    """Elevation (rad) of a lid margin at horizontal angle ``alpha`` (rad); 0 beyond the corners."""
    shape = np.cos(np.clip(alpha / LID_CORNER, -1, 1) * np.pi / 2) ** 1.5
    return (LID_UPPER if upper else LID_LOWER) * shape


def lid_points(side: float, alpha: np.ndarray, beta: np.ndarray, s: np.ndarray, upper: bool) -> np.ndarray:
    """Lid vertices on a shell around the eyeball, (n, 3) cm.

    ``s`` is 0 on the margin and 1 at the hidden edge; the margin rests on the
    eyeball and the shell stands a little off it behind the margin.
    """
    radius = EYE_RADIUS + np.where(s > 0, 0.13 + (0.02 if upper else 0.0), 0.035)
    local = np.stack([np.cos(beta) * np.sin(alpha), np.sin(beta), np.cos(beta) * np.cos(alpha)], -1)
    return eye_centre(side) + radius[:, None] * local


def lid_elevation(alpha: np.ndarray, s: np.ndarray, upper: bool, margin: np.ndarray | None = None) -> np.ndarray:
    """Elevation of lid vertices with parameters (alpha, s) for a given margin elevation."""
    m = lid_margin(alpha, upper) if margin is None else margin
    far = LID_TOP if upper else -LID_TOP
    return m + (far - m) * s


def eyelid(side: float, upper: bool, n_alpha: int = 29, n_s: int = 9) -> Part:
    """Upper or lower lid shell in front of the eyeball; params ``alpha``, ``s``."""
    alpha = np.radians(np.linspace(-82, 82, n_alpha))
    s = np.concatenate([[0.0], np.linspace(0.06, 1.0, n_s - 1)])
    S, A = np.meshgrid(s, alpha, indexing="ij")
    A, S = A.reshape(-1), S.reshape(-1)
    vertices = lid_points(side, A, lid_elevation(A, S, upper), S, upper)
    tris = _grid_triangles(np.arange(A.size).reshape(n_s, n_alpha), wrap=False)
    tris = orient_outward(vertices, tris, eye_centre(side), each=True)
    colors = np.tile(SKIN * np.array([1.0, 0.93, 0.92]), (len(vertices), 1))
    colors[S == 0] = BROW * 1.5  # lashes line the margin
    return Part(vertices, tris, colors, np.full(len(tris), "skin"), {"alpha": A, "s": S})


# -- mouth ------------------------------------------------------------------
def teeth(upper: bool, lip_z: float, slit_y: float) -> Part:
    """A row of teeth on a horizontal arc behind the lips; params ``gap``."""
    radius, span = (2.9, np.radians(48)) if upper else (2.5, np.radians(44))
    ang = np.linspace(-span, span, 41)
    heights = np.array([-0.2, -0.1, 0.4, 1.0]) if upper else np.array([0.05, -0.05, -0.4, -0.7])
    front_z = lip_z - (0.42 if upper else 0.6)
    H, A = np.meshgrid(heights, ang, indexing="ij")
    inset = np.where(H == heights[0], 0.05, 0.0)  # biting edge rounds inward
    vertices = np.stack([
        (radius - inset) * np.sin(A),
        slit_y + H,
        front_z - radius + (radius - inset) * np.cos(A),
    ], -1).reshape(-1, 3)
    tris = _grid_triangles(np.arange(A.size).reshape(H.shape), wrap=False)
    tris = orient_outward(vertices, tris, np.array([0.0, slit_y, front_z - radius]), each=True)
    tooth = np.abs(((np.degrees(A.reshape(-1)) / 8.0) + 0.5) % 1.0 - 0.5)  # 0 between teeth
    shade = 0.55 + 0.45 * smoothstep(0.0, 0.18, tooth)
    shade *= 1 - 0.5 * smoothstep(25, 50, np.abs(np.degrees(A.reshape(-1))))
    colors = np.array([0.80, 0.76, 0.66]) * shade[:, None]
    return Part(vertices, tris, colors, np.full(len(tris), "teeth"))


def mouth_bag(skin_part: Part) -> Part:
    """The dark inside of the mouth: a bag whose rim is the lip slit.

    Rings go back from the rim, widen to hold the teeth, then close. Params:
    ``rim`` (the skin vertex each bag vertex hangs from), ``t`` (0 on the rim,
    1 at the back) and ``sigma`` (+1 upper half, -1 lower, 0 at the corners).
    """
    upper, lower = skin_part.params["slit_upper"], skin_part.params["slit_lower"]
    right, left = skin_part.params["corners"]
    rim = np.concatenate([[right], upper, [left], lower[::-1]])
    sigma = np.concatenate([[0.0], np.ones(len(upper)), [0.0], -np.ones(len(lower))])
    p = skin_part.vertices[rim]
    half_x = np.abs(p[:, 0]).max()
    # depth behind the rim, half-heights above / below, width scale; the last ring closes the bag
    rings = np.array([
        [0.0, 0.0, 0.0, 1.0],
        [0.3, 0.55, 0.4, 0.94],
        [0.9, 1.3, 1.0, 0.92],
        [1.8, 1.55, 1.3, 0.86],
        [3.0, 1.25, 1.1, 0.7],
        [3.8, 0.5, 0.45, 0.3],
    ])
    arch = np.sqrt(np.clip(1 - (p[:, 0] / (half_x + 0.25)) ** 2, 0, 1))
    pts, ts = [], []
    for depth, up, down, width in rings:
        h = np.where(sigma > 0, up, np.where(sigma < 0, -down, 0.0)) * arch
        pts.append(np.stack([p[:, 0] * width, p[:, 1] + h, p[:, 2] - depth], -1))
        ts.append(np.full(len(rim), depth / rings[-1, 0]))
    back = np.array([[0.0, p[:, 1].mean(), p[:, 2].max() - rings[-1, 0] - 0.3]])
    vertices = np.concatenate(pts + [back])
    n_ring = len(rim)
    idx = np.arange(len(rings) * n_ring).reshape(len(rings), n_ring)
    tris = np.concatenate([
        _grid_triangles(idx, wrap=True),
        np.stack([np.full(n_ring, idx.size), idx[-1], np.roll(idx[-1], -1)], -1),
    ])
    centre = np.array([0.0, p[:, 1].mean(), p[:, 2].max() - 1.8])
    tris = orient_outward(vertices, tris, centre, each=True)[:, ::-1]  # seen from inside
    t = np.concatenate(ts + [[1.0]])
    sig = np.concatenate([np.tile(sigma, len(rings)), [0.0]])
    floor = smoothstep(0.1, 0.35, t) * smoothstep(0.95, 0.6, t) * (sig < 0)
    colors = np.array([0.05, 0.008, 0.008]) * (1 - floor[:, None]) + np.array([0.3, 0.06, 0.06]) * floor[:, None]
    params = {"rim": np.concatenate([np.tile(rim, len(rings)), [rim[0]]]), "t": t, "sigma": sig}
    return Part(vertices, tris, colors, np.full(len(tris), "mouth"), params)
