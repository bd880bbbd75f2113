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

from collections.abc import Iterable
from typing import Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.robot import RobotInterface
from spectral_vs.sim.faulty_camera import FaultyCamera, capture_indices, clock_window, empty_capture
from spectral_vs.sim.occluders import HandOccluder


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
        self.dropped = capture_indices(captures, "captures")

    def _spoil(self, index: int) -> PointCloud | None:
        return empty_capture() if index in self.dropped else None


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
        self.start, self.duration = clock_window(start, duration)

    def _spoil(self, index: int) -> PointCloud | None:
        # A small tolerance: the clock adds up periods of dt, e.g. 0.1 * 3 = 0.30000000000000004.
        elapsed = self.elapsed() + 1e-9
        return empty_capture() if self.start <= elapsed < self.start + self.duration else None


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
        self.repeated = capture_indices(captures, "captures")
        if 0 in self.repeated:
            raise ValueError("captures must hold indices >= 1: capture 0 has no previous frame")
        self._last: PointCloud | None = None

    def _spoil(self, index: int) -> PointCloud | None:
        return self._last if index in self.repeated else None

    def _deliver(self, cloud: PointCloud) -> PointCloud:
        self._last = cloud
        return cloud


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


__all__ = [
    "DroppedFrames",
    "FaultyCamera",
    "HandOccluder",
    "Latency",
    "Outage",
    "RepeatedFrames",
    "StrayPoints",
]
