"""The servo controller (:class:`SpectralServo`): from the current cloud to a camera twist,
one registration of the reference per step, turned about the reference's dominant plane,
guarded by the watchdog and the stop rule with its hysteresis."""

from __future__ import annotations

import copy
import math
import time

import numpy as np

from spectral_vs._core import (
    AlignResult,
    ModelAligner,
    PointCloud,
    ViewAlignParams,
    calibrated_confidence,
)
from spectral_vs.poses import pose_error
from spectral_vs.registration import CloudLike, as_cloud
from spectral_vs.servo.arrival import ArrivalCheck
from spectral_vs.servo.estimate import TrackedEstimate
from spectral_vs.servo.faults import _OCCLUSION_REFERENCE_POINTS, SensorFaults
from spectral_vs.servo.frames import Odometry, StaleFrames, StepClock
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.plane_turn import _PlaneTurn
from spectral_vs.servo.records import (
    ServoRecord,
    ServoStatus,
    _converged_status,
    _empty_record,
)
from spectral_vs.servo.recovery import Recovery
from spectral_vs.servo.relocalization import Relocalization
from spectral_vs.servo.scale import resolve_scale
from spectral_vs.servo.schedule import RelocalizationSchedule
from spectral_vs.servo.settings import ServoParams
from spectral_vs.servo.stop import StopRule


def _check_points(reference: PointCloud, min_points: int) -> None:
    """Refuse a reference with fewer than ``min_points`` points (ValueError)."""
    if len(reference) < min_points:
        raise ValueError(
            f"reference has {len(reference)} points, fewer than min_points = {min_points}"
        )


