"""The small robot interface a servo loop drives: read joints, send velocities, capture.

The servo law of the paper (section II-D, eq. 18) needs only the joint positions, a
way to command joint velocities and the point cloud of the wrist camera. The camera
Jacobian comes from :class:`spectral_vs.Kinematics` (URDF + camera offset), so any robot
that implements :class:`RobotInterface` can be servoed: the PyBullet simulation in
:mod:`spectral_vs.sim` is one implementation, a driver for a real arm is another.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from spectral_vs._core import PointCloud


@runtime_checkable
class RobotInterface(Protocol):
    """A robot arm with a wrist-mounted depth camera.

    Joint order and units are those of the :class:`spectral_vs.Kinematics` built from the
    robot's URDF (rad, or m for prismatic joints). Point clouds are in the camera frame
    (Z forward, X right, Y down, metres) that the kinematics' ``T_tip_camera`` places on
    the tip link.

    Optional, outside the protocol: ``capture_stamp() -> float``, the sensor driver's time
    stamp of the last capture, s. :func:`spectral_vs.servo.run_servo` passes it to the
    servo, which holds on a stamp that does not advance (a stale frame).
    """

    def joint_positions(self) -> np.ndarray:
        """Current joint positions, shape (n,), rad (m for prismatic joints)."""
        ...

    def send_joint_velocities(self, q_dot: np.ndarray, dt: float) -> None:
        """Command joint velocities ``q_dot`` for the next ``dt`` seconds.

        A simulation advances its clock by ``dt``; a real robot forwards the command to
        its controller and returns (the loop paces itself). Implementations may clamp the
        command to their hardware limits but must never exceed them.

        Parameters
        ----------
        q_dot : ndarray, shape (n,)
            Joint velocities, rad/s (m/s for prismatic joints), in the kinematics' order.
        dt : float
            Duration of the command, s (the period of the servo loop).
        """
        ...

    def capture(self) -> PointCloud:
        """A point cloud with normals oriented toward the camera, in the camera frame.

        Returns
        -------
        PointCloud
            Points in metres with unit normals (``has_normals`` is True), ready for
            :func:`spectral_vs.align` as the scene.
        """
        ...

    def stop(self) -> None:
        """Bring every joint to zero velocity (safe stop)."""
        ...

    def time(self) -> float:
        """Robot clock in seconds: simulated time in a simulation, wall time on hardware."""
        ...
