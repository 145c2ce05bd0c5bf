"""Vectorised unit-quaternion helpers, (w, x, y, z) order, broadcasting over leading axes.

scipy's ``Rotation`` only takes flat batches and uses (x, y, z, w); motion arrays are ``(T, J, 4)``,
so these thin numpy functions keep the shapes and the order the rest of the package uses.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions with a non-negative w (one of the two antipodes, for stable comparisons)."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    q = q / np.where(n > 0, n, 1.0)
    return np.where(q[..., :1] < 0, -q, q)


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def conj(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion."""
    q = np.asarray(q, dtype=np.float64)
    inverse: np.ndarray = q * np.array([1.0, -1.0, -1.0, -1.0])
    return inverse


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v [..., 3]`` by unit quaternions ``q [..., 4]``."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    rotated: np.ndarray = v + w * t + np.cross(u, t)
    return rotated


def to_matrix(q: np.ndarray) -> np.ndarray:
    """``[..., 4]`` -> ``[..., 3, 3]``."""
    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(-1, 4)
    m = Rotation.from_quat(flat[:, [1, 2, 3, 0]]).as_matrix()
    matrices: np.ndarray = m.reshape((*q.shape[:-1], 3, 3))
    return matrices


def from_matrix(m: np.ndarray) -> np.ndarray:
    """``[..., 3, 3]`` -> ``[..., 4]`` (w >= 0)."""
    m = np.asarray(m, dtype=np.float64)
    flat = m.reshape(-1, 3, 3)
    xyzw = Rotation.from_matrix(flat).as_quat()
    return normalize(xyzw[:, [3, 0, 1, 2]].reshape((*m.shape[:-2], 4)))


def from_axis_angle(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vectors (axis * angle, radians) ``[..., 3]`` -> ``[..., 4]``."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(x/2)/x -> 1/2 as x -> 0; the series keeps small angles exact.
    scale = np.where(angle > 1e-8, np.sin(half) / np.where(angle > 1e-8, angle, 1.0), 0.5 - angle**2 / 48.0)
    return np.concatenate([np.cos(half), rotvec * scale], axis=-1)


def to_axis_angle(q: np.ndarray) -> np.ndarray:
    """``[..., 4]`` -> rotation vectors ``[..., 3]``, angle in [0, pi]."""
    q = normalize(q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    scale = np.where(s > 1e-8, angle / np.where(s > 1e-8, s, 1.0), 2.0)
    return q[..., 1:] * scale


def from_euler(order: str, angles_rad: np.ndarray) -> np.ndarray:
    """Intrinsic Euler angles (BVH convention: ``order`` like ``"ZXY"``, upper case) -> quaternions.

    ``angles_rad [..., 3]`` are in the same order as ``order``.
    """
    angles_rad = np.asarray(angles_rad, dtype=np.float64)
    order = order.upper()
    if len(order) != 3 or any(a not in "XYZ" for a in order):
        raise ValueError(f"Euler order must be 3 of X/Y/Z, got {order!r}")
    # Intrinsic a1-a2-a3 is the matrix product R_a1 @ R_a2 @ R_a3, i.e. q_a1 * q_a2 * q_a3; numpy here is ~20x
    # faster than scipy's from_euler on (T*J) batches.
    q1, q2, q3 = (_axis_quat(axis, angles_rad[..., k]) for k, axis in enumerate(order))
    return normalize(mul(mul(q1, q2), q3))


def _axis_quat(axis: str, angle_rad: np.ndarray) -> np.ndarray:
    """Quaternions ``[..., 4]`` of rotations by ``angle_rad [...]`` about one of the axes X, Y, Z."""
    half = 0.5 * angle_rad
    q = np.zeros((*angle_rad.shape, 4))
    q[..., 0] = np.cos(half)
    q[..., 1 + "XYZ".index(axis)] = np.sin(half)
    return q


def to_euler(order: str, q: np.ndarray) -> np.ndarray:
    """Quaternions -> intrinsic Euler angles (radians) in ``order``; inverse of :func:`from_euler`."""
    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(-1, 4)
    ang = Rotation.from_quat(flat[:, [1, 2, 3, 0]]).as_euler(order.upper())
    angles_rad: np.ndarray = ang.reshape((*q.shape[:-1], 3))
    return angles_rad


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation from ``a`` (t=0) to ``b`` (t=1), shortest path, broadcasting ``t``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None] if np.ndim(t) else float(t)
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-6
    safe = np.where(small, 1.0, sin_t)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(small, t, np.sin(t * theta) / safe)
    return normalize(wa * a + wb * b)


def between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction ``u`` to direction ``v`` (both ``[..., 3]``)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    w = 1.0 + np.sum(u * v, axis=-1, keepdims=True)
    axis = np.cross(u, v)
    # Opposite vectors: any axis orthogonal to u.
    ortho = np.cross(u, np.array([1.0, 0.0, 0.0]))
    ortho = np.where(
        np.linalg.norm(ortho, axis=-1, keepdims=True) < 1e-6, np.cross(u, np.array([0.0, 1.0, 0.0])), ortho
    )
    opposite = w < 1e-9
    q = np.concatenate([np.where(opposite, 0.0, w), np.where(opposite, ortho, axis)], axis=-1)
    return normalize(q)
