"""The simulation's settings (:class:`SimParams`): the physics mode, the drives, the arm,
its camera and the table scene."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from spectral_vs.sim.camera import CameraParams
from spectral_vs.sim.robots import RobotModel, iiwa_model
from spectral_vs.sim.scene import TableSceneParams


@dataclass
class SimParams:
    """The simulation.

    Attributes
    ----------
    mode : {"kinematic", "dynamic"}
        ``"kinematic"``: joints integrate the commanded velocities exactly
        (``resetJointState``), deterministic, for tests. ``"dynamic"``: PyBullet velocity
        motors with torque limits, ``stepSimulation`` at ``time_step``, gravity on.
    time_step : float
        Physics step in dynamic mode, s.
    max_joint_speed : float
        Speed the simulated drives saturate at, rad/s (each joint clamped separately, as
        hardware does; the URDF's 10 rad/s is not a real iiwa's 1.5-2.3 rad/s).
    max_joint_torque : float
        Torque limit of every motor in dynamic mode, N m (the URDF gives 300).
    robot : RobotModel
        The arm: URDF, chain, home configuration, camera mount (the iiwa by default; see
        :func:`spectral_vs.sim.robots.robot_model`).
    q_start : tuple of float, optional
        Joint positions at construction, rad; ``robot.home_q`` when not given.
    T_tip_camera : ndarray, shape (4, 4), optional
        Pose of the camera frame (Z forward, X right, Y down) in the robot's tip link;
        ``robot.T_tip_camera`` when not given.
    camera : CameraParams
        Intrinsics, depth noise and normal estimation.
    scene : TableSceneParams
        Table and clutter.
    """

    mode: Literal["kinematic", "dynamic"] = "kinematic"
    time_step: float = 1.0 / 240.0
    max_joint_speed: float = 1.5
    max_joint_torque: float = 300.0
    robot: RobotModel = field(default_factory=iiwa_model)
    q_start: tuple[float, ...] | None = None
    T_tip_camera: np.ndarray | None = None
    camera: CameraParams = field(default_factory=CameraParams)
    scene: TableSceneParams = field(default_factory=TableSceneParams)

    def __post_init__(self) -> None:
        if self.mode not in ("kinematic", "dynamic"):
            raise ValueError(f"mode must be 'kinematic' or 'dynamic', got {self.mode!r}")
        if (
            not self.time_step > 0.0
            or not self.max_joint_speed > 0.0
            or not self.max_joint_torque > 0.0
        ):
            raise ValueError("time_step, max_joint_speed and max_joint_torque must be > 0")
        if self.q_start is None:
            self.q_start = self.robot.home_q
        if self.T_tip_camera is None:
            self.T_tip_camera = np.array(self.robot.T_tip_camera)
