"""The servo loop (:func:`run_servo`): capture, step, joint command, on any
:class:`~spectral_vs.robot.RobotInterface`."""

from __future__ import annotations

import copy
import math
import numbers
import time
from collections.abc import Callable

import numpy as np

from spectral_vs._core import Kinematics, VelocityCommandParams
from spectral_vs.robot import RobotInterface
from spectral_vs.servo.controller import SpectralServo
from spectral_vs.servo.records import ServoLog, ServoRecord, ServoStatus


def run_servo(
    robot: RobotInterface,
    kinematics: Kinematics,
    servo: SpectralServo,
    *,
    dt: float = 0.1,
    max_steps: int = 200,
    max_time: float = math.inf,
    velocity_params: VelocityCommandParams | None = None,
    stop_at_joint_limit: bool = True,
    callback: Callable[[ServoRecord], None] | None = None,
) -> ServoLog:
    """Servo ``robot`` until the camera reaches the reference pose or a stop condition.

    Each step: read ``q``, capture, :meth:`SpectralServo.step` (with the camera motion since
    the last step from the forward kinematics, for the watchdog, and the robot clock at the
    capture as ``now``), ``q_dot = kinematics.joint_velocities(q, twist, velocity_params)``,
    send it for ``dt`` seconds. A held step (``ServoRecord.hold``, :data:`HOLDS`) sends zero
    joint velocities for ``dt`` and the loop goes on. A robot whose driver stamps its
    captures may offer ``capture_stamp()`` (s, the stamp of the last capture): it is passed
    on as ``stamp``. The robot is stopped (:meth:`RobotInterface.stop`) whatever ends the
    run, an exception included.

    Parameters
    ----------
    robot : RobotInterface
        The arm and its wrist camera.
    kinematics : Kinematics
        Camera kinematics of the robot (its Jacobian maps joint velocities to the camera
        twist in the camera frame).
    servo : SpectralServo
        The controller, built on the reference cloud.
    dt : float
        Control period, s: each command lasts ``dt``.
    max_steps : int
        Step budget; the run stops with reason ``"max_steps"`` when it is spent.
    max_time : float
        Time budget on the robot clock (:meth:`RobotInterface.time`), s; reason ``"max_time"``.
    velocity_params : VelocityCommandParams, optional
        Settings of the joint velocity command; its ``dt`` is set to ``dt``. Defaults to a
        damped pseudo-inverse, a 0.01 rad margin to the position limits and 1 rad/s per joint.
    stop_at_joint_limit : bool
        Stop (reason ``"joint_limit"``) when the command had to clamp a joint at its position
        limit, rather than creeping along the limit with the remaining joints.
    callback : callable, optional
        Called with each :class:`ServoRecord` (progress printing).

    Returns
    -------
    ServoLog
        The records, the final status and its reason.

    Raises
    ------
    TypeError
        For ``dt``, ``max_steps`` or ``max_time`` that is not a number (``max_steps`` an
        integer), or ``velocity_params`` that is not a :class:`VelocityCommandParams`.
    ValueError
        For ``dt`` that is not finite and > 0, ``max_steps`` < 1 or a NaN ``max_time``.
    """
    for name, value, kind in (
        ("dt", dt, numbers.Real),
        ("max_steps", max_steps, numbers.Integral),
        ("max_time", max_time, numbers.Real),
    ):
        if isinstance(value, bool) or not isinstance(value, kind):
            what = "an integer" if kind is numbers.Integral else "a number"
            raise TypeError(f"{name} must be {what}, got {value!r}")
    if not dt > 0 or not math.isfinite(dt):
        raise ValueError(f"dt must be finite and > 0, got {dt}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if math.isnan(max_time):
        raise ValueError("max_time must be a number of seconds (inf: no budget), got nan")
    if velocity_params is not None and not isinstance(velocity_params, VelocityCommandParams):
        raise TypeError(
            f"velocity_params must be a VelocityCommandParams, got {type(velocity_params).__name__}"
        )
    params = (
        copy.copy(velocity_params)
        if velocity_params is not None
        else VelocityCommandParams(dt=dt, max_joint_speed=1.0)
    )
    params.dt = dt
    log = ServoLog()
    start_wall = time.perf_counter()
    start_time = robot.time()
    previous_pose: np.ndarray | None = None
    servo.reset()
    try:
        while True:
            budget = _budget_spent(robot, log, start_time, max_steps, max_time)
            if budget is not None:
                log.status = budget
                break
            record, twist, previous_pose = _servo_step(
                robot, kinematics, servo, previous_pose, start_time
            )
            log.records.append(record)
            if record.status.state == "running" and not record.hold:
                _command_joints(kinematics, record, twist, params, stop_at_joint_limit)
            if record.status.state != "running":
                record.q_dot = np.zeros_like(record.q_dot)
                if callback is not None:
                    callback(record)
                log.status = record.status
                break
            if callback is not None:
                callback(record)
            assert record.q_dot is not None
            robot.send_joint_velocities(record.q_dot, dt)
    finally:
        robot.stop()
        log.wall_seconds = time.perf_counter() - start_wall
    return log


def _budget_spent(
    robot: RobotInterface, log: ServoLog, start_time: float, max_steps: int, max_time: float
) -> ServoStatus | None:
    """The stop when the step or time budget of :func:`run_servo` is spent, else None."""
    if len(log.records) >= max_steps:
        return ServoStatus("stopped", "max_steps", f"{max_steps} steps")
    if robot.time() - start_time >= max_time:
        return ServoStatus("stopped", "max_time", f"{max_time:g} s")
    return None


def _servo_step(
    robot: RobotInterface,
    kinematics: Kinematics,
    servo: SpectralServo,
    previous_pose: np.ndarray | None,
    start_time: float,
) -> tuple[ServoRecord, np.ndarray, np.ndarray]:
    """Read ``q``, capture and step the servo (with the camera's motion since
    ``previous_pose`` from the kinematics, the robot clock and the capture's stamp): the
    record, the twist and the camera pose at ``q``. A held step gets zero joint velocities."""
    q = np.asarray(robot.joint_positions(), dtype=float)
    pose = np.asarray(kinematics.forward(q))
    motion = None if previous_pose is None else np.linalg.inv(previous_pose) @ pose
    cloud = robot.capture()
    now = robot.time()
    stamp_of = getattr(robot, "capture_stamp", None)
    stamp = float(stamp_of()) if callable(stamp_of) else None
    twist, _, record = servo.step_record(cloud, motion, now=now, stamp=stamp)
    record.time = now - start_time
    record.q, record.T_base_camera = q, pose
    # Zero joint velocities unless the command sets them (a held step stays still,
    # whatever the kinematics say).
    record.q_dot = np.zeros_like(q)
    return record, twist, pose


def _command_joints(
    kinematics: Kinematics,
    record: ServoRecord,
    twist: np.ndarray,
    params: VelocityCommandParams,
    stop_at_joint_limit: bool,
) -> None:
    """The joint velocities of ``twist`` at ``record.q`` into ``record``; the stop
    ``"joint_limit"`` in its status when the command clamped a joint at its limit."""
    assert record.q is not None
    command = kinematics.joint_velocities(record.q, twist, params)
    record.q_dot = np.asarray(command.q_dot)
    record.velocity_scale = float(command.velocity_scale)
    limited = list(command.position_limited)
    if limited and stop_at_joint_limit:
        names = [kinematics.joint_names[i] for i in limited]
        record.status = ServoStatus(
            "stopped", "joint_limit", f"joints at their position limits: {names}"
        )
