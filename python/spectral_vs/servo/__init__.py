"""3D spectral visual servoing: the camera is driven to the pose where a reference cloud was
captured (paper, section II-D, eq. 16-18 and Algorithm 1).

At every control step the reference cloud (captured at the desired pose, camera frame) is
registered onto the current cloud (current camera frame): ``T_scene_model`` of
``align(model=reference, scene=current)`` is ``T_current_desired``, the pose of the desired
camera frame in the current one. The decoupled law

    v = lambda_t t,    omega = lambda_r theta u        (T_current_desired = [R(theta u) t])

gives the camera twist, expressed in the current camera frame, that :meth:`Kinematics.
joint_velocities` turns into joint velocities (eq. 18, ``q_dot = J_c^+ X_dot_c``). It is the
classical position-based law: the error ``(t, theta u)`` decays exponentially and the camera
origin moves along a straight line toward the desired one.

Two ways to get the estimate (``ServoParams.mode``):

``"iteration"``
    The paper: one update of Algorithm 1 per control step, from the identity, without the
    global rotation search. The robot's motion plays the role of the iterations.
``"pose"``
    A full registration per step (Algorithm 1 to convergence, with or without the global
    rotation search): a position-based servo on the converged estimate.

With ``ServoParams.warm_start`` each registration starts from the previous estimate carried
along the camera's measured motion instead of the identity (the most robust setting measured,
with ``"pose"``: docs/servoing.md).

:func:`run_servo` closes the loop on any :class:`~spectral_vs.robot.RobotInterface` and stops
the robot safely (zero velocity, with a reason) on a sensor outage longer than
``ServoParams.max_outage``, an implausible jump of the estimate, a joint limit, or a spent
budget. Shorter sensor faults (a dropped or repeated frame, too few points, a hand passing
in front of the camera) hold the robot still and the servo goes on (:data:`HOLDS`).

The package, one module a job:

- :mod:`~spectral_vs.servo.settings`: :class:`ServoParams`, grouped by stage;
- :mod:`~spectral_vs.servo.scale`: the scale lengths derived from the reference
  (:class:`ServoScale`);
- :mod:`~spectral_vs.servo.controller`: :class:`SpectralServo`, whose step composes its
  parts, each a class that owns its state: the reference's prepared sides
  (:mod:`~spectral_vs.servo.reference`), the frame gate (faults, occluders, holds:
  :mod:`~spectral_vs.servo.gate`), the relocalizer (global registrations, the arrival
  check, the recovery: :mod:`~spectral_vs.servo.relocalizer`,
  :mod:`~spectral_vs.servo.arrival`, :mod:`~spectral_vs.servo.recovery`), the tracker
  (the step's registration and the plane turn: :mod:`~spectral_vs.servo.tracker`,
  :mod:`~spectral_vs.servo.plane_turn`), the stop rule (:mod:`~spectral_vs.servo.stop`),
  sharing the estimate held (:mod:`~spectral_vs.servo.estimate`) and the odometry
  (:mod:`~spectral_vs.servo.frames`);
- :mod:`~spectral_vs.servo.law`: the decoupled law and its saturation;
- :mod:`~spectral_vs.servo.loop`: :func:`run_servo`;
- :mod:`~spectral_vs.servo.records`: :class:`ServoStatus`, :class:`ServoRecord`,
  :class:`ServoLog`, :data:`REASONS`, :data:`HOLDS`.

The experiment's harness (start poses, the start check, recording) is
:mod:`spectral_vs.experiment`, and the figure of a run :func:`spectral_vs.plotting.plot_servo`.
"""

from __future__ import annotations

from spectral_vs._core import field_share
from spectral_vs.poses import pose_error, rotation_matrix, rotation_vector
from spectral_vs.servo.controller import SpectralServo
from spectral_vs.servo.fault_settings import FaultParams, RecoveryParams, RelocalizationParams
from spectral_vs.servo.loop import run_servo
from spectral_vs.servo.plane_turn import dominant_normal, dominant_plane
from spectral_vs.servo.records import (
    HOLDS,
    REASONS,
    ServoLog,
    ServoRecord,
    ServoStatus,
    _empty_record,  # noqa: F401  (read by the tests)
)
from spectral_vs.servo.scale import ServoScale
from spectral_vs.servo.settings import ServoParams
from spectral_vs.servo.stage_settings import (
    LawParams,
    PlaneTurnParams,
    RegistrationParams,
    StopParams,
    WatchdogParams,
)

__all__ = [
    "HOLDS",
    "REASONS",
    "FaultParams",
    "LawParams",
    "PlaneTurnParams",
    "RecoveryParams",
    "RegistrationParams",
    "RelocalizationParams",
    "ServoLog",
    "ServoParams",
    "ServoRecord",
    "ServoScale",
    "ServoStatus",
    "SpectralServo",
    "StopParams",
    "WatchdogParams",
    "dominant_normal",
    "dominant_plane",
    "field_share",
    "pose_error",
    "rotation_matrix",
    "rotation_vector",
    "run_servo",
]
