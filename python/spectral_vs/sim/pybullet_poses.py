"""Poses as PyBullet gives and takes them: a position and an (x, y, z, w) quaternion."""

from __future__ import annotations

import math

import numpy as np


def pose_matrix(position, quaternion) -> np.ndarray:
    """4 x 4 transform from a PyBullet position and (x, y, z, w) quaternion.

    PyBullet's quaternions are unit length only to float precision (about 1e-7); the
    quaternion is normalised so that the rotation is orthonormal to double precision.

    Parameters
    ----------
    position : array_like, shape (3,)
        Translation, metres.
    quaternion : array_like, shape (4,)
        Rotation as PyBullet orders it: (x, y, z, w); any non-zero length.

    Returns
    -------
    ndarray, shape (4, 4)
        The rigid transform.
    """
    x, y, z, w = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = position
    return T


def quaternion(R: np.ndarray) -> list[float]:
    """(x, y, z, w) quaternion of a rotation matrix (Shepperd's method: from the largest of
    the trace and the diagonal terms, robust at every angle)."""
    trace = float(np.trace(R))
    k = int(np.argmax(np.diag(R)))
    if trace >= R[k, k]:
        s = math.sqrt(1.0 + trace) * 2.0
        return [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    i, j = (k + 1) % 3, (k + 2) % 3
    s = math.sqrt(1.0 + R[k, k] - R[i, i] - R[j, j]) * 2.0
    q = [0.0, 0.0, 0.0, (R[j, i] - R[i, j]) / s]
    q[k] = s / 4.0
    q[i] = (R[i, k] + R[k, i]) / s
    q[j] = (R[j, k] + R[k, j]) / s
    return q
