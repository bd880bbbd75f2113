"""The base of the simulated camera faults (:mod:`spectral_vs.sim.faults`): a wrapper of a
robot that forwards every call to it and spoils its captures, with the checks of the
capture indices and clock windows the faults are given."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.robot import RobotInterface


def empty_capture() -> PointCloud:
    """A capture with no point (what a driver returns for a dropped frame)."""
    return PointCloud(np.zeros((0, 3)), np.zeros((0, 3)))


def capture_indices(captures: Iterable[int], argument: str) -> frozenset[int]:
    """The capture indices ``captures`` as a set, refusing negative ones (ValueError)."""
    chosen = frozenset(int(index) for index in captures)
    if any(index < 0 for index in chosen):
        raise ValueError(f"{argument} must hold capture indices >= 0, got {sorted(chosen)}")
    return chosen


def clock_window(start: float, duration: float) -> tuple[float, float]:
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
