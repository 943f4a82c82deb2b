"""``facepuppet bench elastic``: the Yano & Harada (2009) elastic path measured on the ICT head.

Basis precomputation (the ICT head and a midpoint-subdivided head of more
than 100k vertices), per-frame CPU and draw cost of the elastic path versus
dense deltas, table memory, and reconstruction error per shape. Goals (the
issue's): median relative error < 10 % with 47 control points, truncation
adding < 1 %, tables at least 3x smaller than dense deltas.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np

from facepuppet.runtime.bench.render import measure_path, synthetic_performance

from facepuppet.offline.bench_data import add_data_argument, data_dir
from facepuppet.offline.elastic.basis import DEFAULT_FIXED_RATIO, DEFAULT_K, ElasticBasis
from facepuppet.offline.elastic.commands import main_front
from facepuppet.offline.elastic.control_points import ict_control_points
from facepuppet.offline.elastic.params import fit_character, target_fixed_mask
from facepuppet.offline.io.rig_import import import_rig


def midpoint_subdivide(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One level of midpoint subdivision: each triangle into four. Returns (vertices, triangles)."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = len(v) + inverse.reshape(3, -1).T  # (m, 3): midpoints of edges 01, 12, 20
    new_v = np.vstack([v, v[unique].mean(axis=1)])
    a, b, c = t.T
    ab, bc, ca = mid.T
    new_t = np.concatenate([np.stack(x, 1) for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return new_v, new_t


def _frame_costs(character, model, frames, width, height) -> dict:
    from facepuppet.runtime.render.gl_context import create_context  # GL: these import moderngl
    from facepuppet.runtime.render.renderer import FaceRenderer

    ctx = create_context(headless=True).ctx
    weights = synthetic_performance(frames, character.n_shapes)
    out = {}
    for path in ("elastic", "gpu", "cpu"):
        r = FaceRenderer(ctx, character, width, height, path=path, elastic=model, log=lambda s: None)
        m = measure_path(r, weights)
        out[path] = {"cpu_prepare_ms": m["cpu_prepare_ms"]["median"], "draw_finish_ms": m["draw_finish_ms"]["median"]}
        r.close()
    return out


def bench_elastic(args: argparse.Namespace) -> dict:
    ict = data_dir(args.data) / "ict-facekit"
    character = import_rig(ict / "generic_neutral_mesh.obj", ict)
    marks = json.loads((ict / "vertex_indices.json").read_text(encoding="utf-8"))["idx_to_landmark_verts"]
    points = ict_control_points(marks, character.vertices, character.triangles, main_front(character))
    start = time.perf_counter()
    model, basis, report = fit_character(character, points, k=args.k, fixed_ratio=args.fixed_ratio)
    result = {"ict": {k: v for k, v in report.items() if k != "shapes"}, "shapes": report["shapes"]}
    result["ict"]["fit_total_seconds"] = time.perf_counter() - start
    # A dense head: one midpoint subdivision of the ICT mesh (> 100k vertices).
    sv, st = midpoint_subdivide(character.vertices, character.triangles)
    t0 = time.perf_counter()
    dense_basis = ElasticBasis(k=args.k).fit(sv, st, points.vertices, target_fixed_mask(sv, points, args.fixed_ratio))
    result["subdivided"] = {"n_vertices": len(sv), "basis_seconds": dense_basis.solve_seconds_,
                            "total_seconds_with_compaction": time.perf_counter() - t0}
    result["frame"] = _frame_costs(character, model, args.frames, args.width, args.height)
    result["goals"] = {
        "median_relative_below_10pct": report["median_relative"] < 0.10,
        "truncation_adds_below_1pct": report["truncation_added_median"] < 0.01,
        "tables_3x_smaller": report["ratio"] >= 3.0,
    }
    _print(result)
    return result


def _print(r: dict) -> None:
    i = r["ict"]
    print(f"ICT head {i['n_vertices']} vertices, {i['n_controls']} controls, k={i['k']}: "
          f"basis {i['basis_seconds']:.2f} s; "
          f"subdivided {r['subdivided']['n_vertices']} vertices: basis {r['subdivided']['basis_seconds']:.1f} s")
    print(f"relative RMS error per shape: median {100 * i['median_relative']:.1f}% "
          f"worst {100 * i['worst_relative']:.1f}%; "
          f"RMS median {i['median_rms_cm']:.3f} cm, worst vertex {i['worst_cm']:.2f} cm; "
          f"truncation adds {100 * i['truncation_added_median']:.2f}% (median) "
          f"{100 * i['truncation_added_worst']:.2f}% (worst)")
    print(f"tables {i['compact_bytes'] / 1e6:.2f} MB vs dense deltas {i['dense_bytes'] / 1e6:.2f} MB: "
          f"{i['ratio']:.1f}x")
    for path, m in r["frame"].items():
        print(f"  {path:8s} prepare {m['cpu_prepare_ms']:.2f} ms, draw+finish {m['draw_finish_ms']:.2f} ms (median)")
    print("goals:", ", ".join(f"{k}={'yes' if v else 'NO'}" for k, v in r["goals"].items()))


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    add_data_argument(parser)
    parser.add_argument("--k", type=int, default=DEFAULT_K)
    parser.add_argument("--fixed-ratio", type=float, default=DEFAULT_FIXED_RATIO)
    parser.add_argument("--frames", type=int, default=60, help="frames per deformation path (60)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)


def register_benches(register_bench: Callable[..., None]) -> None:
    register_bench("elastic", bench_elastic, "elastic control-point model: basis time, frame cost, memory, error",
                   _add_arguments)
