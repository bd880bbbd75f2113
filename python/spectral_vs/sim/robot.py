"""A simulated robot arm with a wrist depth camera above the table, in PyBullet DIRECT mode.

The arm is data (:class:`spectral_vs.sim.robots.RobotModel`: the KUKA LBR iiwa by default,
the Franka Emika Panda, or any URDF).

:class:`PyBulletRobot` implements :class:`spectral_vs.robot.RobotInterface`, so a servo
loop written for it also drives a real robot.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt
import pybullet
from pybullet_utils.bullet_client import BulletClient

from spectral_vs._core import Kinematics, PointCloud
from spectral_vs.field_of_view import ViewCheck
from spectral_vs.sim.camera import back_project, depth_to_cloud, render_depth
from spectral_vs.sim.pybullet_poses import pose_matrix
from spectral_vs.sim.robots import (
    BASE_LINK,
    HOME_Q,
    TIP_LINK,
    default_T_tip_camera,
    iiwa_urdf_path,
)
from spectral_vs.sim.scene import PlacedObject, build_scene
from spectral_vs.sim.settings import SimParams

__all__ = [
    "BASE_LINK",
    "HOME_Q",
    "TIP_LINK",
    "PyBulletRobot",
    "SimParams",
    "default_T_tip_camera",
    "iiwa_urdf_path",
    "pose_matrix",
]


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """Send what C code writes to standard output to standard error meanwhile.

    PyBullet's connect prints ``argv[0]=`` with C's printf, which would corrupt a
    machine-readable output such as ``spectral-vs servo-sim --json``.
    """
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class PyBulletRobot:
    """A robot arm (``params.robot``) on the table with its wrist camera, in its own
    PyBullet DIRECT client.

    The robot base frame is the world frame. The joints of ``robot.held_joints`` (the
    Panda's fingers) are kept at their positions. Use as a context manager, or call
    :meth:`close`, to free the physics server.

    Parameters
    ----------
    params : SimParams
        The simulation; defaults to a kinematic simulation of the iiwa at :data:`HOME_Q`.
    """

    def __init__(self, params: SimParams | None = None) -> None:
        self.params = params if params is not None else SimParams()
        with _stdout_to_stderr():
            self._client = BulletClient(connection_mode=pybullet.DIRECT)
        self._client.setGravity(0.0, 0.0, -9.81)
        self._client.setTimeStep(self.params.time_step)
        self.objects: list[PlacedObject] = build_scene(self._client, self.params.scene)
        model = self.params.robot
        self.robot_id = self._client.loadURDF(
            str(model.urdf_path), basePosition=[0.0, 0.0, 0.0], useFixedBase=True
        )
        self.kinematics = Kinematics(
            model.urdf_path, model.base_link, model.tip_link, self.params.T_tip_camera
        )
        #: Pose of the camera in the tip link, (4, 4), metres.
        self.T_tip_camera = np.asarray(self.kinematics.T_tip_camera)
        self._joints = self._movable_joints()
        self._held = self._held_joints()
        self._tip_index = self._link_index(model.tip_link)
        self._rng = np.random.default_rng(self.params.camera.noise.seed)
        self._time = 0.0
        q_start = self.params.q_start
        self.reset_joint_positions(self.params.robot.home_q if q_start is None else q_start)

    # --- RobotInterface --------------------------------------------------------------

    def joint_positions(self) -> np.ndarray:
        """Current joint positions of the chain, shape (n,), rad."""
        states = self._client.getJointStates(self.robot_id, self._joints)
        return np.array([state[0] for state in states])

    def send_joint_velocities(self, q_dot: np.ndarray, dt: float) -> None:
        """Apply joint velocities for ``dt`` seconds of simulated time.

        Each joint is clamped to ``max_joint_speed``. Kinematic mode integrates
        ``q + q_dot dt`` exactly and stops at the position limits; dynamic mode sets the
        velocity motors and steps the physics ``round(dt / time_step)`` times (at least 1).
        """
        q_dot = self._checked_velocities(q_dot)
        if not dt > 0.0 or not math.isfinite(dt):
            raise ValueError(f"dt must be finite and > 0, got {dt}")
        if self.params.mode == "kinematic":
            self._integrate(q_dot, dt)
        else:
            self._step_dynamics(q_dot, dt)

    def capture(self) -> PointCloud:
        """The wrist camera's point cloud (camera frame, normals toward the camera)."""
        return depth_to_cloud(
            self.capture_depth(), self.params.camera.intrinsics, self.params.camera.normals
        )

    def stop(self) -> None:
        """Zero velocity: motors hold (dynamic mode); joint velocities cleared (kinematic)."""
        if self.params.mode == "dynamic":
            self._set_motor_velocities(np.zeros(len(self._joints)))
        else:
            for joint, q in zip(self._joints, self.joint_positions(), strict=True):
                self._client.resetJointState(self.robot_id, joint, q, 0.0)

    def time(self) -> float:
        """Simulated time since construction, s."""
        return self._time

    # --- Simulation extras -----------------------------------------------------------

    @property
    def client(self):
        """The ``BulletClient`` of this simulation."""
        return self._client

    def reset_joint_positions(self, q: npt.ArrayLike) -> None:
        """Teleport the arm to ``q`` at rest; the motors then hold it.

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint positions of the chain, rad.

        Raises
        ------
        ValueError
            If ``q`` does not hold n finite values.
        """
        q = np.asarray(q, dtype=float)
        if q.shape != (len(self._joints),) or not np.all(np.isfinite(q)):
            raise ValueError(f"q must be {len(self._joints)} finite joint positions, got {q!r}")
        for joint, value in zip(self._joints, q, strict=True):
            self._client.resetJointState(self.robot_id, joint, float(value), 0.0)
        self._set_motor_velocities(np.zeros(len(self._joints)))
        self._hold_joints()

    def capture_depth(self) -> np.ndarray:
        """The planar depth image (H, W), metres, NaN where missing; noisy if configured."""
        depth = render_depth(self._client, self.camera_pose(), self.params.camera.intrinsics)
        noise = self.params.camera.noise
        return noise.apply(depth, self._rng) if noise.enabled else depth

    def tip_pose(self) -> np.ndarray:
        """T_world_tip of the tip link as PyBullet has it (URDF link frame)."""
        state = self._client.getLinkState(
            self.robot_id, self._tip_index, computeForwardKinematics=True
        )
        return pose_matrix(state[4], state[5])

    def camera_pose(self) -> np.ndarray:
        """T_world_camera from PyBullet's link state: the ground truth of the simulation."""
        return self.tip_pose() @ self.T_tip_camera

    def T_base_camera(self, q: np.ndarray | None = None) -> np.ndarray:
        """T_base_camera from the KDL kinematics at ``q`` (the current joints by default).
        The base frame is the world frame.

        Parameters
        ----------
        q : ndarray, shape (n,), optional
            Joint positions, rad.

        Returns
        -------
        ndarray, shape (4, 4)
            Pose of the camera frame in the base frame.
        """
        return self.kinematics.forward(self.joint_positions() if q is None else q)

    def view_check(
        self, min_share: float = 0.3, min_camera_height: float = 0.05, q_reference=None
    ) -> ViewCheck:
        """The start check of :func:`spectral_vs.experiment.start_poses` for this robot and scene.

        The reference points are those of a noise-free depth image rendered at
        ``q_reference`` with this camera (the arm is moved there and back), so the check,
        and the starts it selects, do not depend on the depth noise.

        Parameters
        ----------
        min_share : float
            Share of the reference's points that a start must keep in view, in (0, 1].
        min_camera_height : float
            Lowest accepted camera height above the table top (z = 0), m.
        q_reference : array_like, shape (n,), optional
            Configuration of the reference, rad; ``robot.home_q`` by default.

        Returns
        -------
        spectral_vs.field_of_view.ViewCheck
            ``check(q) -> bool``.
        """
        q_reference = np.asarray(
            self.params.robot.home_q if q_reference is None else q_reference, dtype=float
        )
        q_now = self.joint_positions()
        self.reset_joint_positions(q_reference)
        intrinsics = self.params.camera.intrinsics
        depth = render_depth(self._client, self.camera_pose(), intrinsics)
        self.reset_joint_positions(q_now)
        return ViewCheck(
            self.kinematics,
            q_reference,
            back_project(depth, intrinsics).reshape(-1, 3),
            intrinsics.matrix(),
            (intrinsics.width, intrinsics.height),
            depth_range=(intrinsics.near, intrinsics.far),
            min_share=min_share,
            min_camera_height=min_camera_height,
        )

    def close(self) -> None:
        """Disconnect the physics server (idempotent)."""
        if self._client is not None:
            self._client.disconnect()
            self._client = None

    def __enter__(self) -> PyBulletRobot:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- Internals -------------------------------------------------------------------

    def _movable_joints(self) -> list[int]:
        names = self.kinematics.joint_names
        by_name = {}
        for index in range(self._client.getNumJoints(self.robot_id)):
            info = self._client.getJointInfo(self.robot_id, index)
            if info[2] != pybullet.JOINT_FIXED:
                by_name[info[1].decode()] = index
        return [by_name[name] for name in names]

    def _held_joints(self) -> list[tuple[int, float, float]]:
        """(index, position, force limit) of every joint of ``robot.held_joints``."""
        by_name = {}
        for index in range(self._client.getNumJoints(self.robot_id)):
            info = self._client.getJointInfo(self.robot_id, index)
            by_name[info[1].decode()] = (index, float(info[10]))
        held = []
        for name, position in self.params.robot.held_joints:
            if name not in by_name:
                urdf = self.params.robot.urdf_path.name
                raise ValueError(f"robot.held_joints names {name!r}, not a joint of {urdf}")
            index, force = by_name[name]
            held.append((index, position, force if force > 0.0 else self.params.max_joint_torque))
        return held

    def _hold_joints(self) -> None:
        """Put the held joints at their positions; position motors keep them there."""
        for index, position, force in self._held:
            self._client.resetJointState(self.robot_id, index, position, 0.0)
            self._client.setJointMotorControl2(
                self.robot_id,
                index,
                pybullet.POSITION_CONTROL,
                targetPosition=position,
                force=force,
            )

    def _link_index(self, link_name: str) -> int:
        for index in range(self._client.getNumJoints(self.robot_id)):
            if self._client.getJointInfo(self.robot_id, index)[12].decode() == link_name:
                return index
        raise ValueError(f"no link named {link_name!r}")

    def _checked_velocities(self, q_dot) -> np.ndarray:
        q_dot = np.asarray(q_dot, dtype=float)
        if q_dot.shape != (len(self._joints),) or not np.all(np.isfinite(q_dot)):
            raise ValueError(
                f"q_dot must be {len(self._joints)} finite joint velocities, got {q_dot!r}"
            )
        return np.clip(q_dot, -self.params.max_joint_speed, self.params.max_joint_speed)

    def _integrate(self, q_dot: np.ndarray, dt: float) -> None:
        k = self.kinematics
        q = np.clip(self.joint_positions() + q_dot * dt, k.lower_limits, k.upper_limits)
        for joint, value, velocity in zip(self._joints, q, q_dot, strict=True):
            self._client.resetJointState(self.robot_id, joint, float(value), float(velocity))
        self._time += dt

    def _step_dynamics(self, q_dot: np.ndarray, dt: float) -> None:
        self._set_motor_velocities(q_dot)
        steps = max(1, round(dt / self.params.time_step))
        for _ in range(steps):
            self._client.stepSimulation()
        self._time += steps * self.params.time_step

    def _set_motor_velocities(self, q_dot: np.ndarray) -> None:
        self._client.setJointMotorControlArray(
            self.robot_id,
            self._joints,
            pybullet.VELOCITY_CONTROL,
            targetVelocities=q_dot.tolist(),
            forces=[self.params.max_joint_torque] * len(self._joints),
        )
