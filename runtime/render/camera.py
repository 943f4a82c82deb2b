"""Camera and model matrices: perspective, look-at, framing a mesh, head pose.

All matrices are ndarray of shape (4, 4), float32, row-major, acting on
column vectors (``clip = proj @ view @ model @ [x, y, z, 1]``). Send them to
GLSL (column-major) as ``m.T.tobytes()``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.model.geometry import quat_to_matrix


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection; fov_y in degrees, aspect = width / height."""
    if not (0 < near < far) or aspect <= 0:
        raise ValueError(f"perspective: need 0 < near < far and aspect > 0, got {near}, {far}, {aspect}")
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4), dtype=np.float64)
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m.astype(np.float32)


def look_at(eye: np.ndarray, target: np.ndarray,
            up: np.ndarray | tuple[float, float, float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    """View matrix of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    side = np.cross(forward, up)
    side /= np.linalg.norm(side)
    true_up = np.cross(side, forward)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = side, true_up, -forward
    m[:3, 3] = -m[:3, :3] @ eye
    return m.astype(np.float32)


def model_matrix(rotation: np.ndarray | None = None, translation: np.ndarray | None = None,
                 pivot: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Head pose: rotate about ``pivot`` by quaternion (x, y, z, w), then translate.

    ``x' = R (x - pivot) + pivot + translation``; units are the character's.
    """
    m = np.eye(4)
    pivot = np.asarray(pivot, dtype=np.float64)
    if rotation is not None:
        r = quat_to_matrix(rotation)
        m[:3, :3] = r
        m[:3, 3] = pivot - r @ pivot
    if translation is not None:
        m[:3, 3] += np.asarray(translation, dtype=np.float64)
    return m.astype(np.float32)


@dataclass(frozen=True)
class Camera:
    """A framed camera.

    Attributes
    ----------
    eye : ndarray of shape (3,), float32, character units
    view : ndarray of shape (4, 4), float32
    projection : ndarray of shape (4, 4), float32
    """

    eye: np.ndarray
    view: np.ndarray
    projection: np.ndarray

    @property
    def view_projection(self) -> np.ndarray:
        return (self.projection @ self.view).astype(np.float32)


def frame_bounds(
    lo: np.ndarray, hi: np.ndarray, aspect: float, fov_y_deg: float = 27.0, margin: float = 1.12,
    elevation_deg: float = 8.0,
) -> Camera:
    """Camera on +z looking along -z at the box [lo, hi], fitting it with a margin.

    The camera is raised by ``elevation_deg`` about the box centre (a portrait
    view, slightly from above: an open mouth shows the lower teeth).

    Parameters
    ----------
    lo, hi : array_like of shape (3,), float, the box corners (character units)
    aspect : float, width / height of the target
    fov_y_deg : float, vertical field of view in degrees
    margin : float, >= 1; 1.12 leaves 12 % around the box
    elevation_deg : float, degrees the camera is raised above the box centre
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    centre = (lo + hi) / 2.0
    half = (hi - lo) / 2.0
    # a flat or point-like box (one triangle in a plane, a single vertex) still gets a camera in front of it
    half = np.maximum(half, 1e-3 * max(float(half.max()), 1e-3))
    tan_y = np.tan(np.radians(fov_y_deg) / 2.0)
    # Half height needed so the box's x and y extents both fit, seen at its front face.
    half_height = max(half[1], half[0] / aspect) * margin
    distance = half_height / tan_y + half[2]
    radius = float(np.linalg.norm(half))
    near = max(distance - radius * 1.5, distance * 0.01)
    far = distance + radius * 3.0
    elevation = np.radians(elevation_deg)
    eye = centre + distance * np.array([0.0, np.sin(elevation), np.cos(elevation)])
    return Camera(
        eye=eye.astype(np.float32),
        view=look_at(eye, centre),
        projection=perspective(fov_y_deg, aspect, near, far),
    )
