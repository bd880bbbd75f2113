"""Relocalization and recovery inside the controller's step: the global registration of the
reference onto the view (:func:`spectral_vs.align_views`) when the servo has no trusted
estimate, its spacing and backoff, and the recovery that widens the view's overlap with the
reference when the global registration cannot register it (``ServoParams.relocalize``,
``recover_after``; docs/servoing.md)."""

from __future__ import annotations

import math
import time

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs._core import align_views as _align_views
from spectral_vs.poses import pose_error
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.plane_turn import _turn_between, dominant_plane
from spectral_vs.servo.records import ServoRecord, ServoStatus
from spectral_vs.servo.state import ControllerState

#: Current points that bound the view's field (a strided subsample), and the least depth
#: of a point in front of the camera, m (field_share).
_FIELD_POINTS = 4000
_FIELD_NEAR = 1e-3
#: The recovery widens its standoff up to this many times recover_standoff.
_MAX_STANDOFFS = 3
#: The confidence of an estimate is its fitness over the share of the reference in the
#: field, but at least over this share (the extreme starts keep 30% in the field).
_MIN_FIELD_SHARE = 0.3


def field_share(
    reference_points: np.ndarray,
    T_current_reference: np.ndarray,
    current_points: np.ndarray,
    max_depth: float = math.inf,
) -> float:
    """The share of ``reference_points`` that ``T_current_reference`` puts inside the
    current view's field: in front of the camera, nearer than ``max_depth`` and within the
    bounds of the current points' x/z and y/z (a pinhole camera's image rectangle, as far as
    the view has returns), in [0, 1]. Occlusion is ignored."""
    reference = np.asarray(reference_points, dtype=float)
    current = np.asarray(current_points, dtype=float)
    if len(reference) == 0 or len(current) == 0:
        return 0.0
    current = current[:: max(1, len(current) // _FIELD_POINTS)]
    current = current[current[:, 2] > _FIELD_NEAR]
    if len(current) == 0:
        return 0.0
    u = current[:, 0] / current[:, 2]
    v = current[:, 1] / current[:, 2]
    T = np.asarray(T_current_reference, dtype=float)
    moved = reference @ T[:3, :3].T + T[:3, 3]
    z = moved[:, 2]
    front = (z > _FIELD_NEAR) & (z <= max_depth)
    z = np.where(front, z, 1.0)
    mu, mv = moved[:, 0] / z, moved[:, 1] / z
    inside = front & (mu >= u.min()) & (mu <= u.max()) & (mv >= v.min()) & (mv <= v.max())
    return float(inside.mean())


class Relocalization(ControllerState):
    """The relocalization and the recovery of :class:`~spectral_vs.servo.SpectralServo` (a
    base class of it: they read and keep the controller's state)."""

    def _reset_recovery(self) -> None:
        """Forget the recovery: the failed relocalizations in a row, its steps so far and
        where it started backing off from."""
        self._failed_relocalizations = 0
        self._recovery_steps = 0
        self._T_motion_backoff: np.ndarray | None = None  # self._motion at the back-off start

    def _relocalization_due(self) -> bool:
        """Whether a relocalization may run now: none was tried yet, or the last was
        ``relocalize_interval`` steps ago (when it was not confirmed, ``relocalize_retry``
        grown by ``relocalize_backoff`` per unconfirmed one in a row before it; while
        recovering, ``relocalize_retry``: the recovery widens the view at every step)."""
        since = self._since_relocalization
        p = self.params
        if since is None:
            return True
        if self._confirmed:
            return since >= p.relocalization.relocalize_interval
        if self._recovering():
            return since >= p.recovery.recover_retry
        growth = p.relocalization.relocalize_backoff ** max(0, self._unconfirmed - 1)
        return since >= min(
            p.relocalization.relocalize_interval, p.relocalization.relocalize_retry * growth
        )

    def _confidence(self, T: np.ndarray, fitness: float, cloud: PointCloud) -> float:
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
        trusted = self._anchored and self._confirmed
        prior = None if self._previous is None or not trusted else self._predicted(motion)
        self._since_relocalization = 0
        self._confirmed = False
        self._unconfirmed += 1  # until the step confirms it
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
        if not result.reliable or score < least or self._near_refuted(T):
            self._failed_relocalizations += 1
            return
        self._reset_recovery()
        record.relocalized = True
        self._previous = T
        self._motion = np.eye(4)
        self._anchored = True
        self._ever_anchored = True
        self._lost = False

    def _near_refuted(self, T_current_desired: np.ndarray) -> bool:
        """Whether ``T_current_desired`` puts the goal within the watchdog's jump limits of
        a refuted estimate's (both placed by the camera's measured motion)."""
        T_first_desired = self._odometry @ T_current_desired
        limits = self.params.watchdog
        for refuted in self._refuted:
            moved, turned = pose_error(_rigid_inverse(refuted) @ T_first_desired)
            if moved <= limits.jump_limit_translation and turned <= limits.jump_limit_rotation:
                return True
        return False

    def _check_arrival(self, T: np.ndarray, record: ServoRecord) -> None:
        """The arrival check (``ServoParams.refute_fitness``): an estimate ``T`` near the goal
        whose fitness stays under ``refute_fitness`` for ``refute_steps`` steps is refuted:
        remembered, forgotten as the estimate, and the next step relocalizes."""
        p = self.params
        if not p.relocalization.relocalize:
            return
        at_goal = (
            record.translation_error <= p.relocalization.refute_translation
            and record.rotation_error <= p.relocalization.refute_rotation
        )
        poor = at_goal and record.visible_fitness < p.relocalization.refute_fitness
        self._poor_arrivals = self._poor_arrivals + 1 if poor else 0
        if self._poor_arrivals < p.relocalization.refute_steps:
            return
        record.refuted = True
        self._refuted.append(self._odometry @ T)
        self._poor_arrivals = 0
        self._forget_estimate()

    def _forget_estimate(self) -> None:
        """Forget the estimate and everything learnt about it: the watchdog's lock-on, the
        relocalizations tried and the recovery; the next step relocalizes."""
        self._previous = None
        self._armed = False
        self._anchored = False
        self._lost = True
        self._since_relocalization = None
        self._confirmed = False
        self._unconfirmed = 0
        self._reset_recovery()

    def _recovering(self) -> bool:
        """Whether this step recovers (``ServoParams.recover_after``): no global registration
        was taken yet in this run and the last ``recover_after`` ones were not taken."""
        p = self.params
        # Only before the run's first estimate: once the servo has had one, the view
        # shared enough with the reference, and a lost estimate is held, not recovered
        # from by moving (docs/servoing.md, "What the servo does when it cannot see").
        return (
            p.relocalization.relocalize
            and p.recovery.recover_after > 0
            and not self._anchored
            and not self._ever_anchored
            and self._failed_relocalizations >= p.recovery.recover_after
        )

    def _recover(
        self,
        cloud: PointCloud,
        record: ServoRecord,
        motion: np.ndarray,
        now: float,
        start: float,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """A recovery step: the twist toward the pose that widens the view's overlap with
        the reference (level onto its plane, else back off), or the stop ``"lost"`` once
        ``recover_steps`` were spent; no registration runs."""
        p = self.params
        self._recovery_steps += 1
        self._outage_start = now  # the frame was usable: no sensor outage
        if self._recovery_steps > p.recovery.recover_steps:
            record.status = ServoStatus(
                "stopped",
                "lost",
                f"no relocalization reached recover_score {p.recovery.recover_score:g} within "
                f"{p.recovery.recover_steps} recovery steps (last score "
                f"{record.relocalization_score:.3f})",
            )
            record.seconds = time.perf_counter() - start
            return record.twist, record.status, record
        T = self._level_target(cloud)
        record.recovery = "level"
        if T is None:
            # No plane to level onto: back off along the optical axis from where the
            # recovery started, that pose carried along the camera's measured motion since.
            if self._T_motion_backoff is None:
                self._T_motion_backoff = motion.copy()
            T = np.eye(4)
            T[2, 3] = -self._standoff()
            T = _rigid_inverse(motion) @ self._T_motion_backoff @ T
            record.recovery = "back_off"
        record.T_current_desired = T
        record.translation_error, record.rotation_error = pose_error(T)
        record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _level_target(self, cloud: PointCloud) -> np.ndarray | None:
        """``T_current_target`` of the levelling recovery: the camera turned about its origin
        so that the reference's plane normal comes where the current view sees its plane's,
        at the reference's distance to the plane plus ``recover_standoff``; None when the
        reference or the current view has no dominant plane."""
        if self._reference_plane is None:
            return None
        p = self.params
        source = cloud if cloud.has_normals else self._prepare(cloud, "current")
        stride = p.plane.plane_turn_stride
        current = dominant_plane(
            np.asarray(source.points)[::stride],
            np.asarray(source.normals)[::stride],
            p.plane.plane_cone,
            p.plane.min_plane_share,
            nearest=True,
        )
        if current is None:
            return None
        n_reference, d_reference = self._reference_plane
        n_current, d_current = current
        T = np.eye(4)
        T[:3, :3] = _turn_between(n_reference, n_current)
        # The target origin t lies at n.t + d_current from the plane.
        T[:3, 3] = n_current * (d_reference + self._standoff() - d_current)
        return T

    def _standoff(self) -> float:
        """How much farther from the scene than the reference the recovery takes the camera,
        m: ``recover_standoff``, once more for every ``recover_widen`` global registrations
        of the recovery that were not reliable, up to :data:`_MAX_STANDOFFS` times it (a
        farther view sees more of the scene)."""
        p = self.params.recovery
        if p.recover_widen == 0:
            return p.recover_standoff
        tried = max(0, self._failed_relocalizations - p.recover_after)
        return p.recover_standoff * min(1 + tried // p.recover_widen, _MAX_STANDOFFS)
