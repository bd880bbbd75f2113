"""Servo controllers the spectral servo is measured against (benchmarks/servo_peers.py).

Both controllers here have the interface of :class:`~spectral_vs.servo.SpectralServo`
(``reset()``, ``step(current) -> (twist, status)``, ``step_record(current,
T_previous_current, *, now, stamp) -> (twist, status, record)``), so
:func:`~spectral_vs.servo.run_servo` drives them unchanged, and they fill the same
:class:`~spectral_vs.servo.ServoRecord`. They do not ride sensor faults: ``now`` and
``stamp`` are accepted and not used, and an input with too little in it stops them at once
(``"empty_cloud"``, ``"too_few_points"``).
The twist is the camera velocity ``(v, omega)`` in the current camera frame, m/s and rad/s,
as :meth:`Kinematics.joint_velocities` takes it.

:class:`DenseDepthServo`
    The dense, direct visual servo on depth maps of Teuliere and Marchand ("A dense and
    direct approach to visual servoing using depth maps", IEEE T-RO 30(5), 2014): the
    depth image itself is the feature, one interaction-matrix row per pixel, and a
    Gauss-Newton / Levenberg-Marquardt law. No registration, no correspondences, no
    pose: the baseline the paper argues against.

:class:`RegistrationServo`
    Position-based servoing (the law of :class:`SpectralServo`) on a pose from Open3D:
    point-to-plane ICP (``method="icp"``) or FPFH features + RANSAC followed by
    point-to-plane ICP (``method="fpfh"``). Open3D is an optional dependency (the
    ``bench`` extra) imported only when such a controller is built.
"""

from __future__ import annotations

import importlib
import math
import time
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.clouds import as_cloud
from spectral_vs.poses import pose_error, rotation_matrix, rotation_vector
from spectral_vs.servo.law import _saturated_twist
from spectral_vs.servo.records import (
    ServoRecord,
    ServoStatus,
    _converged_status,
    _empty_record,
    _too_few_points,
)
from spectral_vs.servo.setting_checks import check_positive

InteractionKind = Literal["current", "desired", "mean"]
RegistrationMethod = Literal["icp", "fpfh"]


