"""Sensor faults injected into a robot's wrist camera: the test and experiment harness of the
servo's fault handling (docs/servoing.md, "Sensor faults").

Each class wraps a :class:`~spectral_vs.robot.RobotInterface` and forwards every call to
it, except :meth:`capture`, which it spoils as a real wrist camera does:

- :class:`DroppedFrames`: an empty capture at chosen capture indices (a dropped frame);
- :class:`Outage`: empty captures during a window of the robot clock (a burst of drops,
  or the camera lost for good with ``duration=math.inf``);
- :class:`RepeatedFrames`: the previous frame delivered again at chosen capture indices
  (a stale frame from a driver that missed an update);
- :class:`HandOccluder`: a hand-sized box held in front of the camera, along its optical
  axis, during a window of the robot clock, still or sweeping across the view (a hand), or
  left where it first appeared (a tool left in view) (needs a
  :class:`~spectral_vs.sim.robot.PyBulletRobot`: the box is a body of its simulation);
- :class:`StrayPoints`: stray returns added to every capture: a few far-off points,
  a share of the pixels at random depths, non-finite rows (the capture then comes as an
  (N, 6) array, as a driver's raw buffer);
- :class:`Latency`: every capture delivered one or more control periods late (a USB
  camera's pipeline).

Capture indices count the wrapper's calls of :meth:`capture` from 0; windows are on the
robot clock (:meth:`RobotInterface.time`) since the wrapper was made, s, which is the
servo's ``ServoRecord.time`` when :func:`spectral_vs.servo.run_servo` starts right after.
Every wrapper lists the capture indices it spoiled in ``faults``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.robot import RobotInterface


def _empty_cloud() -> PointCloud:
    """A capture with no point (what a driver returns for a dropped frame)."""
    return PointCloud(np.zeros((0, 3)), np.zeros((0, 3)))


def _indices(captures: Iterable[int], argument: str) -> frozenset[int]:
    """The capture indices ``captures`` as a set, refusing negative ones (ValueError)."""
    chosen = frozenset(int(index) for index in captures)
    if any(index < 0 for index in chosen):
        raise ValueError(f"{argument} must hold capture indices >= 0, got {sorted(chosen)}")
    return chosen


def _window(start: float, duration: float) -> tuple[float, float]:
    """A checked window ``[start, start + duration)`` of the robot clock, s."""
    if not (math.isfinite(start) and start >= 0):
        raise ValueError(f"start must be finite and >= 0 s, got {start}")
    if not duration > 0:
        raise ValueError(f"duration must be > 0 s (inf: for good), got {duration}")
    return float(start), float(duration)


class FaultyCamera:
    """A :class:`RobotInterface` that forwards every call to ``robot``; subclasses spoil
    :meth:`capture` through :meth:`_spoil`.

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera fails.
    """

    def __init__(self, robot: RobotInterface) -> None:
        self.robot = robot
        #: Capture indices (from 0) that the wrapper spoiled.
        self.faults: list[int] = []
        self._captures = 0
        self._start_time = robot.time()

    @property
    def captures(self) -> int:
        """Captures made so far."""
        return self._captures

    def elapsed(self) -> float:
        """Robot clock since the wrapper was made, s."""
        return self.robot.time() - self._start_time

    def joint_positions(self) -> np.ndarray:
        return self.robot.joint_positions()

    def send_joint_velocities(self, q_dot: np.ndarray, dt: float) -> None:
        self.robot.send_joint_velocities(q_dot, dt)

    def capture(self) -> PointCloud:
        """The robot's capture, or the spoiled one; recorded in ``faults`` when spoiled."""
        index = self._captures
        self._captures += 1
        cloud = self._spoil(index)
        if cloud is None:
            return self._deliver(self.robot.capture())
        self.faults.append(index)
        return cloud

    def capture_depth(self) -> np.ndarray:
        """The robot's depth image (``capture_depth()`` of a
        :class:`~spectral_vs.sim.PyBulletRobot`), counted as a capture, with the fault's
        change of the scene in it (:class:`HandOccluder`'s box). A fault that spoils the
        point cloud itself has no depth-image form here (ValueError)."""
        index = self._captures
        self._captures += 1
        if self._spoil(index) is not None:
            raise ValueError(f"{type(self).__name__} spoils point clouds: no depth image form")
        robot: Any = self.robot  # a PyBulletRobot, or another wrapper of one
        return robot.capture_depth()

    def stop(self) -> None:
        self.robot.stop()

    def time(self) -> float:
        return self.robot.time()

    def _spoil(self, index: int) -> PointCloud | None:
        """The spoiled capture number ``index``, or None to capture normally."""
        return None

    def _deliver(self, cloud: PointCloud) -> PointCloud:
        """A normal capture on its way out (subclasses may keep it)."""
        return cloud


