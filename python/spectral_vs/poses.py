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

from spectral_vs._core import rotation_angle, so3_exp, so3_log


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
    """``theta u`` of a rotation matrix: axis times angle, rad, angle in [0, pi]
    (:func:`spectral_vs.so3_log`, the C++ library's logarithm).

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        A rotation matrix (orthonormal within 1e-6, determinant +1).

    Returns
    -------
    ndarray, shape (3,)
        The rotation vector; its norm is the angle.
    """
    return so3_log(np.asarray(R, dtype=float))


def rotation_matrix(rotvec: npt.ArrayLike) -> np.ndarray:
    """The rotation ``exp(hat(rotvec))`` (Rodrigues' formula, :func:`spectral_vs.so3_exp`);
    ``rotvec`` in radians."""
    return so3_exp(np.asarray(rotvec, dtype=float))


def _pose(T: npt.ArrayLike, argument: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise ValueError(f"{argument} must be a 4x4 transform, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError(f"{argument} must be finite, got {T.tolist()}")
    # Products of inverses leave rounding in the last row: 1e-9 tolerates that alone.
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
        raise ValueError(f"{argument} must have the bottom row [0, 0, 0, 1], got {T[3].tolist()}")
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
        If a transform is not 4x4 or its rotation part is not a rotation (finite,
        orthonormal within 1e-6), ``center`` is not 3 numbers, or the translation between
        the poses overflows float64.
    """
    T = _pose(T, "T")
    point = np.zeros(3) if center is None else np.asarray(center, dtype=float)
    if point.shape != (3,) or not np.isfinite(point).all():
        raise ValueError(f"center must be 3 finite numbers (metres), got {point.tolist()}")
    with np.errstate(over="ignore", invalid="ignore"):  # checked below
        if T_true is None:
            R = T[:3, :3]
            offset = T[:3, 3] if center is None else R @ point + T[:3, 3] - point
        else:
            T_true = _pose(T_true, "T_true")
            R = T_true[:3, :3].T @ T[:3, :3]
            offset = T[:3, :3] @ point + T[:3, 3] - T_true[:3, :3] @ point - T_true[:3, 3]
    # hypot, not the norm of numpy, which squares: translations of 1e300 m gave inf.
    distance = math.hypot(*np.asarray(offset, dtype=float).tolist())
    if not math.isfinite(distance):
        raise ValueError(
            f"the translation between the poses overflows float64 (over 1e308 m): {offset.tolist()}"
        )
    try:
        angle = rotation_angle(R)
    except ValueError as error:
        which = (
            "T must be a rigid transform"
            if T_true is None
            else "T and T_true must be rigid transforms"
        )
        raise ValueError(f"{which}: {error}") from None
    return PoseError(distance, angle)
