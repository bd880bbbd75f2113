"""A box held in front of the simulated wrist camera (:class:`HandOccluder`, one of the
faults of :mod:`spectral_vs.sim.faults`): a hand, or a tool left in view, as a body of the
robot's PyBullet simulation."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.robot import RobotInterface
from spectral_vs.sim.faulty_camera import FaultyCamera, clock_window
from spectral_vs.sim.pybullet_poses import quaternion


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
        self.start, self.duration = clock_window(start, duration)
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
        client.resetBasePositionAndOrientation(self.body, centre.tolist(), quaternion(T[:3, :3]))

    def remove(self) -> None:
        """Take the box out of the simulation (idempotent)."""
        if self.body is not None:
            self._sim.client.removeBody(self.body)
            self.body = None
