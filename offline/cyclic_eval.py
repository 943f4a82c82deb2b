"""Cyclic retarget error (Ouzounis, Kiliadis & Mousas eq. 11, Fig. 5) over retargeting methods.

A source motion (weights of character A per frame) is retargeted to a target
character B and back to A, each direction by a model fitted on that
direction's training pairs (:mod:`.retarget_pairs`). The cyclic error

    e_d = 1 / (N_f N_v) Σ_f Σ_v ‖v_{f,v} − v'_{f,v}‖          (eq. 11)

compares A's vertices under the original weights (v) with those under the
weights that came back (v'), over the frames f and the vertices v that some
shape of A moves, in A's units.

Symbols and names: v, v' ``original``, ``returned`` (vertex positions); N_f
frames of ``motion``; N_v vertices of ``region``; e_d ``e_d``.

Targets of other morphology are built here: :func:`stylise` applies a smooth
non-linear spatial warp (bigger eyes, longer jaw, a cartoon taper) to a
character's neutral and to every shape consistently.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from facepuppet.runtime.channels import ChannelMap
from facepuppet.runtime.character import MATERIAL_KINDS, Character, sparse_deltas
from facepuppet.runtime.geometry import vertex_normals

from .kpls import KernelPLS
from .retarget_baselines import (FeaturePointRBF, KernelRidgeRetarget, LinearPLS, LinearRetarget,
                                 PCARBFRetarget)
from .retarget_pairs import feature_matrix, moving_vertices, training_pairs

REFERENCE = "KPLS rbf"


def default_methods() -> dict:
    """Method name -> factory of an unfitted regressor with ``fit``/``predict``."""
    return {
        "KPLS rbf": lambda: KernelPLS(kernel="rbf"),
        "KPLS poly": lambda: KernelPLS(kernel="poly", degree=2),
        "KPLS linear": lambda: KernelPLS(kernel="linear"),
        "Dutreve FP-RBF": FeaturePointRBF,
        "Deng PCA+RBF": PCARBFRetarget,
        "kernel ridge": KernelRidgeRetarget,
        "linear PLS": LinearPLS,
        "linear regression": LinearRetarget,
    }


def _centre_of_kind(character: Character, kind: str, side: float = 0.0) -> np.ndarray | None:
    codes = character.material_params[:, 2].astype(int)
    tri = character.triangles[np.isin(character.triangle_material, np.flatnonzero(codes == MATERIAL_KINDS[kind]))]
    v = character.vertices[np.unique(tri)]
    if side:
        v = v[np.sign(v[:, 0]) == side]
    return v.mean(axis=0).astype(np.float64) if len(v) else None


def stylise(character: Character, eye_scale: float = 1.35, jaw_stretch: float = 0.35,
            taper: float = 0.12, name: str | None = None) -> Character:
    """A cartoon version of ``character``: the same warp applied to the neutral and each shape.

    The warp f (units of the character) enlarges each eye region by up to
    ``eye_scale`` with a Gaussian fall-off, lengthens everything below the
    mouth by a soft ramp of slope ``jaw_stretch`` and widens the cranium /
    narrows the chin by ``taper``. Shape s becomes f(v + d_s) − f(v).
    """
    lo, hi = character.vertices.min(0).astype(np.float64), character.vertices.max(0).astype(np.float64)
    size = float(np.linalg.norm(hi - lo))
    eyes = [_centre_of_kind(character, "eye", s) for s in (1.0, -1.0)]
    mouth = _centre_of_kind(character, "teeth")
    mouth_y = float(mouth[1]) if mouth is not None else float(lo[1] + 0.35 * (hi[1] - lo[1]))
    radius = 0.08 * size

    def warp(p: np.ndarray) -> np.ndarray:
        q = p.astype(np.float64).copy()
        for c in eyes:
            if c is not None:
                r2 = ((p - c) ** 2).sum(1, keepdims=True)
                q += (p - c) * (eye_scale - 1.0) * np.exp(-r2 / radius ** 2)
        soft = 0.03 * size
        below = soft * np.logaddexp(0.0, (mouth_y - p[:, 1]) / soft)  # smooth max(0, mouth_y − y)
        q[:, 1] -= jaw_stretch * below
        q[:, 0] *= 1.0 + taper * np.tanh((p[:, 1] - mouth_y) / (0.15 * size))
        return q

    neutral = character.vertices.astype(np.float64)
    base = warp(neutral)
    tris = character.triangles.astype(np.int64)
    base_normals = vertex_normals(base, tris)
    dense = np.zeros((character.n_shapes, character.n_vertices, 3), np.float32)
    dense_n = np.zeros_like(dense)
    for s in range(character.n_shapes):
        sl = character.shape_slice(s)
        idx = character.delta_indices[sl].astype(np.int64)
        moved = neutral.copy()
        moved[idx] += character.delta_positions[sl]
        dense[s, idx] = (warp(moved[idx]) - base[idx]).astype(np.float32)
        shaped = base.copy()
        shaped[idx] += dense[s, idx]
        dense_n[s] = vertex_normals(shaped, tris) - base_normals
    offsets, indices, positions = sparse_deltas(dense)
    normals = np.concatenate([dense_n[s, indices[offsets[s]:offsets[s + 1]]] for s in range(character.n_shapes)])
    return Character(
        name=name or f"{character.name} (stylised)", units=character.units, vertices=base.astype(np.float32),
        triangles=character.triangles, triangle_material=character.triangle_material,
        vertex_color=character.vertex_color, material_names=character.material_names,
        material_params=character.material_params,
        pivot=warp(character.pivot[None].astype(np.float64))[0].astype(np.float32),
        shape_names=character.shape_names, delta_offsets=offsets, delta_indices=indices,
        delta_positions=positions, delta_normals=normals.astype(np.float32),
        metadata={"settings": {"stylised_from": character.name, "eye_scale": eye_scale,
                               "jaw_stretch": jaw_stretch, "taper": taper}},
    )


def motion_weights(frames, character: Character) -> np.ndarray:
    """Per-frame weights (n_frames, n_shapes) float64 of ``character`` driven by tracker frames by name."""
    frames = [f for f in frames if f.weights is not None]
    if not frames:
        raise ValueError("motion_weights: no frame carries weights")
    cmap = ChannelMap.build(frames[0].channels, character.shape_names)
    return np.stack([cmap.apply(f.weights) for f in frames]).astype(np.float64)


def cyclic_error(character: Character, motion: np.ndarray, returned: np.ndarray,
                 region: np.ndarray | None = None) -> float:
    """e_d (eq. 11), units of ``character``: mean vertex distance between two weight sequences.

    Parameters
    ----------
    motion, returned : ndarray of shape (n_frames, n_shapes), weights before and after the cycle
    region : vertex indices to average over (default: every vertex some shape moves)
    """
    if motion.shape != returned.shape:
        raise ValueError(f"cyclic_error: motion {motion.shape} and returned {returned.shape} differ in shape")
    region = moving_vertices(character, 0.0) if region is None else region
    D = character.dense_deltas()[:, region].reshape(character.n_shapes, -1).astype(np.float64)
    diff = (motion - returned) @ D  # v − v' per frame: the neutral cancels
    # Ouzounis eq. 11: e_d = 1/(N_f N_v) Σ_f Σ_v ‖v − v'‖
    return float(np.linalg.norm(diff.reshape(len(motion), len(region), 3), axis=2).mean())


def evaluate(source: Character, targets: dict, motion: np.ndarray, methods: dict | None = None,
             n_mixes: int = 300, seed: int = 0, k_source: int = 45, k_target: int = 37, log=None) -> list[dict]:
    """Cycle ``motion`` of ``source`` through every target with every method.

    Returns
    -------
    list of dict with keys target, method, e_d (source units), fit_s (both
    directions), predict_us_per_frame (both directions), n_components
    (KPLS only).
    """
    methods = methods or default_methods()
    region = moving_vertices(source, 0.0)
    rows = []
    for tname, target in targets.items():
        fwd = training_pairs(source, target, n_mixes=n_mixes, seed=seed, k_source=k_source, k_target=k_target)
        bwd = training_pairs(target, source, source_points=fwd.target_points, target_points=fwd.source_points,
                             n_mixes=n_mixes, seed=seed + 1)
        F_a, F_b = feature_matrix(source, fwd.source_points), feature_matrix(target, fwd.target_points)
        x_a = motion @ F_a.T
        for mname, factory in methods.items():
            t0 = time.perf_counter()
            there, back = factory().fit(fwd.X, fwd.Y), factory().fit(bwd.X, bwd.Y)
            t1 = time.perf_counter()
            w_b = there.predict(x_a)
            w_a = back.predict(w_b @ F_b.T)
            t2 = time.perf_counter()
            row = {"target": tname, "method": mname, "e_d": cyclic_error(source, motion, w_a, region),
                   "fit_s": t1 - t0, "predict_us_per_frame": 1e6 * (t2 - t1) / len(motion)}
            if hasattr(there, "n_components_"):
                row["n_components"] = [int(there.n_components_), int(back.n_components_)]
            rows.append(row)
            if log:
                log(f"  {tname:<22} {mname:<18} e_d {row['e_d']:.4f} {source.units}  fit {row['fit_s']:.2f} s")
    return rows


def improvements(rows: list[dict], reference: str = REFERENCE) -> dict:
    """{target: {method: 100 (e_method − e_ref) / e_method}}, percent, as the paper reports them."""
    out: dict = {}
    for target in dict.fromkeys(r["target"] for r in rows):
        errs = {r["method"]: r["e_d"] for r in rows if r["target"] == target}
        ref = errs.get(reference)
        if ref is None:
            continue
        out[target] = {m: (100.0 * (e - ref) / e if e > 0 else 0.0) for m, e in errs.items() if m != reference}
    return out


def format_table(rows: list[dict], units: str = "", reference: str = REFERENCE) -> str:
    """Plain-text table: e_d per method (rows) and target (columns), and the reference's improvement."""
    targets = list(dict.fromkeys(r["target"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    errs = {(r["target"], r["method"]): r["e_d"] for r in rows}
    imp = improvements(rows, reference)
    width = max(20, *(len(t) + 2 for t in targets))
    lines = [f"cyclic error e_d ({units}); in brackets: improvement of {reference} over the method",
             f"{'method':<20}" + "".join(f"{t:>{width}}" for t in targets)]
    for m in methods:
        cells = []
        for t in targets:
            pct = imp.get(t, {}).get(m)
            cells.append(f"{errs[(t, m)]:.4f}" + (f" ({pct:+.0f}%)" if pct is not None else "       "))
        lines.append(f"{m:<20}" + "".join(f"{c:>{width}}" for c in cells))
    return "\n".join(lines)


def bar_plot(rows: list[dict], path, units: str = "", size=(960, 480)) -> Path:
    """Grouped bar chart of e_d (one group per target, one bar per method), drawn with Pillow."""
    from PIL import Image, ImageDraw

    targets = list(dict.fromkeys(r["target"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    errs = {(r["target"], r["method"]): r["e_d"] for r in rows}
    W, H = size
    left, right, top, bottom = 60, 190, 30, 50
    img = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(img)
    top_val = max(errs.values()) * 1.1 or 1.0
    palette = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
               (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
    plot_h = H - top - bottom
    draw.line([(left, top), (left, H - bottom), (W - right, H - bottom)], fill="black")
    for i in range(5):
        v = top_val * i / 4
        y = H - bottom - plot_h * i / 4
        draw.line([(left - 4, y), (left, y)], fill="black")
        draw.text((4, y - 6), f"{v:.3f}", fill="black")
    group_w = (W - left - right) / max(len(targets), 1)
    bar_w = group_w * 0.8 / max(len(methods), 1)
    for g, t in enumerate(targets):
        x0 = left + g * group_w + group_w * 0.1
        for j, m in enumerate(methods):
            h = plot_h * errs[(t, m)] / top_val
            draw.rectangle([x0 + j * bar_w, H - bottom - h, x0 + (j + 1) * bar_w - 2, H - bottom],
                           fill=palette[j % len(palette)])
        draw.text((x0, H - bottom + 8), t, fill="black")
    for j, m in enumerate(methods):
        y = top + 16 * j
        draw.rectangle([W - right + 10, y, W - right + 20, y + 10], fill=palette[j % len(palette)])
        draw.text((W - right + 26, y - 1), m, fill="black")
    draw.text((left, 8), f"cyclic retarget error e_d ({units}), Ouzounis et al. eq. 11", fill="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path)
    return path
