"""Relocalization and recovery inside the controller's step: the global registration of the
reference onto the view (:func:`spectral_vs.align_views`) when the servo has no trusted
estimate, its spacing and backoff, and the recovery that widens the view's overlap with the
reference when the global registration cannot register it (``ServoParams.relocalize``,
``recover_after``; docs/servoing.md)."""

from __future__ import annotations

import math
import time

import numpy as np

from spectral_vs._core import PointCloud, field_share
from spectral_vs._core import align_views as _align_views
from spectral_vs.poses import pose_error
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.plane_turn import _turn_between, dominant_plane
from spectral_vs.servo.records import ServoRecord, ServoStatus
from spectral_vs.servo.state import ControllerState

#: The recovery widens its standoff up to this many times recover_standoff, and only once
#: the camera is within one recover_standoff and this angle of its target (rad): a view
#: far on the way there says nothing of the target's.
_MAX_STANDOFFS = 3
_ARRIVED_ROTATION = math.radians(10.0)
#: An occluder over this share of the points spoils a view for the widening: a hand or a box
#: in front of the camera is 25-40% of them, the Panda's own fingers in an extreme start's
#: view 2-4% (they stay, and must not stop the widening).
_SPOILING_SHARE = 0.1
#: The score of an estimate is its fitness over the share of the reference in the
#: field, but at least over this share (the extreme starts keep 30% in the field).
_MIN_FIELD_SHARE = 0.3


class Relocalization(ControllerState):
    """The relocalization and the recovery of :class:`~spectral_vs.servo.SpectralServo` (a
    base class of it: they read and keep the controller's state)."""

    def _reset_recovery(self) -> None:
        """Forget the recovery: the failed relocalizations in a row, its steps so far and
        where it started backing off from."""
        self._failed_relocalizations = 0
        self._widening_tries = 0  # of them, from the recovery's target, no occluder in view
        self._recovery_arrived = False  # the camera is at the recovery's target
        self._recovery_steps = 0
        self._scene_plane: tuple[np.ndarray, float, np.ndarray] | None = None
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
            # Only a view from the recovery's target, and one no occluder spoils, says
            # that the standoff is too small.
            spoiled = record.occluded_points > _SPOILING_SHARE * max(record.points, 1)
            if self._recovering() and self._recovery_arrived and not spoiled:
                self._widening_tries += 1
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
        self._clock.usable(now)  # the frame was usable: no sensor outage
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
        self._recovery_arrived = (
            record.translation_error < p.recovery.recover_standoff
            and record.rotation_error < _ARRIVED_ROTATION
        )
        record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _drop_above_the_scene(self, cloud: PointCloud, record: ServoRecord) -> PointCloud:
        """Before an estimate: ``cloud`` without the points nearer to the camera than the
        view's dominant plane is, and higher above it than any point of the reference above
        its own, by ``occlusion_margin`` (a hand, a box in front of the camera: nothing of
        the reference's scene), when both have a dominant plane; fills
        ``record.occluded_points``. No estimate is needed to place them."""
        if self._reference_height is None or not math.isfinite(self.params.faults.occlusion_margin):
            return cloud
        plane = self._scene_plane_now(cloud)
        if plane is None:
            return cloud
        normal, distance = plane
        points = np.asarray(cloud.points)
        height = points @ normal + distance  # 0 on the plane, d at the camera
        above = height > self._reference_height + self.params.faults.occlusion_margin
        # ... and nearer to the camera than the plane is: a tall thing far off (a wall, a
        # robot's base beside the table) is scenery, not something in front of the camera.
        above &= np.einsum("ij,ij->i", points, points) < distance**2
        record.occluded_points = int(above.sum())
        return cloud.select(~above) if record.occluded_points else cloud

    def _scene_plane_now(self, cloud: PointCloud) -> tuple[np.ndarray, float] | None:
        """The scene's dominant plane in the current camera frame: found once in a view
        (the nearest holding ``min_plane_share``), then carried along the camera's measured
        motion, since an occluder's face may itself be a plane nearer the camera."""
        if self._scene_plane is None:
            found = self._current_plane(cloud)
            if found is None:
                return None
            self._scene_plane = (*found, self._odometry.copy())
        normal, distance, T_first_seen = self._scene_plane
        # The plane n.p + d = 0 of the frame it was seen in, in the current frame.
        T_seen_current = _rigid_inverse(T_first_seen) @ self._odometry
        R, t = T_seen_current[:3, :3], T_seen_current[:3, 3]
        return R.T @ normal, float(distance + normal @ t)

    def _current_plane(self, cloud: PointCloud) -> tuple[np.ndarray, float] | None:
        """The dominant plane of the current view, the nearest of the parallel ones holding
        ``min_plane_share``, from every ``plane_turn_stride``-th point with its normal; None
        without one."""
        p = self.params
        source = cloud if cloud.has_normals else self._prepare(cloud, "current")
        stride = p.plane.plane_turn_stride
        return dominant_plane(
            np.asarray(source.points)[::stride],
            np.asarray(source.normals)[::stride],
            p.plane.plane_cone,
            p.plane.min_plane_share,
            nearest=True,
        )

    def _level_target(self, cloud: PointCloud) -> np.ndarray | None:
        """``T_current_target`` of the levelling recovery: the camera turned about its origin
        so that the reference's plane normal comes where the current view sees its plane's,
        at the reference's distance to the plane plus ``recover_standoff``; None when the
        reference or the current view has no dominant plane."""
        if self._reference_plane is None:
            return None
        current = self._scene_plane_now(cloud)
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
        of the recovery that were not reliable from its target with no occluder in view, up
        to :data:`_MAX_STANDOFFS` times it (a farther view sees more of the scene)."""
        p = self.params.recovery
        if p.recover_widen == 0:
            return p.recover_standoff
        tried = self._widening_tries
        return p.recover_standoff * min(1 + tried // p.recover_widen, _MAX_STANDOFFS)