class Intrinsics(Protocol):
    """What the depth servo needs of a pinhole camera (e.g. ``sim.CameraIntrinsics``):
    image size in pixels, focal lengths and principal point in pixels (column ``u`` sees
    ``x = (u - cx) / fx``, row ``v`` sees ``y = (v - cy) / fy``)."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def fx(self) -> float: ...
    @property
    def fy(self) -> float: ...
    @property
    def cx(self) -> float: ...
    @property
    def cy(self) -> float: ...


# --------------------------------------------------------------------------- shared law


@dataclass(kw_only=True)
class _Law:
    """The law, its saturation and the convergence tolerances of both peers, with the
    defaults of :class:`ServoParams` (documented in each peer's settings)."""

    lambda_t: float = 2.0
    lambda_r: float = 4.0
    max_linear_speed: float = 0.1
    max_angular_speed: float = math.radians(20.0)
    translation_tolerance: float = 0.001
    rotation_tolerance: float = math.radians(0.2)


# --------------------------------------------------------------------------- depth maps


def depth_image_from_cloud(cloud: PointCloud | np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """The organized depth image (H, W) of a camera-frame cloud, metres, NaN where empty.

    Each point is projected with the pinhole model and rounded to its pixel; where several
    points fall on one pixel the nearest wins. A cloud made from a depth image of the same
    camera (``sim.depth_to_cloud``) gives that image back on the pixels it kept.

    Parameters
    ----------
    cloud : PointCloud or ndarray (N, 3)
        Points in the camera frame (Z forward), metres.
    intrinsics : Intrinsics
        The camera.

    Returns
    -------
    ndarray, shape (height, width)
        Depth along the optical axis, metres.
    """
    points = np.asarray(cloud.points if isinstance(cloud, PointCloud) else cloud, dtype=float)
    h, w = intrinsics.height, intrinsics.width
    depth = np.full((h, w), np.inf)
    if len(points):
        z = points[:, 2]
        front = np.isfinite(points).all(axis=1) & (z > 0)
        p, z = points[front], z[front]
        u = np.rint(intrinsics.fx * p[:, 0] / z + intrinsics.cx).astype(np.int64)
        v = np.rint(intrinsics.fy * p[:, 1] / z + intrinsics.cy).astype(np.int64)
        inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
        np.minimum.at(depth, (v[inside], u[inside]), z[inside])
    depth[~np.isfinite(depth)] = np.nan
    return depth


def normalized_coordinates(intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Normalized image coordinates ``x = X/Z`` (1, W) and ``y = Y/Z`` (H, 1) of the pixels."""
    x = (np.arange(intrinsics.width) - intrinsics.cx) / intrinsics.fx
    y = (np.arange(intrinsics.height) - intrinsics.cy) / intrinsics.fy
    return x[np.newaxis, :], y[:, np.newaxis]


def depth_gradients(
    depth: np.ndarray, intrinsics: Intrinsics, step: int = 1, max_depth_jump: float = 0.05
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradients ``Z_x = dZ/dx``, ``Z_y = dZ/dy`` of a depth image in normalized image
    coordinates, by central differences, and where they are valid.

    ``Z_x = fx (Z[v, u + s] - Z[v, u - s]) / (2 s)`` (and likewise along the rows with
    ``fy``), ``s = step`` pixels. A pixel is valid when it and its four neighbours have a
    depth and no neighbour differs from it by more than ``max_depth_jump`` times its
    depth: missing pixels and depth discontinuities (silhouettes, where the depth map is
    not differentiable) are masked out, as is a border of ``step`` pixels.

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Planar depth, metres, NaN = missing.
    intrinsics : Intrinsics
        Focal lengths (pixels) for the change to normalized coordinates.
    step : int
        Half-baseline of the differences, pixels (>= 1).
    max_depth_jump : float
        Largest relative depth change to a neighbour (fraction of the depth).

    Returns
    -------
    Zx, Zy : ndarray, shape (H, W)
        Gradients, metres per unit of normalized coordinate; 0 where not valid.
    valid : ndarray of bool, shape (H, W)
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    Z = np.asarray(depth, dtype=float)
    h, w = Z.shape
    Zx, Zy = np.zeros_like(Z), np.zeros_like(Z)
    valid = np.zeros((h, w), dtype=bool)
    s = step
    if h <= 2 * s or w <= 2 * s:
        return Zx, Zy, valid
    centre = Z[s:-s, s:-s]
    right, left = Z[s:-s, 2 * s :], Z[s:-s, : -2 * s]
    down, up = Z[2 * s :, s:-s], Z[: -2 * s, s:-s]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(centre)
        limit = max_depth_jump * centre
        for neighbour in (right, left, down, up):
            ok &= np.abs(neighbour - centre) <= limit
    inner = (slice(s, h - s), slice(s, w - s))
    Zx[inner] = np.where(ok, intrinsics.fx * (right - left) / (2 * s), 0.0)
    Zy[inner] = np.where(ok, intrinsics.fy * (down - up) / (2 * s), 0.0)
    valid[inner] = ok
    return Zx, Zy, valid


def depth_interaction_matrix(
    Z: np.ndarray, Zx: np.ndarray, Zy: np.ndarray, x: np.ndarray, y: np.ndarray
) -> np.ndarray:
    """Interaction matrix of the depth map: one row per pixel, ``dZ/dt = L_Z (v, omega)``.

    The feature is the depth ``Z(x, y, t)`` read at a fixed pixel (normalized coordinates
    ``x, y``) while the camera moves with the twist ``(v, omega)`` in its own frame. The
    scene point seen there, ``X = (xZ, yZ, Z)``, moves in the camera frame as
    ``dX/dt = -v - omega x X``, so its own depth changes by

        dZ_point/dt = L_P (v, omega),   L_P = [0, 0, -1, -yZ, xZ, 0],

    and its image moves by the classical point interaction matrices

        dx/dt = L_x (v, omega),   L_x = [-1/Z, 0, x/Z, xy, -(1 + x^2), y],
        dy/dt = L_y (v, omega),   L_y = [0, -1/Z, y/Z, 1 + y^2, -xy, -x].

    The depth map follows the point: ``Z(x + dx, y + dy, t + dt) = Z + dZ_point``, so at the
    fixed pixel ``dZ/dt = dZ_point/dt - Z_x dx/dt - Z_y dy/dt``, i.e.
    ``L_Z = L_P - Z_x L_x - Z_y L_y``:

        L_Z = [ Z_x / Z,
                Z_y / Z,
                -(Z + x Z_x + y Z_y) / Z,
                -y Z - x y Z_x - (1 + y^2) Z_y,
                 x Z + (1 + x^2) Z_x + x y Z_y,
                 x Z_y - y Z_x ]

    (Teuliere and Marchand 2014, the depth-map feature; ``Z_x, Z_y`` are the gradients of
    the depth map in normalized coordinates, :func:`depth_gradients`).
    ``benchmarks/tests/test_peer_servos.py`` checks it against finite differences of a rendered
    surface.

    Parameters
    ----------
    Z, Zx, Zy, x, y : ndarray, shape (N,)
        Depth (m), its gradients (m per normalized unit) and the normalized coordinates of
        each pixel.

    Returns
    -------
    ndarray, shape (N, 6)
        Rows ``L_Z``; columns ``(v_x, v_y, v_z, omega_x, omega_y, omega_z)``.
    """
    Z, Zx, Zy, x, y = (np.asarray(a, dtype=float) for a in (Z, Zx, Zy, x, y))
    L = np.empty((Z.size, 6))
    L[:, 0] = Zx / Z
    L[:, 1] = Zy / Z
    L[:, 2] = -(Z + x * Zx + y * Zy) / Z
    L[:, 3] = -y * Z - x * y * Zx - (1.0 + y * y) * Zy
    L[:, 4] = x * Z + (1.0 + x * x) * Zx + x * y * Zy
    L[:, 5] = x * Zy - y * Zx
    return L


@dataclass
class DepthServoParams(_Law):
    """Settings of :class:`DenseDepthServo`.

    Attributes
    ----------
    lambda_t, lambda_r : float
        Gains, 1/s. The Gauss-Newton step ``xi = -(L^T L + mu diag(L^T L))^-1 L^T e`` is the
        first-order camera displacement ``(t, theta u)`` to the desired pose; the law is
        ``v = lambda_t xi_t``, ``omega = lambda_r xi_r`` (Teuliere and Marchand's
        ``v = -lambda (...)^-1 L^T e`` with one gain per part, the gains of
        :class:`ServoParams`).
    mu : float
        Levenberg-Marquardt damping (0: Gauss-Newton).
    interaction : {"current", "desired", "mean"}
        Where ``L_Z`` is evaluated: at the current depth map (its depth and gradients), at
        the desired one, or the mean of the two.
    gradient_step : int
        Half-baseline of the central differences of the depth gradients, pixels.
    max_depth_jump : float
        Depth discontinuity mask: largest relative depth change to a gradient neighbour.
    max_depth : float
        Pixels deeper than this (either map) are ignored, m (as ``ServoParams.max_depth``).
    pixel_stride : int
        Use every ``pixel_stride``-th pixel along rows and columns (1 = all).
    translation_tolerance, rotation_tolerance : float
        Converged when the Gauss-Newton step is below both (m, rad) ...
    min_fitness : float
        ... and at least this share of the reference's valid pixels were used (valid in both
        maps): a small step on a small overlap is no arrival.
    max_linear_speed, max_angular_speed : float
        Saturation of ``|v|`` (m/s) and ``|omega|`` (rad/s), the twist scaled as a whole.
    min_pixels : int
        Stop (``"too_few_points"``) when fewer pixels are valid in both maps.
    """

    mu: float = 0.0
    interaction: InteractionKind = "current"
    gradient_step: int = 1
    max_depth_jump: float = 0.05
    max_depth: float = 1.5
    pixel_stride: int = 1
    min_fitness: float = 0.8
    min_pixels: int = 500

    def __post_init__(self) -> None:
        if self.interaction not in ("current", "desired", "mean"):
            raise ValueError(
                f"interaction must be 'current', 'desired' or 'mean', got {self.interaction!r}"
            )
        check_positive(
            self,
            (
                "lambda_t",
                "lambda_r",
                "max_depth_jump",
                "max_depth",
                "translation_tolerance",
                "rotation_tolerance",
                "max_linear_speed",
                "max_angular_speed",
            ),
        )
        if not self.mu >= 0:
            raise ValueError(f"mu must be >= 0, got {self.mu}")
        if self.gradient_step < 1 or self.pixel_stride < 1 or self.min_pixels < 1:
            raise ValueError("gradient_step, pixel_stride and min_pixels must be >= 1")
        if not 0.0 <= self.min_fitness <= 1.0:
            raise ValueError(f"min_fitness must be in [0, 1], got {self.min_fitness}")


class DenseDepthServo:
    """The dense depth-map visual servo (Teuliere and Marchand 2014).

    Per step: the error ``e = Z - Z*`` on the pixels valid in both depth maps (depth within
    ``max_depth``, gradients valid: no missing neighbour, no discontinuity), the interaction
    matrix ``L`` of :func:`depth_interaction_matrix` on those pixels, the Levenberg-Marquardt
    step ``xi = -(H + mu diag H)^-1 L^T e`` with ``H = L^T L``, and the twist
    ``(lambda_t xi_t, lambda_r xi_r)`` saturated as in :class:`SpectralServo`.

    The record's fields: ``T_current_desired`` is ``exp(xi)`` (the first-order estimate of
    the pose of the desired camera), ``translation_error``, ``rotation_error`` its size,
    ``translation_cost`` the RMS depth error over the used pixels (m), ``fitness`` the
    share of the reference's valid pixels used, ``points`` the number used.

    Parameters
    ----------
    reference : ndarray (H, W) or PointCloud
        Depth image captured at the desired pose (metres, NaN = missing), or a cloud in
        that camera frame, turned back into the depth image (:func:`depth_image_from_cloud`).
    intrinsics : Intrinsics
        The camera (``sim.CameraIntrinsics``); the images must be height x width.
    params : DepthServoParams, optional
    """

    def __init__(
        self,
        reference: np.ndarray | PointCloud,
        intrinsics: Intrinsics,
        params: DepthServoParams | None = None,
    ) -> None:
        self.params = params if params is not None else DepthServoParams()
        self.intrinsics = intrinsics
        self._x, self._y = normalized_coordinates(intrinsics)
        self.reference = self._depth(reference, "reference")
        self._ref_Zx, self._ref_Zy, ref_valid = depth_gradients(
            self.reference, intrinsics, self.params.gradient_step, self.params.max_depth_jump
        )
        with np.errstate(invalid="ignore"):
            self._ref_valid = ref_valid & (self.reference <= self.params.max_depth)
        s = self.params.pixel_stride
        self._ref_count = int(self._ref_valid[::s, ::s].sum())
        if self._ref_count < self.params.min_pixels:
            raise ValueError(
                f"reference has {self._ref_count} valid pixels, fewer than min_pixels = "
                f"{self.params.min_pixels}"
            )
        self._steps = 0

    def _depth(self, image: np.ndarray | PointCloud, argument: str) -> np.ndarray:
        if isinstance(image, PointCloud):
            return depth_image_from_cloud(image, self.intrinsics)
        depth = np.asarray(image, dtype=float)
        expected = (self.intrinsics.height, self.intrinsics.width)
        if depth.shape == expected:
            return depth
        if depth.ndim == 2 and depth.shape[1] in (3, 6):  # an (N, 3) / (N, 6) cloud
            return depth_image_from_cloud(depth[:, :3], self.intrinsics)
        raise ValueError(
            f"{argument} must be a depth image of shape {expected} or a cloud, got "
            f"shape {depth.shape}"
        )

    def reset(self) -> None:
        """Forget the step count (the law has no other memory)."""
        self._steps = 0

    def gauss_newton_step(self, current: np.ndarray) -> tuple[np.ndarray, float, int]:
        """The Levenberg-Marquardt step ``xi`` (6,), the RMS depth error (m) and the number
        of pixels used, for a current depth image (H, W)."""
        p = self.params
        Zx, Zy, valid = depth_gradients(current, self.intrinsics, p.gradient_step, p.max_depth_jump)
        with np.errstate(invalid="ignore"):
            valid &= self._ref_valid & (current <= p.max_depth)
        s = p.pixel_stride
        if s > 1:
            thinned = np.zeros_like(valid)
            thinned[::s, ::s] = valid[::s, ::s]
            valid = thinned
        count = int(valid.sum())
        if count == 0:
            return np.zeros(6), math.nan, 0
        rows, cols = np.nonzero(valid)
        x, y = self._x[0, cols], self._y[rows, 0]
        Z = current[rows, cols]
        e = Z - self.reference[rows, cols]
        if p.interaction == "current":
            L = depth_interaction_matrix(Z, Zx[rows, cols], Zy[rows, cols], x, y)
        else:
            Zd = self.reference[rows, cols]
            L = depth_interaction_matrix(
                Zd, self._ref_Zx[rows, cols], self._ref_Zy[rows, cols], x, y
            )
            if p.interaction == "mean":
                L = 0.5 * (L + depth_interaction_matrix(Z, Zx[rows, cols], Zy[rows, cols], x, y))
        H = L.T @ L
        if p.mu > 0:
            H = H + p.mu * np.diag(np.diag(H))
        xi = -np.linalg.solve(H, L.T @ e)
        return xi, float(np.sqrt(np.mean(e * e))), count

    def step(
        self, current: np.ndarray | PointCloud, T_previous_current: np.ndarray | None = None
    ) -> tuple[np.ndarray, ServoStatus]:
        """One control step: the twist ``(v, omega)`` (camera frame, m/s, rad/s) and status.

        ``T_previous_current`` is accepted for the interface of :class:`SpectralServo` and
        not used: the law has no memory.
        """
        twist, status, _ = self.step_record(current, T_previous_current)
        return twist, status

    def step_record(
        self,
        current: np.ndarray | PointCloud,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step` with its :class:`ServoRecord` (``now`` and ``stamp``: the interface
        of :meth:`SpectralServo.step_record`, not used)."""
        start = time.perf_counter()
        p = self.params
        depth = self._depth(current, "current")
        xi, rms, count = self.gauss_newton_step(depth)
        record = _empty_record(self._steps, count)
        self._steps += 1
        record.iterations = 1
        record.fitness = count / self._ref_count
        if count < p.min_pixels:
            record.status = _too_few_points(
                count, f"{count} pixels valid in both depth maps (min_pixels {p.min_pixels})"
            )
            record.seconds = time.perf_counter() - start
            return record.twist, record.status, record
        T = np.eye(4)
        T[:3, :3] = rotation_matrix(xi[3:])
        T[:3, 3] = xi[:3]
        record.T_current_desired = T
        record.translation_error = float(np.linalg.norm(xi[:3]))
        record.rotation_error = float(np.linalg.norm(xi[3:]))
        record.translation_cost = rms
        if (
            record.fitness >= p.min_fitness
            and record.translation_error < p.translation_tolerance
            and record.rotation_error < p.rotation_tolerance
        ):
            record.status = ServoStatus(
                "converged",
                "converged",
                f"step {1000 * record.translation_error:.2f} mm, "
                f"{math.degrees(record.rotation_error):.3f} deg, RMS depth error "
                f"{1000 * rms:.2f} mm",
            )
        else:
            record.twist, record.saturation = _saturated_twist(xi[:3], xi[3:], p)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record


class DepthImageRobot:
    """A robot wrapper whose :meth:`capture` returns the raw depth image (H, W) of the
    wrapped robot's ``capture_depth()`` (e.g. ``sim.PyBulletRobot``), for
    :class:`DenseDepthServo` in :func:`run_servo`; every other call is forwarded.

    Parameters
    ----------
    robot
        A :class:`RobotInterface` that also has ``capture_depth() -> ndarray (H, W)``.
    """

    def __init__(self, robot: Any) -> None:
        self.robot = robot

    def joint_positions(self) -> np.ndarray:
        return self.robot.joint_positions()

    def send_joint_velocities(self, q_dot: np.ndarray, dt: float) -> None:
        self.robot.send_joint_velocities(q_dot, dt)

    def capture(self) -> np.ndarray:
        return self.robot.capture_depth()

    def stop(self) -> None:
        self.robot.stop()

    def time(self) -> float:
        return self.robot.time()


# --------------------------------------------------------------------------- ICP-PBVS


def open3d_module() -> Any:
    """Import Open3D, or fail with how to install it (the ``bench`` extra)."""
    try:
        return importlib.import_module("open3d")
    except ImportError as error:
        raise ImportError(
            "RegistrationServo needs Open3D, an optional dependency: "
            "pip install 'spectral_vs[bench]' (or pip install open3d)"
        ) from error


@dataclass
class RegistrationServoParams(_Law):
    """Settings of :class:`RegistrationServo` (Open3D registration + the PBVS law).

    Distances are given in voxels (multiples of ``voxel_size``), as in Open3D's tutorials,
    whose values these defaults are: normals over 2 voxels (30 neighbours at most), FPFH
    over 5 voxels (100 at most), RANSAC on 3 correspondences with inliers within 1.5
    voxels, edge-length check 0.9, 100000 iterations at confidence 0.999, and the ICP
    refinement within 0.4 voxel.

    Attributes
    ----------
    method : {"icp", "fpfh"}
        ``"icp"``: point-to-plane ICP from the identity (or the warm start) with
        correspondences within ``icp_distance`` voxels. ``"fpfh"``: FPFH + RANSAC, then
        point-to-plane ICP within ``refine_distance`` voxels, every step.
    voxel_size : float
        Both clouds are downsampled to this voxel, m (the spectral servo's 15 mm).
    icp_distance : float
        ``"icp"``: largest correspondence distance, voxels. It sets ICP's basin: a
        correspondence farther than this is ignored.
    icp_max_iterations : int
        Iterations of ICP per step (both methods).
    warm_start : bool
        ``"icp"``: start from the previous estimate carried along the camera's measured
        motion (as ``ServoParams.warm_start``) instead of the identity.
    normal_radius, feature_radius : float
        Radii of the normal fit (reference only when normals are missing) and of the FPFH
        features, voxels.
    ransac_distance : float
        RANSAC inlier distance, voxels.
    ransac_max_iterations : int
    ransac_confidence : float
    refine_distance : float
        ``"fpfh"``: correspondence distance of the ICP refinement, voxels.
    seed : int
        Seed of Open3D's random generator (RANSAC), set at construction and at
        :meth:`RegistrationServo.reset`.
    lambda_t, lambda_r, max_linear_speed, max_angular_speed : float
        The law and its saturation, as in :class:`ServoParams`.
    translation_tolerance, rotation_tolerance : float
        Converged when the estimate is below both (m, rad) ...
    min_fitness : float
        ... and the fitness, the share of the reference's points with a point of the current
        cloud within ``fitness_distance`` at the estimate, is at least this.
    fitness_distance : float
        Distance of the fitness test, voxels. Not ICP's own correspondence distance: with
        ``icp_distance`` = 10 voxels ICP's fitness was 1.0 at local optima 100 mm and 20
        degrees from the goal.
    max_depth : float
        Points farther along the optical axis are ignored, m.
    min_points : int
        Stop when the current cloud has fewer points (within ``max_depth``).
    """

    method: RegistrationMethod = "icp"
    voxel_size: float = 0.015
    icp_distance: float = 10.0
    icp_max_iterations: int = 30
    warm_start: bool = False
    normal_radius: float = 2.0
    feature_radius: float = 5.0
    ransac_distance: float = 1.5
    ransac_max_iterations: int = 100000
    ransac_confidence: float = 0.999
    refine_distance: float = 0.4
    seed: int = 0
    min_fitness: float = 0.9
    fitness_distance: float = 1.0
    max_depth: float = 1.5
    min_points: int = 500

    def __post_init__(self) -> None:
        if self.method not in ("icp", "fpfh"):
            raise ValueError(f"method must be 'icp' or 'fpfh', got {self.method!r}")
        check_positive(
            self,
            (
                "voxel_size",
                "icp_distance",
                "normal_radius",
                "feature_radius",
                "ransac_distance",
                "refine_distance",
                "fitness_distance",
                "lambda_t",
                "lambda_r",
                "max_linear_speed",
                "max_angular_speed",
                "translation_tolerance",
                "rotation_tolerance",
                "max_depth",
            ),
        )
        if self.icp_max_iterations < 1 or self.ransac_max_iterations < 1 or self.min_points < 1:
            raise ValueError("icp_max_iterations, ransac_max_iterations, min_points must be >= 1")
        if not 0.0 < self.ransac_confidence < 1.0:
            raise ValueError(f"ransac_confidence must be in (0, 1), got {self.ransac_confidence}")
        if not 0.0 <= self.min_fitness <= 1.0:
            raise ValueError(f"min_fitness must be in [0, 1], got {self.min_fitness}")


class RegistrationServo:
    """Position-based servoing on Open3D's registration (ICP-PBVS and FPFH-PBVS).

    Each step registers the reference (source, desired camera frame) onto the current
    cloud (target): the transformation is ``T_current_desired``, and the law of
    :class:`SpectralServo` gives the twist, ``v = lambda_t t``, ``omega = lambda_r theta u``,
    saturated. No watchdog: a wrong estimate is followed (the speed limits bound it).

    Parameters
    ----------
    reference : PointCloud or ndarray (N, 3) / (N, 6)
        Cloud captured at the desired pose, in that camera frame, metres. Normals are
        used when present, else fitted and turned toward the camera.
    params : RegistrationServoParams, optional

    Raises
    ------
    ImportError
        If Open3D is not installed.
    ValueError
        If the reference has fewer than ``min_points`` points within ``max_depth``.
    """

    def __init__(
        self, reference: PointCloud | np.ndarray, params: RegistrationServoParams | None = None
    ) -> None:
        self.params = params if params is not None else RegistrationServoParams()
        self._o3d = open3d_module()
        self._o3d.utility.random.seed(self.params.seed)
        points, normals = self._crop(reference, "reference")
        if len(points) < self.params.min_points:
            raise ValueError(
                f"reference has {len(points)} points, fewer than min_points = "
                f"{self.params.min_points}"
            )
        self.reference = self._prepare(points, normals)
        self._reference_features = (
            self._features(self.reference) if self.params.method == "fpfh" else None
        )
        self._previous: np.ndarray | None = None
        self._steps = 0

    # --- clouds ----------------------------------------------------------------------

    def _crop(self, cloud: PointCloud | np.ndarray, argument: str) -> tuple[np.ndarray, Any]:
        # A raw buffer's invalid returns are dropped, as an Open3D user does.
        c = as_cloud(cloud, argument, drop_non_finite=True)
        points = np.asarray(c.points, dtype=float)
        normals = None if c.normals is None else np.asarray(c.normals, dtype=float)
        keep = (points[:, 2] <= self.params.max_depth) & (points[:, 2] > 0)
        return points[keep], None if normals is None else normals[keep]

    def _prepare(self, points: np.ndarray, normals: np.ndarray | None) -> Any:
        """An Open3D cloud downsampled to ``voxel_size`` with unit normals toward the camera."""
        o3d = self._o3d
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        if normals is not None:
            cloud.normals = o3d.utility.Vector3dVector(normals)
        cloud = cloud.voxel_down_sample(self.params.voxel_size)
        if normals is None:
            cloud.estimate_normals(
                o3d.geometry.KDTreeSearchParamHybrid(
                    radius=self.params.normal_radius * self.params.voxel_size, max_nn=30
                )
            )
            cloud.orient_normals_towards_camera_location(np.zeros(3))
        else:
            cloud.normalize_normals()
        return cloud

    def _features(self, cloud: Any) -> Any:
        o3d = self._o3d
        return o3d.pipelines.registration.compute_fpfh_feature(
            cloud,
            o3d.geometry.KDTreeSearchParamHybrid(
                radius=self.params.feature_radius * self.params.voxel_size, max_nn=100
            ),
        )

    # --- registration ----------------------------------------------------------------

    def _icp(self, target: Any, initial: np.ndarray, distance: float) -> Any:
        reg = self._o3d.pipelines.registration
        return reg.registration_icp(
            self.reference,
            target,
            distance * self.params.voxel_size,
            initial,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=self.params.icp_max_iterations),
        )

    def estimate(
        self, current: PointCloud | np.ndarray, initial_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, float]:
        """``T_current_desired`` and the fitness (within ``fitness_distance``) of the
        registration of the reference onto ``current`` (``initial_guess`` only for
        ``"icp"``; identity by default)."""
        points, normals = self._crop(current, "current")
        target = self._prepare(points, normals)
        return self._register(target, initial_guess)

    def _register(self, target: Any, initial_guess: np.ndarray | None) -> tuple[np.ndarray, float]:
        p = self.params
        reg = self._o3d.pipelines.registration
        if p.method == "icp":
            guess = np.eye(4) if initial_guess is None else np.asarray(initial_guess, dtype=float)
            result = self._icp(target, guess, p.icp_distance)
        else:
            distance = p.ransac_distance * p.voxel_size
            coarse = reg.registration_ransac_based_on_feature_matching(
                self.reference,
                target,
                self._reference_features,
                self._features(target),
                True,
                distance,
                reg.TransformationEstimationPointToPoint(False),
                3,
                [
                    reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                    reg.CorrespondenceCheckerBasedOnDistance(distance),
                ],
                reg.RANSACConvergenceCriteria(p.ransac_max_iterations, p.ransac_confidence),
            )
            result = self._icp(target, np.asarray(coarse.transformation), p.refine_distance)
        T = np.array(result.transformation)
        check = reg.evaluate_registration(
            self.reference, target, p.fitness_distance * p.voxel_size, T
        )
        return T, float(check.fitness)

    # --- the servo interface ---------------------------------------------------------

    def reset(self) -> None:
        """Forget the previous estimate and the step count; reseed RANSAC."""
        self._previous = None
        self._steps = 0
        self._o3d.utility.random.seed(self.params.seed)

    def step(
        self, current: PointCloud | np.ndarray, T_previous_current: np.ndarray | None = None
    ) -> tuple[np.ndarray, ServoStatus]:
        """One control step: the twist ``(v, omega)`` (camera frame, m/s, rad/s) and status.

        ``T_previous_current``, the camera's own motion since the previous step, carries the
        previous estimate along for the warm start.
        """
        twist, status, _ = self.step_record(current, T_previous_current)
        return twist, status

    def step_record(
        self,
        current: PointCloud | np.ndarray,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step` with its :class:`ServoRecord` (``iterations`` is not reported by
        Open3D and stays 0; ``now`` and ``stamp``: the interface of
        :meth:`SpectralServo.step_record`, not used)."""
        start = time.perf_counter()
        p = self.params
        points, normals = self._crop(current, "current")
        record = _empty_record(self._steps, len(points))
        self._steps += 1
        if len(points) < p.min_points:
            record.status = _too_few_points(
                len(points),
                f"the current cloud has {len(points)} points (min_points {p.min_points})",
            )
            record.seconds = time.perf_counter() - start
            return record.twist, record.status, record
        guess = None
        if p.method == "icp" and p.warm_start and self._previous is not None:
            guess = self._previous
            if T_previous_current is not None:
                guess = np.linalg.inv(np.asarray(T_previous_current, dtype=float)) @ guess
        T, fitness = self._register(self._prepare(points, normals), guess)
        self._previous = T
        t_err, r_err = pose_error(T)
        record.T_current_desired = T
        record.translation_error, record.rotation_error = t_err, r_err
        record.fitness = fitness
        if (
            fitness >= p.min_fitness
            and t_err < p.translation_tolerance
            and (r_err < p.rotation_tolerance)
        ):
            record.status = _converged_status(t_err, r_err)
        else:
            record.twist, record.saturation = _saturated_twist(
                T[:3, 3], rotation_vector(T[:3, :3]), p
            )
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record


__all__ = [
    "DenseDepthServo",
    "DepthImageRobot",
    "DepthServoParams",
    "Intrinsics",
    "RegistrationServo",
    "RegistrationServoParams",
    "depth_gradients",
    "depth_image_from_cloud",
    "depth_interaction_matrix",
    "normalized_coordinates",
    "open3d_module",
]
