"""What a pinhole camera has in its field of view: the share of a cloud it sees
(:func:`view_share`) and the start check built on it (:class:`ViewCheck`), which keeps the
servo experiment's far starts to those that still see part of the reference. The
experiment (:mod:`spectral_vs.experiment`) and the simulated robot
(:meth:`spectral_vs.sim.PyBulletRobot.view_check`) both use them."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from spectral_vs._core import Kinematics


def view_share(
    points: np.ndarray,
    T_camera_points: np.ndarray,
    K: np.ndarray,
    image_size: tuple[int, int],
    depth_range: tuple[float, float] = (0.0, math.inf),
) -> float:
    """Share of ``points`` that a pinhole camera has in its field of view.

    A point counts when, moved into the camera frame, it lies between the depth limits and
    projects inside the image. Occlusion is ignored: a point hidden behind another one
    counts.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        The points in their own frame (e.g. the reference cloud, reference camera frame), m.
    T_camera_points : ndarray, shape (4, 4)
        Pose of the points' frame in the camera frame (Z forward, X right, Y down).
    K : ndarray, shape (3, 3)
        Camera matrix (fx, fy, cx, cy in pixels); pixel (u, v) covers [u - 0.5, u + 0.5).
    image_size : (int, int)
        Width and height, pixels.
    depth_range : (float, float)
        Depths seen, ``(near, far)``, m.

    Returns
    -------
    float
        The share in view, in [0, 1]; 0 for no points.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(points) == 0:
        return 0.0
    T = np.asarray(T_camera_points, dtype=float)
    p = points @ T[:3, :3].T + T[:3, 3]
    z = p[:, 2]
    near, far = depth_range
    in_depth = (z > max(near, 1e-9)) & (z < far)
    z_safe = np.where(in_depth, z, 1.0)
    u = K[0, 0] * p[:, 0] / z_safe + K[0, 2]
    v = K[1, 1] * p[:, 1] / z_safe + K[1, 2]
    width, height = image_size
    inside = (u >= -0.5) & (u < width - 0.5) & (v >= -0.5) & (v < height - 0.5)
    return float(np.count_nonzero(in_depth & inside)) / len(points)


class ViewCheck:
    """The start check of the sets with ``min_view_share``: a start configuration is
    accepted when its camera is at least ``min_camera_height`` above the base frame's
    z = 0 plane (the table top of the simulation: not inside or under the table) and sees
    at least ``min_share`` of the reference's points (:func:`view_share`: the reference
    cloud moved into the start camera frame by the kinematics, projected with the
    intrinsics, occlusion ignored).

    Parameters
    ----------
    kinematics : Kinematics
        Camera kinematics of the robot.
    q_reference : array_like, shape (n,)
        Configuration where the reference was captured, rad.
    reference_points : ndarray, shape (N, 3)
        The reference cloud's points, reference camera frame, m.
    K : ndarray, shape (3, 3)
        Camera matrix, pixels.
    image_size : (int, int)
        Width and height, pixels.
    depth_range : (float, float)
        Depths the camera sees, ``(near, far)``, m.
    min_share : float
        Share of the reference in view to accept a start, in (0, 1].
    min_camera_height : float
        Lowest accepted camera height above z = 0 of the base frame, m.
    """

    def __init__(
        self,
        kinematics: Kinematics,
        q_reference: Any,
        reference_points: np.ndarray,
        K: np.ndarray,
        image_size: tuple[int, int],
        *,
        depth_range: tuple[float, float] = (0.0, math.inf),
        min_share: float = 0.3,
        min_camera_height: float = 0.05,
    ) -> None:
        if not 0.0 < min_share <= 1.0:
            raise ValueError(f"min_share must be in (0, 1], got {min_share}")
        points = np.asarray(reference_points, dtype=float).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        if len(points) == 0:
            raise ValueError("reference_points must hold at least one finite point")
        self.kinematics = kinematics
        self.q_reference = np.asarray(q_reference, dtype=float)
        self.reference_points = points
        self.K = np.asarray(K, dtype=float)
        self.image_size = image_size
        self.depth_range = depth_range
        self.min_share = min_share
        self.min_camera_height = min_camera_height
        self._T_base_reference = np.asarray(kinematics.forward(self.q_reference))

    def share(self, q: np.ndarray) -> float:
        """Share of the reference's points in view of the camera at ``q`` (rad)."""
        T_base_camera = np.asarray(self.kinematics.forward(q))
        return view_share(
            self.reference_points,
            np.linalg.inv(T_base_camera) @ self._T_base_reference,
            self.K,
            self.image_size,
            self.depth_range,
        )

    def __call__(self, q: np.ndarray) -> bool:
        """Whether a start at ``q`` (rad) passes: camera above the table, view shared."""
        if np.asarray(self.kinematics.forward(q))[2, 3] < self.min_camera_height:
            return False
        return self.share(q) >= self.min_share


__all__ = ["ViewCheck", "view_share"]