class SpectralServo(SensorFaults, Relocalization):
    """The servo controller: from the current cloud to a camera twist.

    Parameters
    ----------
    reference : PointCloud or ndarray
        Cloud captured at the desired camera pose, in that camera frame, metres; (N, 3) or
        (N, 6) arrays (points, normals) are accepted. Missing normals are estimated and
        turned toward the camera origin.
    params : ServoParams, optional
        Settings; defaults to ``ServoParams()``. Its scale lengths given as 0 (the
        defaults) are derived from the reference here (:mod:`spectral_vs.servo.scale`).

    Attributes
    ----------
    params : ServoParams
        The settings used: a copy of ``params`` with every scale length resolved.
    scale : ServoScale
        The scale lengths resolved (m), the reference's extent and which were derived.

    Raises
    ------
    ValueError
        If the reference is empty or has fewer than ``params.min_points`` points.
    """

    def __init__(self, reference: CloudLike, params: ServoParams | None = None) -> None:
        given = params if params is not None else ServoParams()
        raw = as_cloud(reference, "reference")
        _check_points(raw, given.faults.min_points)  # before its scale is measured
        self.params, self.scale = resolve_scale(given, raw)
        cloud = self._crop(raw)
        _check_points(cloud, given.faults.min_points)
        self._align_params = self.params.align_params()
        self._view_params = ViewAlignParams(**self.params.relocalization.view_overrides)
        self.reference = self._prepare(cloud, "reference")
        self._clock = StepClock()
        self._stale_frames = StaleFrames()
        self._odometry = Odometry()
        self._tracked = TrackedEstimate()
        # What the relocalization registers: the reference as captured, with its normals.
        self._reference_view = cloud if cloud.has_normals else self.reference
        # The reference's side of the registration (its EGI coefficients, centred points)
        # is prepared once here; each step adds only the current cloud's work.
        self._aligner = ModelAligner(self.reference, self._align_params)
        self._tracking_aligner: ModelAligner | None = None
        if self.params.uses_tracking():
            tracking = copy.copy(self._align_params)
            tracking.max_translation = self.params.registration.tracking_translation
            tracking.local_icp = self.params.registration.tracking_icp
            self._tracking_aligner = ModelAligner(self.reference, tracking)
        self._centroid = np.asarray(self.reference.centroid())
        self._plane_turn: _PlaneTurn | None = (
            _PlaneTurn.of(self._reference_view, self._centroid, self.params, self._align_params)
            if self.params.plane.plane_turn
            else None
        )
        reference_points = np.asarray(cloud.points)
        stride = max(1, math.ceil(len(reference_points) / _OCCLUSION_REFERENCE_POINTS))
        self._occlusion_reference = np.array(reference_points[::stride], dtype=float)
        self._recovery = Recovery.of(self._reference_view, self.params, self._prepare)
        self._stop_rule = StopRule(self.params)
        self._arrival = ArrivalCheck(self.params)
        self._schedule = RelocalizationSchedule(self.params)
        self.reset()

    def reset(self) -> None:
        """Forget the previous estimate (the watchdog's memory), the step count, whether the
        servo converged (``ServoParams.reengage_translation``) and what the fault tests
        remember (the last frame, the outage's start)."""
        self._forget_estimate()
        self._tracked.reset()  # and no global registration taken in this run
        self._steps = 0
        self._last_turn = 0.0
        self._arrival.reset()
        self._stop_rule.reset()
        self._reset_faults()

    @property
    def last_turn(self) -> float:
        """The turn about the reference's dominant normal added to the last estimate, rad
        (0 without ``ServoParams.plane_turn`` or a dominant plane)."""
        return self._last_turn

    @property
    def has_plane_turn(self) -> bool:
        """True when the estimates are turned about the reference's dominant normal
        (``ServoParams.plane_turn`` and a reference with a dominant plane)."""
        return self._plane_turn is not None

    @property
    def previous_estimate(self) -> np.ndarray | None:
        """The last accepted ``T_current_desired`` (None before the first step)."""
        previous = self._tracked.previous
        return None if previous is None else previous.copy()

    def estimate(
        self, current: CloudLike, initial_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, AlignResult]:
        """Register the reference onto ``current``: ``T_current_desired`` and the AlignResult.

        Parameters
        ----------
        current : PointCloud or ndarray
            The cloud of the camera at its current pose, camera frame, metres (not empty
            within ``max_depth``).
        initial_guess : ndarray (4, 4), optional
            ``T_current_desired`` to start Algorithm 1 from; the identity by default.

        Returns
        -------
        T_current_desired : ndarray, shape (4, 4)
            The registration's pose, turned about the reference's dominant normal with
            ``ServoParams.plane_turn`` (the turn is :attr:`last_turn`).
        result : AlignResult
            The registration (its ``T_scene_model`` before the turn).
        """
        cloud = self._crop(as_cloud(current, "current"))
        return self._estimate(cloud, initial_guess, self._aligner)

    def _estimate(
        self, cloud: PointCloud, initial_guess: np.ndarray | None, aligner: ModelAligner
    ) -> tuple[np.ndarray, AlignResult]:
        """:meth:`estimate` of the cropped ``cloud`` with the given prepared reference."""
        scene, result = self._register(cloud, initial_guess, aligner)
        return self._turned(cloud, scene, np.asarray(result.T_scene_model)), result

    def _register(
        self, cloud: PointCloud, initial_guess: np.ndarray | None, aligner: ModelAligner
    ) -> tuple[PointCloud, AlignResult]:
        """The downsampled ``cloud`` and the registration of the reference onto it, without
        the plane turn (a step turns only the estimate it keeps)."""
        scene = self._prepare(cloud, "current")
        return scene, aligner.align(scene, initial_guess)

    def _turned(self, cloud: PointCloud, scene: PointCloud, T: np.ndarray) -> np.ndarray:
        """``T`` turned about the reference's dominant normal (``ServoParams.plane_turn``),
        from the normals of ``cloud`` (those of its downsampled ``scene`` without)."""
        self._last_turn = 0.0
        if self._plane_turn is not None:
            normals = np.asarray((cloud if cloud.has_normals else scene).normals)
            self._last_turn = self._plane_turn.turn(normals, T)
            T = self._plane_turn.turned(T, self._last_turn)
        return T

    def step(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus]:
        """One control step: the camera twist toward the desired pose, and the status.

        Parameters
        ----------
        current : PointCloud or ndarray
            The current cloud, camera frame, metres.
        T_previous_current : ndarray (4, 4), optional
            The camera's own motion since the previous step (pose of the current camera
            frame in the previous one, e.g. from the forward kinematics). The watchdog then
            compares the new estimate with the previous one carried along this motion
            (over the held steps since, too); without it, with the previous estimate itself,
            and the camera counts as still for the stale-frame test.
        now : float, optional
            Time of the capture, s, on the clock that ``ServoParams.max_outage`` is
            measured on (:func:`run_servo` passes the robot clock). Without it, the
            computer's monotonic clock (:func:`time.monotonic`) at the call.
        stamp : float, optional
            The capture's own time stamp from the sensor driver, s: a stamp not later than
            the last one marks a stale frame. Without it, only the fingerprint tells.

        Returns
        -------
        twist : ndarray, shape (6,)
            ``(v, omega)``, camera frame, m/s and rad/s; zero unless the state is running
            and the step was not held.
        status : ServoStatus
            ``running`` (also at a held step: its message says why, see :data:`HOLDS`),
            ``converged`` (the estimate is within the tolerances and the fitness high
            enough) or ``stopped`` with a reason: ``"sensor_outage"`` (holds for longer
            than ``max_outage``) or ``"jump"`` (the watchdog, armed once the fitness has
            reached ``watchdog_fitness``).
        """
        twist, status, _ = self.step_record(current, T_previous_current, now=now, stamp=stamp)
        return twist, status

    def step_record(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step` with its :class:`ServoRecord`."""
        cpu = time.process_time()
        twist, status, record = self._step_record(current, T_previous_current, now, stamp)
        record.cpu_seconds = time.process_time() - cpu
        return twist, status, record

    def _step_record(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None,
        now: float | None,
        stamp: float | None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step_record` without its CPU time: the frame's faults, the occluders, the
        relocalization or the recovery, the registration, the watchdog, the stop rule."""
        start = time.perf_counter()
        now = self._clock.tick(now)
        motion = self._carry(T_previous_current)
        # A sensor's invalid returns are dropped at each step, never raised on.
        raw = as_cloud(current, "current", drop_non_finite=True)
        cloud = self._crop(raw)
        record = _empty_record(self._steps, len(cloud))
        self._steps += 1
        fault = self._frame_fault(raw, len(cloud), stamp)
        if fault is not None:
            return self._hold(record, *fault, now, start)
        cloud, occluded, hidden, outage = self._drop_occluders(cloud, record, motion)
        if outage is not None:
            return self._hold(record, "occluded", outage, now, start)

        relocalize = self.params.relocalization.relocalize
        if relocalize and not self._tracked.anchored:
            cloud = self._recovery.drop_above_the_scene(cloud, record, self._odometry.since_first)
            # What stands above the scene's plane may fill the view: an outage, as an
            # occluder over most of the view is (a start of the large set emptied its view
            # so, and the relocalization raised on the empty cloud).
            emptied = self._too_few_left(cloud, record, "above the scene's plane")
            if emptied is not None:
                return self._hold(record, "occluded", emptied, now, start)
        self._schedule.step()
        if relocalize and self._tracked.lost and self._relocalization_due():
            self._relocalize(cloud, record, motion)
            motion = self._odometry.since_accepted
        if self._recovering():
            return self._recover(cloud, record, motion, now, start)
        if relocalize and not self._tracked.anchored:
            # No estimate the verdict vouched for: the local registration from the
            # identity is unchecked, and is not turned into motion.
            return self._hold(record, "unreliable", self._unreliable_message(record), now, start)
        T = self._measure(cloud, record, motion, hidden)

        jump = self._jump(T, motion)
        if occluded and not record.carried:
            # Ridden only when the registration of the rest is sound: a registration that
            # the occluder corrupted turns into no motion and trips no watchdog. A carried
            # estimate does not depend on the frame.
            message = self._occluded_hold(record, jump)
            if message is not None:
                return self._hold(record, "occluded", message, now, start)
        if jump is not None:
            record.status = ServoStatus("stopped", "jump", jump)
        else:
            record.reliable = relocalize
            self._accept(T, record, now)
            self._command(T, record)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _unreliable_message(self, record: ServoRecord) -> str:
        """Why a step without an estimate holds: the last global registration's verdict."""
        if record.relocalization_verdict:
            return (
                f"the global registration is {record.relocalization_verdict} (support score "
                f"{record.relocalization_score:.3f}), not taken"
            )
        return "no reliable estimate yet; the next global registration is due later"

    def _registration(
        self,
        cloud: PointCloud,
        record: ServoRecord,
        guess: np.ndarray | None,
        motion: np.ndarray,
        hidden: float,
    ) -> tuple[PointCloud, AlignResult]:
        """The step's registration from ``guess``: within ``tracking_translation`` when it
        may track (:meth:`_can_track`), redone with ``max_translation`` when a locked-on
        tracking fit is poor over the part of the reference no occluder hides (``hidden``
        is the share hidden); fills ``record.tracking``."""
        # A relocalized step checks the global pose on the full grid once.
        tracking = not record.relocalized and self._can_track(guess, motion)
        if tracking:
            assert self._tracking_aligner is not None
            scene, result = self._register(cloud, guess, self._tracking_aligner)
            # Once locked on, a poor fit may mean the answer lies beyond the tracking bound
            # (the camera or the scene jumped): the full search decides, and the watchdog
            # sees the jump. Before, a poor fit is the relocalization's to judge.
            visible = result.fitness / max(1.0 - hidden, 1e-9)
            tracking = not self._tracked.armed or visible >= self.params.watchdog.watchdog_fitness
        if not tracking:
            scene, result = self._register(cloud, guess, self._aligner)
        record.tracking = tracking
        return scene, result

    def _measure(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray, hidden: float
    ) -> np.ndarray:
        """The step's estimate ``T_current_desired``: the registration turned about the
        plane, or the last estimate carried along the camera's motion before lock-on; fills
        the record's estimate, errors, fitness (also over the ``hidden`` share's rest),
        confidence and Algorithm 1's figures."""
        p = self.params
        guess = None
        if (
            p.registration.warm_start or self._tracked.anchored
        ) and self._tracked.previous is not None:
            guess = self._tracked.predicted(motion)
        scene, result = self._registration(cloud, record, guess, motion, hidden)
        last = result.history[-1] if len(result.history) else None
        record.fitness = float(result.fitness)
        # An occluder lowers the fitness by the share of the reference it hides: every
        # test below reads the fitness over the rest.
        record.visible_fitness = min(1.0, record.fitness / max(1.0 - hidden, 1e-9))
        # Where the registration fits poorly the views share too little for Algorithm 1's
        # step: the EGI correlation of two partial views peaks 10-20 degrees off the truth,
        # and far from the goal the phase correlation's shift leaps by tens of mm from step
        # to step. The last good estimate carried along the camera's measured motion is the
        # estimate while the fitness is under watchdog_fitness, before lock-on and after.
        record.carried = (
            self._tracked.anchored
            and guess is not None
            and record.visible_fitness < p.watchdog.watchdog_fitness
        )
        T = np.asarray(result.T_scene_model)
        # The plane turn is of the estimate the step keeps, and of the confidence's pose
        # under its threshold: a carried step with a confident fit uses neither. An ICP
        # that was kept (tracking_icp) already fixed the turn about the plane's normal,
        # past the EGIs, whose off-plane normals a tool on the table biases (2.8 degrees).
        poor = record.visible_fitness < p.relocalization.relocalize_fitness
        record.icp = not record.carried and result.icp_iterations > 0
        if (not record.carried or poor) and not record.icp:
            T = self._turned(cloud, scene, T)
        else:
            self._last_turn = 0.0
        # fitness / share >= fitness: the share is needed only under the threshold.
        record.score = (
            record.visible_fitness
            if record.visible_fitness >= p.relocalization.relocalize_fitness
            else self._field_score(T, record.visible_fitness, cloud)
        )
        # The confidence is of the estimate the step keeps: a carried one did not take the
        # registration, and is calibrated apart.
        record.confidence = calibrated_confidence(
            record.score, "servo_carried" if record.carried else "servo"
        )
        if record.carried:
            assert guess is not None
            T = guess
            self._last_turn = 0.0
        record.T_current_desired = T
        record.translation_error, record.rotation_error = pose_error(T)
        record.iterations = int(result.iterations)
        record.plane_turn = 0.0 if record.carried else self._last_turn
        if last is not None:
            record.translation_cost = float(last.translation_cost)
            record.rotation_cost = float(last.rotation_cost)
            record.translation_step = float(last.translation_step)
            record.rotation_gradient = float(last.rotation_gradient)
        return T

    def _occluded_hold(self, record: ServoRecord, jump: str | None) -> str | None:
        """Why a step whose registration ran with an occluder in view holds: the estimate
        would trip the watchdog (``jump``), or its fitness over the reference's visible
        part is under ``watchdog_fitness``; None when the step may move."""
        if jump is not None:
            return f"with an occluder, {jump}"
        if record.visible_fitness < self.params.watchdog.watchdog_fitness:
            return (
                f"with an occluder hiding {100 * record.hidden_share:.0f}% of the reference, "
                f"the fitness over the rest is {record.visible_fitness:.3f} "
                f"(watchdog_fitness {self.params.watchdog.watchdog_fitness})"
            )
        return None

    def _accept(self, T: np.ndarray, record: ServoRecord, now: float) -> None:
        """Keep ``T`` as the previous estimate: the watchdog's and the warm start's memory,
        the outage's clock, the lock-on and whether the servo is lost."""
        p = self.params
        arms = record.visible_fitness >= p.watchdog.watchdog_fitness
        self._tracked.accept(T, arms, record.score >= p.relocalization.relocalize_fitness)
        self._odometry.accepted()
        self._clock.usable(now)
        self._schedule.accepted(record.relocalized, not self._tracked.lost)

    def _command(self, T: np.ndarray, record: ServoRecord) -> None:
        """The stop rule with its hysteresis, else the twist toward ``T``."""
        if self._stop_rule.settled(record):
            record.status = _converged_status(record.translation_error, record.rotation_error)
        else:
            record.twist, record.saturation = self.twist(T)
            self._check_arrival(T, record)

    def _can_track(self, guess: np.ndarray | None, motion: np.ndarray | None) -> bool:
        """Whether this registration may seek only ``tracking_translation``: locked on (the
        watchdog armed, or a relocalization taken), and
        the predicted estimate moves the reference's centroid by at most half of it from
        the registration's start ``guess`` (identity when None); ``motion`` as for
        :meth:`TrackedEstimate.predicted`."""
        locked = self._tracked.locked
        if self._tracking_aligner is None or not locked or self._tracked.previous is None:
            return False
        predicted = self._tracked.predicted(motion)
        start = np.eye(4) if guess is None else np.asarray(guess, dtype=float)
        c = self._centroid
        moved = predicted[:3, :3] @ c + predicted[:3, 3] - (start[:3, :3] @ c + start[:3, 3])
        return bool(np.abs(moved).max() <= 0.5 * self.params.registration.tracking_translation)

    def _jump(self, T: np.ndarray, motion: np.ndarray | None) -> str | None:
        """A message when ``T`` is implausibly far from the previous estimate carried along
        ``motion`` (as for :meth:`TrackedEstimate.predicted`), else None."""
        if self._tracked.previous is None or not self._tracked.armed:
            return None
        predicted = self._tracked.predicted(motion)
        # |translation| of predicted^-1 T is |t - t_predicted|: the two parts are independent.
        moved, turned = pose_error(_rigid_inverse(predicted) @ T)
        p = self.params
        if moved > p.watchdog.jump_limit_translation or turned > p.watchdog.jump_limit_rotation:
            return (
                f"the estimate changed by {1000 * moved:.1f} mm and {math.degrees(turned):.2f} "
                f"deg in one step (limits {1000 * p.watchdog.jump_limit_translation:.1f} mm, "
                f"{math.degrees(p.watchdog.jump_limit_rotation):.2f} deg)"
            )
        return None


# --------------------------------------------------------------------------- the loop
