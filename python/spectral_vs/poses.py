"""How far apart two poses are: one function, one order, units in the names.

:func:`pose_error` gives ``(translation_m, rotation_rad)``, the package's units (metres,
radians), as a :class:`PoseError` that also reads in millimetres and degrees::

    error = svs.pose_error(result.T_scene_model, T_true, center=model.centroid())
    error.translation_mm, error.rotation_deg
    t, r = svs.pose_error(np.linalg.inv(T_world_a) @ T_world_b)  # metres, radians
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt


class PoseError(NamedTuple):
    """The distance between two poses: translation in metres, rotation angle in radians.

    Unpacks as ``translation_m, rotation_rad``; :attr:`translation_mm` and
    :attr:`rotation_deg` are the same values in millimetres and degrees.
    """

    translation_m: float
    rotation_rad: float

    @property
    def translation_mm(self) -> float:
        """The translation error, millimetres."""
        return 1000.0 * self.translation_m

    @property
    def rotation_deg(self) -> float:
        """The rotation error, degrees."""
        return math.degrees(self.rotation_rad)


def rotation_vector(R: npt.ArrayLike) -> np.ndarray:
    """``theta u`` of a rotation matrix: axis times angle, rad, angle in [0, pi].

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        A rotation matrix.

    Returns
    -------
    ndarray, shape (3,)
        The rotation vector; its norm is the angle.
    """
    R = np.asarray(R, dtype=float)
    cos_angle = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = math.acos(cos_angle)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-6:
        return w / 2.0  # sin(angle) ~ angle
    if angle < math.pi - 1e-3:
        return w * (angle / (2.0 * math.sin(angle)))
    # Near pi the skew part vanishes: the axis is the dominant column of R + I.
    B = (R + np.eye(3)) / 2.0
    k = int(np.argmax(np.diag(B)))
    axis = B[:, k] / math.sqrt(max(B[k, k], 1e-12))
    if w @ axis < 0:
        axis = -axis
    return axis / np.linalg.norm(axis) * angle


def rotation_matrix(rotvec: npt.ArrayLike) -> np.ndarray:
    """The rotation ``exp(hat(rotvec))`` (Rodrigues' formula); ``rotvec`` in radians."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(rotvec))
    K = np.array(
        [[0.0, -rotvec[2], rotvec[1]], [rotvec[2], 0.0, -rotvec[0]], [-rotvec[1], rotvec[0], 0.0]]
    )
    if angle < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + math.sin(angle) / angle * K + (1.0 - math.cos(angle)) / angle**2 * (K @ K)


def _pose(T: npt.ArrayLike, argument: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise ValueError(f"{argument} must be a 4x4 transform, got shape {T.shape}")
    return T


def pose_error(
    T: npt.ArrayLike, T_true: npt.ArrayLike | None = None, *, center: npt.ArrayLike | None = None
) -> PoseError:
    """The translation (m) and rotation (rad) between two poses, or of one relative pose.

    Parameters
    ----------
    T : ndarray (4, 4)
        With ``T_true``: the estimated pose (e.g. ``T_scene_model``). Alone: a relative
        pose such as ``inv(T_world_a) @ T_world_b``, measured from the identity.
    T_true : ndarray (4, 4), optional
        The true pose, in the same frames as ``T``.
    center : ndarray (3,), optional
        The point, in the coordinates ``T`` moves (the model's, e.g. its centroid), at
        which the translation error is measured: ``|T center - T_true center|``. Default
        the origin: the distance between the two translation vectors.

    Returns
    -------
    PoseError
        ``(translation_m, rotation_rad)``: the distance between the moved centers, metres,
        and the angle of the rotation between the two poses (``R_true^T R``), radians in
        [0, pi]; ``.translation_mm`` and ``.rotation_deg`` give millimetres and degrees.

    Raises
    ------
    ValueError
        If a transform is not 4x4, or ``center`` is not 3 numbers.
    """
    T = _pose(T, "T")
    point = np.zeros(3) if center is None else np.asarray(center, dtype=float)
    if point.shape != (3,):
        raise ValueError(f"center must be 3 numbers (metres), got shape {point.shape}")
    if T_true is None:
        R = T[:3, :3]
        offset = T[:3, 3] if center is None else R @ point + T[:3, 3] - point
    else:
        T_true = _pose(T_true, "T_true")
        R = T_true[:3, :3].T @ T[:3, :3]
        offset = T[:3, :3] @ point + T[:3, 3] - T_true[:3, :3] @ point - T_true[:3, 3]
    return PoseError(float(np.linalg.norm(offset)), float(np.linalg.norm(rotation_vector(R))))
