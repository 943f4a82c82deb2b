"""Mesh maths shared by the importer, the CPU deformation path and the renderer, and the one smoothstep."""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals.

    Parameters
    ----------
    vertices : ndarray of shape (n_vertices, 3), float
    triangles : ndarray of shape (n_triangles, 3), int, counter-clockwise seen from outside

    Returns
    -------
    normals : ndarray of shape (n_vertices, 3), float32; zero for vertices in no triangle.
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    # cross product length is twice the area: summing unnormalised face
    # normals weights each face by its area.
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n = np.zeros_like(v)
    for corner in range(3):
        np.add.at(n, t[:, corner], face)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.maximum(length, 1e-30)).astype(np.float32)


def incidence_matrix(n_vertices: int, triangles: np.ndarray) -> sp.csr_matrix:
    """Sparse (n_vertices, n_triangles) matrix with a 1 where a vertex is a corner of a face.

    ``incidence @ face_normals`` sums face normals onto vertices; it is the
    fast form of :func:`vertex_normals` when the topology is fixed.
    """
    t = np.asarray(triangles, dtype=np.int64)
    rows = t.reshape(-1)
    cols = np.repeat(np.arange(len(t)), 3)
    data = np.ones(len(rows), dtype=np.float32)
    return sp.csr_matrix((data, (rows, cols)), shape=(n_vertices, len(t)))


def bounds(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) corners of the axis-aligned box, each (3,) float64, ignoring NaN."""
    v = np.asarray(vertices, dtype=np.float64)
    return np.nanmin(v, axis=0), np.nanmax(v, axis=0)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) float64 of a quaternion (x, y, z, w); normalised first."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / max(np.linalg.norm(q), 1e-30)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) float64, w >= 0, of a rotation matrix (3, 3) (Shepperd's method)."""
    m = np.asarray(m, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        q = np.empty(4)
        q[i] = 0.25 * s
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
        q[3] = (m[k, j] - m[j, k]) / s
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def euler_to_quat(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Quaternion (x, y, z, w) float64 of head yaw (about +y), pitch (about +x), roll (about +z), radians.

    Applied in the order roll, then pitch, then yaw (R = Ry · Rx · Rz).
    """
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp_ = np.cos(pitch / 2), np.sin(pitch / 2)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    qy = np.array([0.0, sy, 0.0, cy])
    qx = np.array([sp_, 0.0, 0.0, cp])
    qz = np.array([0.0, 0.0, sr, cr])
    return quat_mul(quat_mul(qy, qx), qz)


def quat_to_euler(q: np.ndarray) -> tuple[float, float, float]:
    """(yaw, pitch, roll) radians of a quaternion (x, y, z, w): the inverse of :func:`euler_to_quat`.

    With R = Ry(yaw) · Rx(pitch) · Rz(roll): R[1, 2] = -sin(pitch), R[1, 0] / R[1, 1] = tan(roll),
    R[0, 2] / R[2, 2] = tan(yaw); pitch in [-pi/2, pi/2]. ``q`` need not be unit length.
    """
    x, y, z, w = (float(c) for c in q)
    n = x * x + y * y + z * z + w * w
    s = 2.0 / n if n > 0 else 0.0
    r12 = s * (y * z - w * x)
    r10, r11 = s * (x * y + w * z), 1.0 - s * (x * x + z * z)
    r02, r22 = s * (x * z + w * y), 1.0 - s * (x * x + y * y)
    pitch = math.asin(min(max(-r12, -1.0), 1.0))
    return math.atan2(r02, r22), pitch, math.atan2(r10, r11)


def smoothstep(e0: float, e1: float, x: float | np.ndarray) -> float | np.ndarray:
    """Hermite step 3t² - 2t³ of t = (x - e0) / (e1 - e0) clamped to [0, 1]: 0 at ``e0``, 1 at ``e1``.

    Either order of the edges; zero slope at both, the largest slope 1.5 / |e1 - e0| half way.

    Parameters
    ----------
    e0, e1 : float, the edges, units of x
    x : float, or ndarray of any shape, float; a float gives a float without a NumPy call (the
        live pipeline eases with it per frame), an array gives an ndarray of its shape, float64
    """
    if isinstance(x, (int, float)):
        t = min(max((x - e0) / (e1 - e0), 0.0), 1.0)
        return t * t * (3.0 - 2.0 * t)
    t = np.clip((np.asarray(x, dtype=np.float64) - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def nlerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Normalised linear interpolation of quaternions (x, y, z, w), shortest way round."""
    if float(np.dot(a, b)) < 0:
        b = -b
    q = (1.0 - s) * a + s * b
    return q / max(float(np.linalg.norm(q)), 1e-12)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a·b of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )
