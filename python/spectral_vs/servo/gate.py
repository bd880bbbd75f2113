"""The frame gate, a part of the servo that owns its state: what a frame must pass before
it is registered (enough points within ``max_depth``, not a frame already seen, no occluder
over most of the reference), the occluders it drops, and the holds that ride the faults up
to ``ServoParams.max_outage`` (:data:`~spectral_vs.servo.HOLDS`). The tests themselves are
free functions of :mod:`spectral_vs.sensor_faults`."""

from __future__ import annotations

import math

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.sensor_faults import near_occluders
from spectral_vs.servo.frames import StaleFrames, StepClock
from spectral_vs.servo.records import ServoRecord
from spectral_vs.servo.settings import ServoParams


def checked_motion(T_previous_current: np.ndarray) -> np.ndarray:
    """``T_previous_current`` checked: a finite rigid 4 x 4 transform (ValueError naming it)."""
    T = np.asarray(T_previous_current, dtype=float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(
            f"T_previous_current must be a finite 4x4 transform (the camera's motion since "
            f"the last step), got shape {T.shape}{'' if T.shape != (4, 4) else ' with NaN/inf'}"
        )
    R = T[:3, :3]
    rigid = np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0
    if not rigid or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
        raise ValueError(
            "T_previous_current must be a rigid transform ([R t; 0 0 0 1], R a rotation)"
        )
    return T


class FrameGate:
    """The faults of a frame and the holds on them: the step clock and the outage
    (:class:`StepClock`), the last frame (:class:`StaleFrames`), the occluders in front of
    the reference (``occlusion_points``, the reference's subsample, camera frame, m)."""

    def __init__(self, params: ServoParams, occlusion_points: np.ndarray) -> None:
        self.params = params
        self.occlusion_points = occlusion_points
        self.clock = StepClock()
        self.stale_frames = StaleFrames()

    def reset(self) -> None:
        """A new run: no step, no usable frame, no last frame."""
        self.stale_frames.reset()
        self.clock.reset()

    def fault(self, raw: PointCloud, points: int, stamp: float | None) -> tuple[str, str] | None:
        """``(hold, message)`` when the frame cannot be used (too few of its ``points``
        within ``max_depth``, or a stale frame), else None."""
        least = self.params.faults.min_points
        if points == 0 or points < least:
            hold = "empty_cloud" if points == 0 else "too_few_points"
            return hold, f"the current cloud has {points} points (min_points {least})"
        stale = self.stale_frames.check(raw, stamp)
        return None if stale is None else ("stale_frame", stale)

    def drop_occluders(
        self, cloud: PointCloud, record: ServoRecord, predicted: np.ndarray | None
    ) -> tuple[PointCloud, bool, float, str | None]:
        """A hand in front of the camera: ``cloud`` without the surfaces nearer than the
        reference could be at the ``predicted`` estimate (None: no estimate the servo
        vouches for, and no test), whether they are an occluder (``occlusion_min_share`` of
        the points, hiding that share of the reference at least), the share of the
        reference they hide, and a message when the step must hold (too few points left,
        or most of the reference hidden). Fills ``record.occluded_points`` and
        ``record.hidden_share``."""
        faults = self.params.faults
        if predicted is None or not math.isfinite(faults.occlusion_margin):
            return cloud, False, 0.0, None
        points = len(cloud)
        mask, hidden = near_occluders(
            np.asarray(cloud.points), self.occlusion_points, predicted, faults.occlusion_margin
        )
        record.occluded_points = int(mask.sum())
        record.hidden_share = hidden
        if not record.occluded_points:
            return cloud, False, hidden, None
        cloud = cloud.select(~mask)
        # Near surfaces on none of the reference's rays (a far-off estimate sees the near
        # table as nearer than the reference) hide nothing to register: dropped, no hold.
        share = faults.occlusion_min_share
        occluded = record.occluded_points >= share * points and hidden >= share
        message = self.too_few_left(cloud, record, "occluding ones")
        if message is None and hidden > faults.occlusion_max_share:
            # Most of the reference is behind the occluder: an outage, not a new scene to
            # register (or relocalize) the little left in view onto.
            message = (
                f"an occluder hides {100 * hidden:.0f}% of the reference "
                f"(occlusion_max_share {faults.occlusion_max_share:g})"
            )
        return cloud, occluded, hidden, message

    def too_few_left(self, cloud: PointCloud, record: ServoRecord, dropped: str) -> str | None:
        """Why the step holds when fewer than ``min_points`` of ``cloud`` remain once the
        ``record.occluded_points`` points (what they are: ``dropped``) were dropped, else
        None."""
        least = self.params.faults.min_points
        if len(cloud) >= least:
            return None
        return (
            f"{len(cloud)} points remain without {record.occluded_points} {dropped} "
            f"(min_points {least})"
        )

    def hold(self, record: ServoRecord, hold: str, message: str, now: float) -> None:
        """Finish ``record`` as a held step (zero twist, nothing remembered), or as the stop
        ``"sensor_outage"`` when the holds have lasted longer than ``max_outage``."""
        self.clock.hold(record, hold, message, now, self.params.faults.max_outage)
