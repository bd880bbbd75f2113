"""The servo controller (:class:`SpectralServo`): from the current cloud to a camera twist,
one registration of the reference per step, turned about the reference's dominant plane,
guarded by the watchdog and the stop rule with its hysteresis."""

from __future__ import annotations

import time

import numpy as np

from spectral_vs._core import AlignResult, PointCloud
from spectral_vs.clouds import CloudLike, as_cloud
from spectral_vs.poses import _pose, rotation_vector
from spectral_vs.servo.estimate import TrackedEstimate
from spectral_vs.servo.frames import Odometry
from spectral_vs.servo.gate import FrameGate, checked_motion
from spectral_vs.servo.law import _saturated_twist
from spectral_vs.servo.records import (
    ServoRecord,
    ServoStatus,
    _converged_status,
    _empty_record,
)
from spectral_vs.servo.reference import ServoReference, check_points
from spectral_vs.servo.relocalizer import Relocalizer
from spectral_vs.servo.scale import resolve_scale
from spectral_vs.servo.settings import ServoParams
from spectral_vs.servo.stop import StopRule
from spectral_vs.servo.tracker import Tracker


class SpectralServo:
    """The servo controller: from the current cloud to a camera twist.

    Each step passes the frame through its parts, each a small class that owns its state:
    the frame gate (faults, occluders, holds: :class:`~spectral_vs.servo.gate.FrameGate`),
    the relocalizer (global registrations, the arrival check, the recovery:
    :class:`~spectral_vs.servo.relocalizer.Relocalizer`), the tracker (the registration of
    the step: :class:`~spectral_vs.servo.tracker.Tracker`), the stop rule
    (:class:`~spectral_vs.servo.stop.StopRule`) and the control law. They share the
    estimate held (:class:`~spectral_vs.servo.estimate.TrackedEstimate`) and the camera's
    odometry (:class:`~spectral_vs.servo.frames.Odometry`).

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
    reference : PointCloud
        The reference, cropped to ``max_depth``, downsampled, with normals.

    Raises
    ------
    ValueError
        If the reference is empty or has fewer than ``params.min_points`` points.
    """

    def __init__(self, reference: CloudLike, params: ServoParams | None = None) -> None:
        given = params if params is not None else ServoParams()
        raw = as_cloud(reference, "reference")
        check_points(raw, given.faults.min_points)  # before its scale is measured
        self.params, self.scale = resolve_scale(given, raw)
        self._reference = ServoReference(raw, self.params)
        self.reference = self._reference.cloud
        self._tracked = TrackedEstimate()
        self._odometry = Odometry()
        self._gate = FrameGate(self.params, self._reference.occlusion_points)
        self._relocalizer = Relocalizer(self._reference, self._tracked, self._odometry)
        self._tracker = Tracker(self._reference, self._tracked)
        self._stop_rule = StopRule(self.params)
        self.reset()

    def reset(self) -> None:
        """Forget the previous estimate (the watchdog's memory), the step count, whether the
        servo converged (``ServoParams.reengage_translation``) and what the fault tests
        remember (the last frame, the outage's start)."""
        self._relocalizer.reset()
        self._tracked.reset()  # and no global registration taken in this run
        self._tracker.reset()
        self._steps = 0
        self._stop_rule.reset()
        self._odometry.reset()
        self._gate.reset()

    @property
    def last_turn(self) -> float:
        """The turn about the reference's dominant normal added to the last estimate, rad
        (0 without ``ServoParams.plane_turn`` or a dominant plane)."""
        return self._tracker.last_turn

    @property
    def has_plane_turn(self) -> bool:
        """True when the estimates are turned about the reference's dominant normal
        (``ServoParams.plane_turn`` and a reference with a dominant plane)."""
        return self._tracker.plane_turn is not None

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
        cloud = self._reference.crop(as_cloud(current, "current"))
        scene, result = self._tracker.register(cloud, initial_guess, self._reference.aligner)
        return self._tracker.turned(cloud, scene, np.asarray(result.T_scene_model)), result

    def twist(self, T_current_desired: np.ndarray) -> tuple[np.ndarray, float]:
        """The decoupled law and its saturation.

        Parameters
        ----------
        T_current_desired : ndarray, shape (4, 4)
            Pose of the desired camera frame in the current camera frame.

        Returns
        -------
        twist : ndarray, shape (6,)
            ``(v, omega)`` of the camera in the current camera frame, m/s and rad/s:
            ``v = lambda_t t``, ``omega = lambda_r theta u``, scaled down as a whole so that
            ``|v| <= max_linear_speed`` and ``|omega| <= max_angular_speed``.
        scale : float
            The factor in (0, 1] that was applied.

        Raises
        ------
        ValueError
            If ``T_current_desired`` is not a finite 4 x 4 rigid transform.
        """
        T = _pose(T_current_desired, "T_current_desired")  # ValueError unless 4 x 4 and finite
        return _saturated_twist(T[:3, 3], rotation_vector(T[:3, :3]), self.params.law)

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
        gate, relocalizer, tracked = self._gate, self._relocalizer, self._tracked
        now = gate.clock.tick(now)
        motion = self._carry(T_previous_current)
        # A sensor's invalid returns are dropped at each step, never raised on.
        raw = as_cloud(current, "current", drop_non_finite=True)
        cloud = self._reference.crop(raw)
        record = _empty_record(self._steps, len(cloud))
        self._steps += 1
        fault = gate.fault(raw, len(cloud), stamp)
        if fault is not None:
            return self._hold(record, *fault, now, start)
        # From the first occluded frame on, once the servo has an estimate it vouches for:
        # a relocalization taken, or the lock-on.
        vouched = tracked.locked and tracked.previous is not None
        predicted = tracked.predicted(motion) if vouched else None
        cloud, occluded, hidden, outage = gate.drop_occluders(cloud, record, predicted)
        if outage is not None:
            return self._hold(record, "occluded", outage, now, start)

        relocalize = self.params.relocalization.relocalize
        if relocalize and not tracked.anchored:
            cloud = relocalizer.drop_above_the_scene(cloud, record)
            # What stands above the scene's plane may fill the view: an outage, as an
            # occluder over most of the view is (a start of the large set emptied its view
            # so, and the relocalization raised on the empty cloud).
            emptied = gate.too_few_left(cloud, record, "above the scene's plane")
            if emptied is not None:
                return self._hold(record, "occluded", emptied, now, start)
        relocalizer.schedule.step()
        if relocalize and tracked.lost and relocalizer.due():
            relocalizer.relocalize(cloud, record, motion)
            motion = self._odometry.since_accepted
        if relocalizer.recovering():
            return self._recover(cloud, record, motion, now, start)
        if relocalize and not tracked.anchored:
            # No estimate the verdict vouched for: the local registration from the
            # identity is unchecked, and is not turned into motion.
            why = relocalizer.unreliable_message(record)
            return self._hold(record, "unreliable", why, now, start)
        T = self._tracker.measure(cloud, record, motion, hidden)

        jump = self._tracker.jump(T, motion)
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

    def _carry(self, T_previous_current: np.ndarray | None) -> np.ndarray:
        """Add the camera's motion since the previous step (identity when not given) to the
        odometry and to the stale-frame test's; return the motion since the last accepted
        step (``T_accepted_current``)."""
        if T_previous_current is not None:
            step = checked_motion(T_previous_current)
            self._odometry.carry(step)
            self._gate.stale_frames.moved(step)
        return self._odometry.since_accepted

    def _hold(
        self, record: ServoRecord, hold: str, message: str, now: float, start: float
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """Finish ``record`` as a held step (zero twist, nothing remembered), or stop with
        ``"sensor_outage"`` when the holds have lasted longer than ``max_outage``."""
        self._gate.hold(record, hold, message, now)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _recover(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray, now: float, start: float
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """A recovery step: the twist toward the pose that widens the view's overlap with
        the reference, or the stop ``"lost"``; no registration runs."""
        self._gate.clock.usable(now)  # the frame was usable: no sensor outage
        T = self._relocalizer.recover(cloud, record, motion)
        if T is not None:
            record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

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
        """Keep ``T`` as the estimate: the watchdog's and the warm start's memory, the
        outage's clock, the lock-on and whether the servo is lost."""
        p = self.params
        arms = record.visible_fitness >= p.watchdog.watchdog_fitness
        self._tracked.accept(T, arms, record.score >= p.relocalization.relocalize_fitness)
        self._odometry.accepted()
        self._gate.clock.usable(now)
        self._relocalizer.schedule.accepted(record.relocalized, not self._tracked.lost)

    def _command(self, T: np.ndarray, record: ServoRecord) -> None:
        """The stop rule with its hysteresis, else the twist toward ``T``."""
        if self._stop_rule.settled(record):
            record.status = _converged_status(record.translation_error, record.rotation_error)
        else:
            record.twist, record.saturation = self.twist(T)
            self._relocalizer.check_arrival(T, record)
