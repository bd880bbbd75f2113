"""The recovery, a part of the servo that owns its state: before the run's first estimate,
when global registrations keep failing, it moves the camera to widen the view's overlap
with the reference, in stages (a view that nearly registered turned in place onto the
reference's plane first; then levelled onto it at one, two, three standoffs; else backed
off along the optical axis), and it drops what stands in front of the scene
(``ServoParams.recovery``; docs/servoing.md, "Recovery from a view the registration cannot
register")."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.poses import pose_error
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.plane_turn import _turn_between, dominant_plane
from spectral_vs.servo.records import ServoRecord, ServoStatus
from spectral_vs.servo.settings import ServoParams

#: The recovery widens its standoff up to this many times recover_standoff, and takes its
#: next stage only once the camera is within one recover_standoff and this angle of its
#: target (rad): a view far on the way there says nothing of the target's.
_MAX_STANDOFFS = 3
#: The stages of the levelling recovery, in order: turned in place (no translation: the
#: camera's distance to the reference cannot grow), taken only when the first failed global
#: registration had the support of recover_score (the view nearly registered); then at
#: the reference's distance to the plane plus 1 to _MAX_STANDOFFS recover_standoff (a
#: wider view, bought with distance). A stage's number is its standoffs.
_TURN = 0
_ARRIVED_ROTATION = math.radians(10.0)
#: An occluder over this share of the points spoils a view for the widening: a hand or a box
#: in front of the camera is 25-40% of them, the Panda's own fingers in an extreme start's
#: view 2-4% (they stay, and must not stop the widening).
_SPOILING_SHARE = 0.1

Plane = tuple[np.ndarray, float]  #: (unit normal, distance d): n.p + d = 0


class Recovery:
    """The recovery's state (failed global registrations in a row, its steps, where it
    started backing off from, the scene's plane as first seen) and its moves.

    ``params`` is the servo's (read at each call); ``reference_plane`` the reference's
    dominant plane and ``reference_height`` how high its scene stands above it (m), both
    None without one; ``prepare`` downsamples a cloud with normals, for a view without."""

    def __init__(
        self,
        params: ServoParams,
        reference_plane: Plane | None,
        reference_height: float | None,
        prepare: Callable[[PointCloud, str], PointCloud],
    ) -> None:
        self.params = params
        self._reference_plane = reference_plane
        self._reference_height = reference_height
        self._prepare = prepare
        self.reset()

    @classmethod
    def of(
        cls,
        reference: PointCloud,
        params: ServoParams,
        prepare: Callable[[PointCloud, str], PointCloud],
    ) -> Recovery:
        """The recovery of ``reference`` (as captured, with normals): its dominant plane,
        the nearest holding ``min_plane_share``, and the height of its scene above it (the
        99.9th percentile: the tallest object)."""
        points, normals = np.asarray(reference.points), np.asarray(reference.normals)
        plane = dominant_plane(
            points, normals, params.plane.plane_cone, params.plane.min_plane_share, nearest=True
        )
        height = None
        if plane is not None:
            normal, distance = plane
            height = float(np.percentile(points @ normal + distance, 99.9))
        return cls(params, plane, height, prepare)

    def reset(self) -> None:
        """Forget the recovery: the failed relocalizations in a row, its steps so far and
        where it started backing off from."""
        self._failed = 0
        self._first_stage = 1  # _TURN when the first failed try nearly registered
        self._widening_tries = 0  # of them, from the recovery's target, no occluder in view
        self._arrived = False  # the camera is at the recovery's target
        self._steps = 0
        #: The scene's plane (normal, distance) in the frame first seen, and T_first_that.
        self._scene_plane: tuple[np.ndarray, float, np.ndarray] | None = None
        #: How far the camera stood from the reference's distance to the plane when the
        #: plane was first seen (the start: before an estimate the servo holds), m.
        self._start_offset: float | None = None
        self._T_motion_backoff: np.ndarray | None = None  # the motion at the back-off start

    def due(self, anchored: bool) -> bool:
        """Whether this step recovers (``ServoParams.recover_after``): no global registration
        was taken in this run (``anchored``: one was) and the last ``recover_after`` ones
        failed."""
        p = self.params
        # Only before the run's first estimate: once the servo has had one, the view
        # shared enough with the reference, and a lost estimate is held, not recovered
        # from by moving (docs/servoing.md, "What the servo does when it cannot see").
        return (
            p.relocalization.relocalize
            and p.recovery.recover_after > 0
            and not anchored
            and self._failed >= p.recovery.recover_after
        )

    def failed(self, recovering: bool, record: ServoRecord) -> None:
        """A global registration was not taken (``recovering``: during the recovery)."""
        if self._failed == 0:
            # A view whose registration had the support a recovery takes, but not the
            # verdict, is near: turning it in place moves the camera no farther away.
            nearly = record.relocalization_score >= self.params.recovery.recover_score
            self._first_stage = _TURN if nearly else 1
        self._failed += 1
        # Only a view from the recovery's target, and one no occluder spoils, says that
        # the standoff is too small.
        spoiled = record.occluded_points > _SPOILING_SHARE * max(record.points, 1)
        if recovering and self._arrived and not spoiled:
            self._widening_tries += 1

    def step(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray, odometry: np.ndarray
    ) -> np.ndarray | None:
        """One recovery step: ``T_current_target``, the pose that widens the view (level
        onto the plane, else back off), with the record's estimate, errors and
        ``recovery`` filled; None, with the stop ``"lost"`` in the record, once
        ``recover_steps`` were spent. ``motion`` is T_accepted_current, ``odometry``
        T_first_current."""
        p = self.params
        self._steps += 1
        if self._steps > p.recovery.recover_steps:
            record.status = ServoStatus(
                "stopped",
                "lost",
                f"no relocalization reached recover_score {p.recovery.recover_score:g} within "
                f"{p.recovery.recover_steps} recovery steps (last score "
                f"{record.relocalization_score:.3f})",
            )
            return None
        T = self._level_target(cloud, odometry)
        record.recovery = "turn" if self._stage() == _TURN else "level"
        if T is None:
            # No plane to level onto: back off along the optical axis from where the
            # recovery started, that pose carried along the camera's measured motion since.
            if self._T_motion_backoff is None:
                self._T_motion_backoff = motion.copy()
            T = np.eye(4)
            # The back-off has no turn: it starts at one standoff.
            T[2, 3] = -self.params.recovery.recover_standoff * self._stage_from(1)
            T = _rigid_inverse(motion) @ self._T_motion_backoff @ T
            record.recovery = "back_off"
        record.T_current_desired = T
        record.translation_error, record.rotation_error = pose_error(T)
        self._arrived = (
            record.translation_error < p.recovery.recover_standoff
            and record.rotation_error < _ARRIVED_ROTATION
        )
        return T

    def drop_above_the_scene(
        self, cloud: PointCloud, record: ServoRecord, odometry: np.ndarray
    ) -> PointCloud:
        """Before an estimate: ``cloud`` without the points nearer to the camera than the
        view's dominant plane is, and higher above it than any point of the reference above
        its own, by ``occlusion_margin`` (a hand, a box in front of the camera: nothing of
        the reference's scene), when both have a dominant plane; fills
        ``record.occluded_points``. No estimate is needed to place them."""
        margin = self.params.faults.occlusion_margin
        if self._reference_height is None or not math.isfinite(margin):
            return cloud
        plane = self._scene_plane_now(cloud, odometry)
        if plane is None:
            return cloud
        normal, distance = plane
        points = np.asarray(cloud.points)
        height = points @ normal + distance  # 0 on the plane, d at the camera
        above = height > self._reference_height + margin
        # ... and nearer to the camera than the plane is: a tall thing far off (a wall, a
        # robot's base beside the table) is scenery, not something in front of the camera.
        above &= np.einsum("ij,ij->i", points, points) < distance**2
        record.occluded_points = int(above.sum())
        return cloud.select(~above) if record.occluded_points else cloud

    def _scene_plane_now(self, cloud: PointCloud, odometry: np.ndarray) -> Plane | None:
        """The scene's dominant plane in the current camera frame: found once in a view
        (the nearest holding ``min_plane_share``), then carried along the camera's measured
        motion, since an occluder's face may itself be a plane nearer the camera."""
        if self._scene_plane is None:
            found = self._current_plane(cloud)
            if found is None:
                return None
            self._scene_plane = (*found, odometry.copy())
        normal, distance, T_first_seen = self._scene_plane
        # The plane n.p + d = 0 of the frame it was seen in, in the current frame.
        T_seen_current = _rigid_inverse(T_first_seen) @ odometry
        R, t = T_seen_current[:3, :3], T_seen_current[:3, 3]
        return R.T @ normal, float(distance + normal @ t)

    def _current_plane(self, cloud: PointCloud) -> Plane | None:
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

    def _level_target(self, cloud: PointCloud, odometry: np.ndarray) -> np.ndarray | None:
        """``T_current_target`` of the levelling recovery at its stage: the camera turned
        about its origin so that the reference's plane normal comes where the current view
        sees its plane's; after the turn in place also moved along that normal to the
        reference's distance to the plane plus the stage's standoffs, never more than
        ``recover_excursion`` beyond the start's offset from it. None when the
        reference or the current view has no dominant plane."""
        if self._reference_plane is None:
            return None
        current = self._scene_plane_now(cloud, odometry)
        if current is None:
            return None
        n_reference, d_reference = self._reference_plane
        n_current, d_current = current
        T = np.eye(4)
        T[:3, :3] = _turn_between(n_reference, n_current)
        if self._start_offset is None:
            self._start_offset = abs(d_current - d_reference)
        stage = self._stage()
        if stage > _TURN:
            p = self.params.recovery
            standoff = min(p.recover_standoff * stage, self._start_offset + p.recover_excursion)
            # The target origin t lies at n.t + d_current from the plane.
            T[:3, 3] = n_current * (d_reference + standoff - d_current)
        return T

    def _stage(self) -> int:
        """The levelling recovery's stage (its standoffs; :data:`_TURN` in place)."""
        return self._stage_from(self._first_stage)

    def _stage_from(self, first: int) -> int:
        """The stage of a recovery that began at ``first``: one further for every
        ``recover_widen`` global registrations of the recovery that were not reliable from
        its target with no occluder in view, up to :data:`_MAX_STANDOFFS`;
        ``recover_widen`` 0: one standoff throughout."""
        widen = self.params.recovery.recover_widen
        if widen == 0:
            return 1
        return min(first + self._widening_tries // widen, _MAX_STANDOFFS)
