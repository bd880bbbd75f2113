"""The tracker, a part of the servo that owns its state: each step's registration of the
reference onto the frame, within the tracking bound while locked on or the full bound
otherwise, turned about the reference's dominant plane, carried along the odometry where
it fits poorly, with its score and calibrated confidence; and the watchdog's test of the
estimate against the last one (``ServoParams.registration``, ``plane``, ``watchdog``)."""

from __future__ import annotations

import math

import numpy as np

from spectral_vs._core import AlignResult, ModelAligner, PointCloud, step_score
from spectral_vs.poses import pose_error
from spectral_vs.servo.estimate import TrackedEstimate
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.plane_turn import _PlaneTurn
from spectral_vs.servo.records import ServoRecord
from spectral_vs.servo.reference import ServoReference


class Tracker:
    """The registration of each step. It reads the servo's ``tracked`` estimate (the
    guess, the lock-on) and keeps the last plane turn."""

    def __init__(self, reference: ServoReference, tracked: TrackedEstimate) -> None:
        params = reference.params
        self.params = params
        self.reference = reference
        self.tracked = tracked
        self.plane_turn: _PlaneTurn | None = (
            _PlaneTurn.of(reference.view, reference.centroid, params, reference.align_params)
            if params.plane.plane_turn
            else None
        )
        self.reset()

    def reset(self) -> None:
        """A new run: no plane turn yet."""
        self.last_turn = 0.0  #: the plane turn of the last estimate, rad

    def register(
        self, cloud: PointCloud, initial_guess: np.ndarray | None, aligner: ModelAligner
    ) -> tuple[PointCloud, AlignResult]:
        """The downsampled ``cloud`` and the registration of the reference onto it, without
        the plane turn (a step turns only the estimate it keeps)."""
        scene = self.reference.prepare(cloud, "current")
        return scene, aligner.align(scene, initial_guess)

    def turned(self, cloud: PointCloud, scene: PointCloud, T: np.ndarray) -> np.ndarray:
        """``T`` turned about the reference's dominant normal (``ServoParams.plane_turn``),
        from the normals of ``cloud`` (those of its downsampled ``scene`` without)."""
        self.last_turn = 0.0
        if self.plane_turn is not None:
            self.last_turn = self.plane_turn.turn(cloud if cloud.has_normals else scene, T)
            T = self.plane_turn.turned(T, self.last_turn)
        return T

    def measure(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray, hidden: float
    ) -> np.ndarray:
        """The step's estimate ``T_current_desired``: the registration turned about the
        plane, or the last estimate carried along the camera's ``motion`` where the fit is
        poor; fills the record's estimate, errors, fitness (also over the rest of the
        ``hidden`` share), score, confidence and Algorithm 1's figures."""
        p = self.params
        guess = None
        if (
            p.registration.warm_start or self.tracked.anchored
        ) and self.tracked.previous is not None:
            guess = self.tracked.predicted(motion)
        scene, result = self._registration(cloud, record, guess, motion, hidden)
        record.fitness = float(result.fitness)
        # An occluder lowers the fitness by the share of the reference it hides: every
        # test below reads the fitness over the rest.
        record.visible_fitness = visible_fitness(record.fitness, hidden)
        # Where the registration fits poorly the views share too little for Algorithm 1's
        # step: the EGI correlation of two partial views peaks 10-20 degrees off the truth,
        # and far from the goal the phase correlation's shift leaps by tens of mm from step
        # to step. The last good estimate carried along the camera's measured motion is the
        # estimate while the fitness is under watchdog_fitness, before lock-on and after.
        record.carried = (
            self.tracked.anchored
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
            T = self.turned(cloud, scene, T)
        else:
            self.last_turn = 0.0
        # The score and the confidence are of the estimate the step keeps: a carried one did
        # not take the registration, and is calibrated apart (spectral_vs.step_score).
        record.score, record.confidence = step_score(
            record.visible_fitness,
            record.carried,
            self.reference.occlusion_points,
            T,
            cloud.points,
            p.relocalization.relocalize_fitness,
            max_depth=p.registration.max_depth,
        )
        if record.carried:
            assert guess is not None
            T = guess
            self.last_turn = 0.0
        record.T_current_desired = T
        record.translation_error, record.rotation_error = pose_error(T)
        record.plane_turn = 0.0 if record.carried else self.last_turn
        _record_iterations(record, result)
        return T

    def jump(self, T: np.ndarray, motion: np.ndarray | None) -> str | None:
        """The watchdog: a message when ``T`` is implausibly far from the previous estimate
        carried along ``motion`` (as for :meth:`TrackedEstimate.predicted`), else None."""
        if self.tracked.previous is None or not self.tracked.armed:
            return None
        predicted = self.tracked.predicted(motion)
        # |translation| of predicted^-1 T is |t - t_predicted|: the two parts are independent.
        moved, turned = pose_error(_rigid_inverse(predicted) @ T)
        w = self.params.watchdog
        if moved > w.jump_limit_translation or turned > w.jump_limit_rotation:
            return (
                f"the estimate changed by {1000 * moved:.1f} mm and {math.degrees(turned):.2f} "
                f"deg in one step (limits {1000 * w.jump_limit_translation:.1f} mm, "
                f"{math.degrees(w.jump_limit_rotation):.2f} deg)"
            )
        return None

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
            assert self.reference.tracking_aligner is not None
            scene, result = self.register(cloud, guess, self.reference.tracking_aligner)
            # Once locked on, a poor fit may mean the answer lies beyond the tracking bound
            # (the camera or the scene jumped): the full search decides, and the watchdog
            # sees the jump. Before, a poor fit is the relocalization's to judge.
            visible = visible_fitness(result.fitness, hidden)
            tracking = not self.tracked.armed or visible >= self.params.watchdog.watchdog_fitness
        if not tracking:
            scene, result = self.register(cloud, guess, self.reference.aligner)
        record.tracking = tracking
        return scene, result

    def _can_track(self, guess: np.ndarray | None, motion: np.ndarray | None) -> bool:
        """Whether this registration may seek only ``tracking_translation``: locked on (the
        watchdog armed, or a relocalization taken), and the predicted estimate moves the
        reference's centroid by at most half of it from the registration's start ``guess``
        (identity when None); ``motion`` as for :meth:`TrackedEstimate.predicted`."""
        tracked = self.tracked
        if self.reference.tracking_aligner is None or not tracked.locked:
            return False
        if tracked.previous is None:
            return False
        predicted = tracked.predicted(motion)
        start = np.eye(4) if guess is None else np.asarray(guess, dtype=float)
        c = self.reference.centroid
        moved = predicted[:3, :3] @ c + predicted[:3, 3] - (start[:3, :3] @ c + start[:3, 3])
        return bool(np.abs(moved).max() <= 0.5 * self.params.registration.tracking_translation)


def visible_fitness(fitness: float, hidden: float) -> float:
    """The fitness over the part of the reference no occluder hides (``hidden`` is the
    hidden share): an occluder lowers the fitness by the share it hides. At most 1."""
    return min(1.0, fitness / max(1.0 - hidden, 1e-9))


def _record_iterations(record: ServoRecord, result: AlignResult) -> None:
    """Algorithm 1's figures of ``result`` into ``record``: its iterations and the costs and
    steps of its last one."""
    record.iterations = int(result.iterations)
    if len(result.history):
        last = result.history[-1]
        record.translation_cost = float(last.translation_cost)
        record.rotation_cost = float(last.rotation_cost)
        record.translation_step = float(last.translation_step)
        record.rotation_gradient = float(last.rotation_gradient)