class DroppedFrames(FaultyCamera):
    """Empty captures (dropped frames) at the capture indices ``captures``.

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera fails.
    captures : iterable of int
        Capture indices (from 0) that come back empty.
    """

    def __init__(self, robot: RobotInterface, captures: Iterable[int]) -> None:
        super().__init__(robot)
        self.dropped = _indices(captures, "captures")

    def _spoil(self, index: int) -> PointCloud | None:
        return _empty_cloud() if index in self.dropped else None


class Outage(FaultyCamera):
    """Empty captures while the robot clock is in ``[start, start + duration)`` since the
    wrapper was made: a burst of dropped frames, or the camera (or the target) lost for
    good with ``duration=math.inf``.

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera fails.
    start : float
        Beginning of the outage, s of robot clock since the wrapper was made.
    duration : float
        Its length, s (> 0; ``inf``: it never ends).
    """

    def __init__(self, robot: RobotInterface, start: float, duration: float) -> None:
        super().__init__(robot)
        self.start, self.duration = _window(start, duration)

    def _spoil(self, index: int) -> PointCloud | None:
        # A small tolerance: the clock adds up periods of dt, e.g. 0.1 * 3 = 0.30000000000000004.
        elapsed = self.elapsed() + 1e-9
        return _empty_cloud() if self.start <= elapsed < self.start + self.duration else None


class RepeatedFrames(FaultyCamera):
    """The previous frame delivered again (a stale frame) at the capture indices
    ``captures``: the very cloud of the last capture, whatever the robot did since.

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera fails.
    captures : iterable of int
        Capture indices (from 1) that repeat the capture before them; index 0, which has
        nothing before it, is refused.
    """

    def __init__(self, robot: RobotInterface, captures: Iterable[int]) -> None:
        super().__init__(robot)
        self.repeated = _indices(captures, "captures")
        if 0 in self.repeated:
            raise ValueError("captures must hold indices >= 1: capture 0 has no previous frame")
        self._last: PointCloud | None = None

    def _spoil(self, index: int) -> PointCloud | None:
        return self._last if index in self.repeated else None

    def _deliver(self, cloud: PointCloud) -> PointCloud:
        self._last = cloud
        return cloud


