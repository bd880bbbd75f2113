"""What a servo run leaves behind: the status of a step (:class:`ServoStatus`), the record
of a step (:class:`ServoRecord`), the run's log (:class:`ServoLog`), and the reasons a run
ends (:data:`REASONS`) or a step holds the robot still (:data:`HOLDS`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Literal

import numpy as np

ServoState = Literal["running", "converged", "stopped"]

#: Why a servo run ended (``ServoStatus.reason``, ``ServoLog.reason``).
REASONS = (
    "converged",  # the estimated error is within the tolerances
    "empty_cloud",  # the camera sees nothing (peer servos; SpectralServo holds, HOLDS)
    "too_few_points",  # fewer than min_points (peer servos; SpectralServo holds, HOLDS)
    "sensor_outage",  # no usable frame (HOLDS) for longer than ServoParams.max_outage
    "unreliable",  # no reliable estimate (HOLDS: "unreliable") for longer than max_outage
    "jump",  # the estimate moved more than ServoParams.jump_limit_* since the last step
    "joint_limit",  # the joint velocity command had to clamp a joint at its position limit
    "max_steps",  # the step budget of run_servo is spent
    "max_time",  # the time budget of run_servo is spent (robot clock)
    "lost",  # the recovery (ServoParams.recover_after) ran recover_steps without a relocalization
)

#: Why :class:`SpectralServo` held the robot still at a step (``ServoRecord.hold``; ``""``
#: when it did not). A held step commands a zero twist, never converges and changes neither
#: the watchdog's nor the warm start's previous estimate; holds that last longer than
#: ``ServoParams.max_outage`` stop the servo with ``"sensor_outage"`` (``"unreliable"``
#: when the last hold was ``"unreliable"``).
HOLDS = (
    "empty_cloud",  # the capture has no point within max_depth (a dropped frame)
    "too_few_points",  # fewer than ServoParams.min_points points within max_depth
    "stale_frame",  # the frame of a previous step again (same fingerprint or capture stamp)
    "occluded",  # an occluder hides too much, or the registration without it is poor
    "unreliable",  # no estimate the verdict vouches for (docs/servoing.md, "cannot see")
)


@dataclass
class ServoStatus:
    """Where the servo stands after a step.

    Attributes
    ----------
    state : {"running", "converged", "stopped"}
        ``"stopped"`` means the robot must not move (the twist is zero).
    reason : str
        ``""`` while running, else one of :data:`REASONS`.
    message : str
        Details for a person, e.g. the size of a rejected jump, or why a running step held
        the robot still (``ServoRecord.hold``).
    """

    state: ServoState = "running"
    reason: str = ""
    message: str = ""


@dataclass
class ServoRecord:
    """One control step.

    Attributes
    ----------
    step : int
        Index of the step, from 0.
    time : float
        Robot clock at the capture, s (NaN from :meth:`SpectralServo.step` alone).
    points : int
        Points of the current cloud within ``ServoParams.max_depth``.
    T_current_desired : ndarray, shape (4, 4)
        The estimate: pose of the desired camera frame in the current camera frame (the
        one-iteration step in ``"iteration"`` mode). Identity when no registration ran.
    translation_error : float
        ``|t|`` of the estimate, m.
    rotation_error : float
        Angle of the estimate, rad.
    translation_cost, rotation_cost : float
        J_t (eq. 9, voxel grids) and J_r (eq. 16, normalised EGI coefficients) of the last
        iteration of Algorithm 1.
    translation_step : float
        Phase-correlation shift of the last iteration, voxels.
    rotation_gradient : float
        ``|grad C|`` of the last iteration, normalised correlation per rad.
    iterations : int
        Iterations of Algorithm 1 this step.
    fitness : float
        Share of the reference's voxels matched in the current cloud at the estimate.
    visible_fitness : float
        ``fitness`` over the part of the reference that no occluder hides,
        ``fitness / (1 - hidden_share)`` at most 1: what the stop rule, the lock-on, the
        loss and the arrival check read (an occluder lowers ``fitness`` by what it hides).
    reliable : bool
        The twist of the step comes from an estimate the servo vouches for: a global
        registration whose verdict is ``reliable`` (``ViewAlignResult.reliable``), carried
        along the camera's measured motion, or a registration warm-started from it that
        fits the reference's visible part (``visible_fitness``) and stays within the
        watchdog's limits of it. A step that is not reliable never moves the robot (it
        holds, ``"unreliable"``), except a recovery step (``recovery``) and the paper's
        bare loop (``ServoParams.relocalize`` off), which no verdict checks.
    twist : ndarray, shape (6,)
        Commanded camera twist (v in m/s, omega in rad/s), camera frame, after saturation.
    saturation : float
        Factor in (0, 1] the twist was scaled by to meet the speed limits.
    seconds : float
        Wall time of the step (registration and control law), s.
    cpu_seconds : float
        CPU time of the process during the step (``time.process_time``), s: what a busy
        machine does not inflate as it does the wall time.
    status : ServoStatus
        The outcome of the step.
    q, q_dot : ndarray or None
        Joint positions at the capture and the joint velocities sent (:func:`run_servo`).
    T_base_camera : ndarray or None
        Camera pose from the kinematics at ``q`` (:func:`run_servo`).
    velocity_scale : float
        ``VelocityCommand.velocity_scale`` of the joint command (1 when not limited).
    plane_turn : float
        Turn about the reference's dominant normal added to the estimate, rad
        (``ServoParams.plane_turn``; 0 when not used).
    tracking : bool
        The estimate is the registration that sought only
        ``ServoParams.tracking_translation`` (False also when it was redone with
        ``max_translation`` for a poor fitness).
    icp : bool
        The estimate ends with the tracking registration's point-to-plane ICP
        (``ServoParams.tracking_icp``), kept: Algorithm 1's step refined by pairs within a
        voxel, which leave out what the reference lacks and what an occluder hides.
    hold : str
        Why the step held the robot still (zero twist), one of :data:`HOLDS`; ``""`` when
        it did not. A held step never converges and changes neither the watchdog's nor the
        warm start's previous estimate; its ``status`` is ``running`` (the message says
        why) or, after ``ServoParams.max_outage``, ``stopped`` with ``"sensor_outage"``.
        At an ``"occluded"`` hold after a registration, the estimate's fields (
        ``T_current_desired``, the errors, ``fitness``) are those of the rejected one.
    outage : float
        Time without an accepted frame at a held step, s (see ``ServoParams.max_outage``);
        0 when the step was not held.
    occluded_points : int
        Points of the current cloud dropped as nearer to the camera than the reference
        could be (``ServoParams.occlusion_margin``); 0 when the occluder test did not run.
    hidden_share : float
        Share of the reference that those occluders hide, in [0, 1].
    relocalized : bool
        The step started from a global registration (``ServoParams.relocalize``).
    relocalization_score : float
        Support score of the global registration tried this step (NaN when none was).
    relocalization_verdict : str
        The verdict (``ViewAlignResult.status``: ``"reliable"``, ``"doubtful"``, ...) of the
        global registration tried this step (``""`` when none was). The servo takes a
        relocalization only when it is ``"reliable"`` (docs/trust.md), its support score
        reaches ``relocalize_score`` and it is not near a refuted estimate.
    relocalization_prior : bool
        The global registration kept the servo's own estimate (its prior, refined) over
        every searched pose.
    score : float
        The registration's score, uncalibrated, in [0, 1]: its fitness over the visible part
        of the reference (``visible_fitness``) or, under ``ServoParams.relocalize_fitness``,
        over the part that its estimate puts inside the current view's field (at least 30%
        of it); NaN when no registration ran. The loss and lock-on tests read it.
    confidence : float
        The probability that the step's estimate ``T_current_desired`` is right (within 5
        degrees and 10 mm, at the reference's centroid), in [0, 1]: ``score`` through the
        servo's calibration map, one for a registered estimate and one for a ``carried``
        one (``spectral_vs.calibrated_confidence(score, "servo" or "servo_carried")``,
        docs/trust.md, "The servo's confidence"); NaN when no registration ran. A report:
        the servo's rule of motion is ``reliable``.
    carried : bool
        The estimate is the last accepted one carried along the camera's measured motion,
        not the registration's: once a relocalization was taken, at a step whose fitness is
        under ``watchdog_fitness`` (before lock-on and after), where the views share too
        little for Algorithm 1's step.
    recovery : str
        ``""``, or how the step moved the camera to widen its overlap with the reference
        (``ServoParams.recover_after``): ``"turn"`` (in place, onto the reference's plane),
        ``"level"`` (onto it, at the reference's distance to it plus the stage's standoff)
        or ``"back_off"`` (along the optical axis).
        ``T_current_desired`` and the errors are then those of the recovery's target pose,
        no registration ran (``fitness`` and ``confidence`` NaN), and the step never
        converges.
    refuted : bool
        The arrival check refuted the estimate at this step (``ServoParams.refute_fitness``):
        it reached the goal with a poor fitness; the next step relocalizes away from it.
    """

    step: int
    time: float
    points: int
    T_current_desired: np.ndarray
    translation_error: float
    rotation_error: float
    translation_cost: float
    rotation_cost: float
    translation_step: float
    rotation_gradient: float
    iterations: int
    fitness: float
    twist: np.ndarray
    saturation: float
    seconds: float
    status: ServoStatus
    q: np.ndarray | None = None
    q_dot: np.ndarray | None = None
    T_base_camera: np.ndarray | None = None
    velocity_scale: float = 1.0
    plane_turn: float = 0.0
    tracking: bool = False
    icp: bool = False
    hold: str = ""
    outage: float = 0.0
    occluded_points: int = 0
    hidden_share: float = 0.0
    relocalized: bool = False
    relocalization_score: float = math.nan
    relocalization_verdict: str = ""
    relocalization_prior: bool = False
    score: float = math.nan
    confidence: float = math.nan
    carried: bool = False
    recovery: str = ""
    refuted: bool = False
    cpu_seconds: float = 0.0
    visible_fitness: float = math.nan
    reliable: bool = False


@dataclass
class ServoLog:
    """A servo run: its records, why it ended and in which state.

    Attributes
    ----------
    records : list of ServoRecord
        Every control step, in order.
    status : ServoStatus
        The final status; ``status.reason`` is one of :data:`REASONS`.
    wall_seconds : float
        Wall time of the whole run, s.
    """

    records: list[ServoRecord] = field(default_factory=list)
    status: ServoStatus = field(default_factory=ServoStatus)
    wall_seconds: float = 0.0

    @property
    def reason(self) -> str:
        """Why the run ended (one of :data:`REASONS`)."""
        return self.status.reason

    @property
    def converged(self) -> bool:
        """True when the run ended because the tolerances were met."""
        return self.status.state == "converged"

    def array(self, name: str) -> np.ndarray:
        """One field of every record stacked in an array, e.g. ``log.array("twist")``.

        Raises
        ------
        ValueError
            If ``name`` is not a field of :class:`ServoRecord` (the message lists them),
            also for a log without records.
        """
        names = [item.name for item in fields(ServoRecord)]
        if not isinstance(name, str) or name not in names:
            raise ValueError(
                f"name must be a field of ServoRecord ({', '.join(names)}), got {name!r}"
            )
        return np.array([getattr(record, name) for record in self.records])


# --------------------------------------------------------------------------- controller


def _empty_record(step: int, points: int) -> ServoRecord:
    """The record of a step before anything is measured: no estimate, zero twist."""
    return ServoRecord(
        step=step,
        time=math.nan,
        points=points,
        T_current_desired=np.eye(4),
        translation_error=math.nan,
        rotation_error=math.nan,
        translation_cost=math.nan,
        rotation_cost=math.nan,
        translation_step=math.nan,
        rotation_gradient=math.nan,
        iterations=0,
        fitness=math.nan,
        twist=np.zeros(6),
        saturation=1.0,
        seconds=0.0,
        status=ServoStatus(),
    )


def _too_few_points(count: int, message: str) -> ServoStatus:
    """The stop for an input with ``count`` usable points (or pixels), below the minimum (the
    baselines' servos; :class:`SpectralServo` holds instead, :data:`HOLDS`)."""
    return ServoStatus("stopped", "empty_cloud" if count == 0 else "too_few_points", message)


def _converged_status(translation: float, rotation: float) -> ServoStatus:
    """Converged, with the estimated error (m, rad) in the message."""
    return ServoStatus(
        "converged",
        "converged",
        f"estimated error {1000 * translation:.2f} mm, {math.degrees(rotation):.3f} deg",
    )
