"""Relocalization inside the controller's step: the global registration of the reference
onto the view (:func:`spectral_vs.align_views`) when the servo has no trusted estimate, its
spacing and backoff, the arrival check, and the hand-over to the recovery
(:mod:`spectral_vs.servo.recovery`) when the global registration cannot register the view
(``ServoParams.relocalize``, ``recover_after``; docs/servoing.md)."""

from __future__ import annotations

import time

import numpy as np

from spectral_vs._core import PointCloud, field_share
from spectral_vs._core import align_views as _align_views
from spectral_vs.servo.records import ServoRecord, ServoStatus
from spectral_vs.servo.state import ControllerState

#: The score of an estimate is its fitness over the share of the reference in the
#: field, but at least over this share (the extreme starts keep 30% in the field).
_MIN_FIELD_SHARE = 0.3


class Relocalization(ControllerState):
    """The relocalization and the recovery of :class:`~spectral_vs.servo.SpectralServo` (a
    base class of it: they read and keep the controller's state)."""

    def _relocalization_due(self) -> bool:
        """Whether a relocalization may run now (:meth:`RelocalizationSchedule.due`)."""
        return self._schedule.due(self._recovering())

    def _field_score(self, T: np.ndarray, fitness: float, cloud: PointCloud) -> float:
        """``fitness`` over the share of the reference that ``T`` puts inside the field of
        ``cloud`` (its points' bounds in x/z and y/z, nearer than ``max_depth``; at least
        ``_MIN_FIELD_SHARE``), in [0, 1]."""
        share = field_share(
            self._occlusion_reference,
            T,
            np.asarray(cloud.points),
            self.params.registration.max_depth,
        )
        # An estimate that puts the reference out of the field is not trusted for fitting
        # the little it leaves in view.
        return float(min(1.0, fitness / max(share, _MIN_FIELD_SHARE)))

    def _relocalize(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray | None
    ) -> None:
        """The global registration of the reference onto ``cloud`` (cropped, as captured),
        with the estimate carried along ``motion`` as its prior once one was taken: taken as the
        previous estimate when its support reaches ``relocalize_score``."""
        # The estimate carried so far, if a global registration was taken before (an
        # estimate of the local step alone far from the goal is no prior worth refining).
        # An estimate never confirmed since it was taken is no prior: kept over the search,
        # a wrong pose that tracked poorly was taken again at every relocalization.
        tracked = self._tracked
        trusted = tracked.anchored and self._schedule.confirmed and tracked.previous is not None
        prior = tracked.predicted(motion) if trusted else None
        self._schedule.tried()
        if not cloud.has_normals:  # an (N, 3) capture: the downsampled cloud's normals
            cloud = self._prepare(cloud, "current")
        result = _align_views(self._reference_view, cloud, self._view_params, prior)
        T, score = np.asarray(result.T_current_reference), float(result.support.score)
        record.relocalization_score = score
        record.relocalization_verdict = result.status
        record.relocalization_prior = prior is not None and result.hypothesis == -1
        # While recovering the view widens step by step: a marginal score in the middle
        # of it is worth waiting out (a 17-degree wrong pose scored 0.061 there).
        least = (
            self.params.recovery.recover_score
            if self._recovering()
            else self.params.relocalization.relocalize_score
        )
        # Only the answer the verdict vouches for: never an alternative it did not judge,
        # nor a pose the arrival check refuted.
        if (
            not result.reliable
            or score < least
            or self._arrival.near_refuted(T, self._odometry.since_first)
        ):
            self._recovery.failed(self._recovering(), record)
            return
        self._recovery.reset()
        record.relocalized = True
        self._tracked.take(T)
        self._odometry.accepted()

    def _check_arrival(self, T: np.ndarray, record: ServoRecord) -> None:
        """The arrival check (:class:`~spectral_vs.servo.arrival.ArrivalCheck`): an estimate
        ``T`` it refutes is forgotten, and the next step relocalizes."""
        if not self.params.relocalization.relocalize:
            return
        if self._arrival.refutes(T, record, self._odometry.since_first):
            self._forget_estimate()

    def _forget_estimate(self) -> None:
        """Forget the estimate and everything learnt about it: the watchdog's lock-on, the
        relocalizations tried and the recovery; the next step relocalizes."""
        self._tracked.forget()
        self._schedule.reset()
        self._recovery.reset()

    def _recovering(self) -> bool:
        """Whether this step recovers (:meth:`Recovery.due`): no global registration was
        taken in this run and the last ``recover_after`` ones failed."""
        return self._recovery.due(self._tracked.ever_anchored)

    def _recover(
        self,
        cloud: PointCloud,
        record: ServoRecord,
        motion: np.ndarray,
        now: float,
        start: float,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """A recovery step (:meth:`Recovery.step`): the twist toward the pose that widens
        the view's overlap with the reference, or the stop ``"lost"``; no registration
        runs."""
        self._clock.usable(now)  # the frame was usable: no sensor outage
        T = self._recovery.step(cloud, record, motion, self._odometry.since_first)
        if T is not None:
            record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record