class HandOccluder(FaultyCamera):
    """A box in front of the camera while the robot clock is in ``[start, start +
    duration)`` since the wrapper was made.

    The box is a visual-only body of the robot's PyBullet client (it collides with
    nothing), created at the first capture in the window with its centre ``distance``
    along the camera's optical axis (plus ``offset`` across it) and its faces parallel to
    the image plane, and removed at the first capture after the window (or by
    :meth:`remove`). It follows the camera (a hand held in front of it), moving across the
    view at ``sweep`` m/s along the camera's x axis (a hand passing by: centred at the
    window's middle), or stays where it appeared with ``follow=False`` (a tool left in
    view). A 9 cm box at 0.25 m hides about a tenth of a 58 degree view: part of the
    scene, not all of it.

    Parameters
    ----------
    robot : PyBulletRobot
        The simulated robot: it needs ``client`` and ``camera_pose()``.
    start : float
        When the box appears, s of robot clock since the wrapper was made.
    duration : float
        How long it stays, s (``math.inf``: for good).
    distance : float
        Distance of the box's centre from the camera along the optical axis, m.
    size : float or (float, float, float)
        Edge of the cubic box, or its edges along the camera's x, y and z, m (a hand:
        about 0.08-0.10, or 0.1 x 0.2 x 0.05).
    offset : (float, float)
        Offset of the box's centre across the optical axis (camera x right, y down), m.
    sweep : float
        Speed of the box across the view along the camera's x axis, m/s (needs a finite
        ``duration``); 0: still.
    follow : bool
        The box follows the camera (True) or stays where it first appeared (False).
    """

    def __init__(
        self,
        robot: RobotInterface,
        start: float,
        duration: float = 1.0,
        *,
        distance: float = 0.25,
        size: float | tuple[float, float, float] = 0.09,
        offset: tuple[float, float] = (0.0, 0.0),
        sweep: float = 0.0,
        follow: bool = True,
    ) -> None:
        super().__init__(robot)
        if not hasattr(robot, "client") or not hasattr(robot, "camera_pose"):
            raise ValueError("robot must be a PyBulletRobot (with client and camera_pose)")
        self.start, self.duration = _window(start, duration)
        edges = np.broadcast_to(np.asarray(size, dtype=float), (3,)).copy()
        if not (np.isfinite(edges).all() and (edges > 0).all()):
            raise ValueError(f"size must be finite and > 0 m, got {size}")
        if not (math.isfinite(distance) and distance > edges[2] / 2):
            raise ValueError(f"distance must be finite and > size / 2 m, got {distance}")
        if not math.isfinite(sweep) or (sweep != 0 and not math.isfinite(duration)):
            raise ValueError(f"sweep must be finite m/s, with a finite duration; got {sweep}")
        self.distance, self.edges = float(distance), edges
        self.size = float(edges.max())
        self.offset = (float(offset[0]), float(offset[1]))
        self.sweep, self.follow = float(sweep), bool(follow)
        self._sim: Any = robot  # a PyBulletRobot: its client and ground-truth camera pose
        #: PyBullet body id of the box while it is present, else None.
        self.body: int | None = None

    def _spoil(self, index: int) -> PointCloud | None:
        elapsed = self.elapsed() + 1e-9  # the clock adds up periods of dt
        if self.start <= elapsed < self.start + self.duration:
            if self.body is None or self.follow:
                self._place(elapsed)
            self.faults.append(index)
        else:
            self.remove()
        return None  # the camera renders the scene with the box in it

    def _place(self, elapsed: float) -> None:
        """Create the box if needed and put it in front of the camera."""
        client = self._sim.client
        if self.body is None:
            shape = client.createVisualShape(
                client.GEOM_BOX, halfExtents=(self.edges / 2).tolist(), rgbaColor=[0.9, 0.7, 0.6, 1]
            )
            self.body = int(client.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape))
        T = np.asarray(self._sim.camera_pose(), dtype=float)
        x = self.offset[0]
        if self.sweep:
            x += self.sweep * (elapsed - self.start - self.duration / 2)
        centre = T[:3, :3] @ np.array([x, self.offset[1], self.distance]) + T[:3, 3]
        client.resetBasePositionAndOrientation(self.body, centre.tolist(), _quaternion(T[:3, :3]))

    def remove(self) -> None:
        """Take the box out of the simulation (idempotent)."""
        if self.body is not None:
            self._sim.client.removeBody(self.body)
            self.body = None


