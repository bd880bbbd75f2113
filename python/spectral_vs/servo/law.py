"""The decoupled control law: the camera twist from the estimate, saturated to the speed
limits, and the rigid inverse the servo carries estimates with."""

from __future__ import annotations

from typing import Any

import numpy as np


def _rigid_inverse(T: np.ndarray) -> np.ndarray:
    """The inverse of a rigid 4 x 4 transform, ``[R^T | -R^T t]``."""
    inverse = np.eye(4)
    inverse[:3, :3] = T[:3, :3].T
    inverse[:3, 3] = -(T[:3, :3].T @ T[:3, 3])
    return inverse


def _saturated_twist(
    translation: np.ndarray, rotvec: np.ndarray, law: Any
) -> tuple[np.ndarray, float]:
    """``(lambda_t t, lambda_r theta u)`` scaled down as a whole to the speed limits, and
    the scale; ``law`` has the gains ``lambda_t``, ``lambda_r`` (1/s) and the limits
    ``max_linear_speed`` (m/s), ``max_angular_speed`` (rad/s) (:meth:`SpectralServo.twist`)."""
    v = law.lambda_t * np.asarray(translation, dtype=float)
    omega = law.lambda_r * np.asarray(rotvec, dtype=float)
    scale = 1.0
    speed, turn = float(np.linalg.norm(v)), float(np.linalg.norm(omega))
    if speed > law.max_linear_speed:
        scale = min(scale, law.max_linear_speed / speed)
    if turn > law.max_angular_speed:
        scale = min(scale, law.max_angular_speed / turn)
    return np.concatenate([v, omega]) * scale, scale
