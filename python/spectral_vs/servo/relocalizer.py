"""The relocalizer, a part of the servo that owns its state: the global registration of the
reference onto the view (:func:`spectral_vs.align_views`) when the servo has no trusted
estimate, its spacing and backoff (:class:`RelocalizationSchedule`), the arrival check
(:class:`ArrivalCheck`), and the hand-over to the recovery (:class:`Recovery`) when the
global registration cannot register the view (``ServoParams.relocalize``,
``recover_after``; docs/servoing.md)."""

from __future__ import annotations

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs._core import align_views as _align_views
from spectral_vs.servo.arrival import ArrivalCheck
from spectral_vs.servo.estimate import TrackedEstimate
from spectral_vs.servo.frames import Odometry
from spectral_vs.servo.records import ServoRecord
from spectral_vs.servo.recovery import Recovery
from spectral_vs.servo.reference import ServoReference
from spectral_vs.servo.schedule import RelocalizationSchedule


class Relocalizer:
    """The global registrations of a servo and what follows from them. It shares the
    servo's ``tracked`` estimate (it takes a global registration into it, or forgets it)
    and ``odometry`` (the camera's motion since the first step, and since the estimate)."""

    def __init__(
        self, reference: ServoReference, tracked: TrackedEstimate, odometry: Odometry
    ) -> None:
        params = reference.params
        self.params = params
        self.reference = reference
        self.tracked = tracked
        self.odometry = odometry
        self.schedule = RelocalizationSchedule(params)
        self.arrival = ArrivalCheck(params)
        self.recovery = Recovery.of(reference.view, params, reference.prepare)

    def reset(self) -> None:
        """A new run: no global registration tried, none refuted, no recovery."""
        self.forget()
        self.arrival.reset()

    def forget(self) -> None:
        """Forget the estimate and everything learnt about it: the watchdog's lock-on, the
        relocalizations tried and the recovery; the next step relocalizes."""
        self.tracked.forget()
        self.schedule.reset()
        self.recovery.reset()

    def recovering(self) -> bool:
        """Whether this step recovers (:meth:`Recovery.due`): no global registration was
        taken in this run and the last ``recover_after`` ones failed."""
        return self.recovery.due(self.tracked.ever_anchored)

    def due(self) -> bool:
        """Whether a relocalization may run now (:meth:`RelocalizationSchedule.due`)."""
        return self.schedule.due(self.recovering())

    def relocalize(self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray) -> None:
        """The global registration of the reference onto ``cloud`` (cropped, as captured),
        with the estimate carried along ``motion`` as its prior once one was taken: taken as
        the estimate when the verdict vouches for it with the support of
        ``relocalize_score`` (``recover_score`` while recovering)."""
        # The estimate carried so far, if a global registration was taken before (an
        # estimate of the local step alone far from the goal is no prior worth refining).
        # An estimate never confirmed since it was taken is no prior: kept over the search,
        # a wrong pose that tracked poorly was taken again at every relocalization.
        tracked = self.tracked
        trusted = tracked.anchored and self.schedule.confirmed and tracked.previous is not None
        prior = tracked.predicted(motion) if trusted else None
        self.schedule.tried()
        if not cloud.has_normals:  # an (N, 3) capture: the downsampled cloud's normals
            cloud = self.reference.prepare(cloud, "current")
        result = _align_views(self.reference.view, cloud, self.reference.view_params, prior)
        T, score = np.asarray(result.T_current_reference), float(result.support.score)
        record.relocalization_score = score
        record.relocalization_verdict = result.status
        record.relocalization_prior = prior is not None and result.hypothesis == -1
        # While recovering the view widens step by step: a marginal score in the middle
        # of it is worth waiting out (a 17-degree wrong pose scored 0.061 there).
        recovering = self.recovering()
        least = (
            self.params.recovery.recover_score
            if recovering
            else self.params.relocalization.relocalize_score
        )
        # Only the answer the verdict vouches for: never an alternative it did not judge,
        # nor a pose the arrival check refuted.
        if (
            not result.reliable
            or score < least
            or self.arrival.near_refuted(T, self.odometry.since_first)
        ):
            self.recovery.failed(recovering, record)
            return
        self.recovery.reset()
        record.relocalized = True
        tracked.take(T)
        self.odometry.accepted()

    def recover(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray
    ) -> np.ndarray | None:
        """A recovery step (:meth:`Recovery.step`): the pose to move toward, which widens
        the view's overlap with the reference, or None (the stop ``"lost"`` in ``record``,
        or nothing to do yet)."""
        return self.recovery.step(cloud, record, motion, self.odometry.since_first)

    def drop_above_the_scene(self, cloud: PointCloud, record: ServoRecord) -> PointCloud:
        """``cloud`` without what stands above the scene's plane (:meth:`Recovery.
        drop_above_the_scene`)."""
        return self.recovery.drop_above_the_scene(cloud, record, self.odometry.since_first)

    def check_arrival(self, T: np.ndarray, record: ServoRecord) -> None:
        """The arrival check (:class:`~spectral_vs.servo.arrival.ArrivalCheck`): an estimate
        ``T`` it refutes is forgotten, and the next step relocalizes."""
        if not self.params.relocalization.relocalize:
            return
        if self.arrival.refutes(T, record, self.odometry.since_first):
            self.forget()

    def unreliable_message(self, record: ServoRecord) -> str:
        """Why a step without an estimate holds: the last global registration's verdict."""
        if record.relocalization_verdict:
            return (
                f"the global registration is {record.relocalization_verdict} (support score "
                f"{record.relocalization_score:.3f}), not taken"
            )
        return "no reliable estimate yet; the next global registration is due later"