class StrayPoints(FaultyCamera):
    """Stray returns in every capture, as a depth sensor gives them.

    Each capture gets ``far`` points at ``far_distance`` along random rays in front of the
    camera, moves ``random_share`` of its points to random depths in ``depth_range`` along
    their own rays (their normals turned to the camera), and, with ``non_finite`` rows,
    comes as an (N, 6) array (points, normals) with that many rows of NaN and inf, as a
    driver's raw buffer. Seeded: the same captures give the same stray points.

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera returns stray points.
    far : int
        Far-off points per capture, >= 0.
    far_distance : float
        Their distance from the camera, m.
    random_share : float
        Share of the points moved to random depths, in [0, 1].
    depth_range : (float, float)
        The random depths, m.
    non_finite : int
        Non-finite rows per capture, >= 0.
    seed : int
        Seed of the draws.
    """

    def __init__(
        self,
        robot: RobotInterface,
        *,
        far: int = 1,
        far_distance: float = 1e4,
        random_share: float = 0.0,
        depth_range: tuple[float, float] = (0.1, 5.0),
        non_finite: int = 0,
        seed: int = 0,
    ) -> None:
        super().__init__(robot)
        if far < 0 or non_finite < 0:
            raise ValueError(f"far and non_finite must be >= 0, got {far}, {non_finite}")
        if not 0.0 <= random_share <= 1.0:
            raise ValueError(f"random_share must be in [0, 1], got {random_share}")
        if not 0 < depth_range[0] < depth_range[1]:
            raise ValueError(
                f"depth_range must be (low, high) with 0 < low < high m, got {depth_range}"
            )
        self.far, self.far_distance = int(far), float(far_distance)
        self.random_share, self.depth_range = float(random_share), depth_range
        self.non_finite = int(non_finite)
        self._rng = np.random.default_rng(seed)

    def capture(self) -> Any:  # an (N, 6) array when it has non-finite rows
        index = self._captures
        self._captures += 1
        cloud = self.robot.capture()
        points = np.array(cloud.points, dtype=float)
        normals = np.array(cloud.normals, dtype=float)
        rng = self._rng
        moved = rng.random(len(points)) < self.random_share
        if moved.any():
            depth = rng.uniform(*self.depth_range, int(moved.sum()))
            rays = points[moved] / np.linalg.norm(points[moved], axis=1, keepdims=True)
            points[moved] = rays * depth[:, None]
            normals[moved] = -rays
        rays = rng.normal(size=(self.far, 3))
        rays[:, 2] = np.abs(rays[:, 2]) + 1.0  # in front of the camera
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        points = np.vstack([points, self.far_distance * rays])
        normals = np.vstack([normals, -rays])
        if self.far or moved.any() or self.non_finite:
            self.faults.append(index)
        if not self.non_finite:
            return PointCloud(points, normals)
        bad = np.full((self.non_finite, 6), np.nan)
        bad[::2, 2] = np.inf
        return np.vstack([np.hstack([points, normals]), bad])


class Latency(FaultyCamera):
    """Every capture delivered ``periods`` captures late: the frame the camera took that
    many control periods ago (the first frames until the pipeline has filled).

    Parameters
    ----------
    robot : RobotInterface
        The robot whose camera lags.
    periods : int
        How many captures late, >= 1.
    """

    def __init__(self, robot: RobotInterface, periods: int = 1) -> None:
        super().__init__(robot)
        if periods < 1:
            raise ValueError(f"periods must be >= 1, got {periods}")
        self.periods = int(periods)
        self._frames: list[PointCloud] = []

    def _deliver(self, cloud: PointCloud) -> PointCloud:
        self._frames.append(cloud)
        if len(self._frames) > self.periods + 1:
            self._frames.pop(0)
        return self._frames[0]


def _quaternion(R: np.ndarray) -> list[float]:
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


__all__ = [
    "DroppedFrames",
    "FaultyCamera",
    "HandOccluder",
    "Latency",
    "Outage",
    "RepeatedFrames",
    "StrayPoints",
]
