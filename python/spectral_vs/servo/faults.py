"""Sensor faults inside the controller's step: a frame already seen (stale), too few
points, an occluder in front of the camera; and the hold that rides them, up to
``ServoParams.max_outage`` (:data:`~spectral_vs.servo.HOLDS`). The tests themselves are free
functions of :mod:`spectral_vs.sensor_faults`."""

from __future__ import annotations

import math
import time

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.sensor_faults import near_occluders
from spectral_vs.servo.records import ServoRecord, ServoStatus
from spectral_vs.servo.state import ControllerState

#: Reference points kept for the occluder test (a strided subsample of the reference as
#: captured): its bins (2.9 degrees) then hold about 10 points each at 160 x 120.
_OCCLUSION_REFERENCE_POINTS = 5000


def _motion_step(T_previous_current: np.ndarray) -> np.ndarray:
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


class SensorFaults(ControllerState):
    """The fault tests of :class:`~spectral_vs.servo.SpectralServo` (a base class of it:
    the tests read and keep the controller's state)."""

    def _frame_fault(
        self, raw: PointCloud, points: int, stamp: float | None
    ) -> tuple[str, str] | None:
        """``(hold, message)`` when the frame cannot be used (too few of its ``points``
        within ``max_depth``, or a stale frame), else None."""
        p = self.params
        if points == 0 or points < p.faults.min_points:
            hold = "empty_cloud" if points == 0 else "too_few_points"
            return hold, f"the current cloud has {points} points (min_points {p.faults.min_points})"
        stale = self._stale_frames.check(raw, stamp)
        return None if stale is None else ("stale_frame", stale)

    def _drop_occluders(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray
    ) -> tuple[PointCloud, bool, float, str | None]:
        """A hand in front of the camera: ``cloud`` without the surfaces nearer than the
        reference could be, whether they are an occluder (``occlusion_min_share`` of the
        points, hiding that share of the reference at least), the
        share of the reference they hide, and a message when too few points remain (the
        step holds). Runs once locked on; fills ``record.occluded_points`` and
        ``record.hidden_share``."""
        p = self.params
        # From the first occluded frame on, once the servo has an estimate it vouches for:
        # a relocalization taken, or the lock-on.
        trusted = self._tracked.locked
        if not (
            trusted
            and self._tracked.previous is not None
            and math.isfinite(p.faults.occlusion_margin)
        ):
            return cloud, False, 0.0, None
        points = len(cloud)
        mask, hidden = near_occluders(
            np.asarray(cloud.points),
            self._occlusion_reference,
            self._tracked.predicted(motion),
            p.faults.occlusion_margin,
        )
        record.occluded_points = int(mask.sum())
        record.hidden_share = hidden
        if not record.occluded_points:
            return cloud, False, hidden, None
        cloud = cloud.select(~mask)
        # Near surfaces on none of the reference's rays (a far-off estimate sees the near
        # table as nearer than the reference) hide nothing to register: dropped, no hold.
        share = p.faults.occlusion_min_share
        occluded = record.occluded_points >= share * points and hidden >= share
        message = self._too_few_left(cloud, record, "occluding ones")
        if message is not None:
            return cloud, occluded, hidden, message
        if hidden > p.faults.occlusion_max_share:
            # Most of the reference is behind the occluder: an outage, not a new scene to
            # register (or relocalize) the little left in view onto.
            message = (
                f"an occluder hides {100 * hidden:.0f}% of the reference "
                f"(occlusion_max_share {p.faults.occlusion_max_share:g})"
            )
            return cloud, occluded, hidden, message
        return cloud, occluded, hidden, None

    def _too_few_left(self, cloud: PointCloud, record: ServoRecord, dropped: str) -> str | None:
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

    def _reset_faults(self) -> None:
        """Forget what the fault tests remember: the camera's motion since the last accepted
        step (and since the first, the arrival check's odometry), the last frame and stamp,
        and the clock's last step and usable frame."""
        self._odometry.reset()
        self._stale_frames.reset()
        self._clock.reset()

    def _carry(self, T_previous_current: np.ndarray | None) -> np.ndarray:
        """Add the camera's motion since the previous step (identity when not given) to the
        motion since the last accepted step, since the first step and since the last frame
        came first; return the first (``T_accepted_current``)."""
        if T_previous_current is not None:
            step = _motion_step(T_previous_current)
            self._odometry.carry(step)
            self._stale_frames.moved(step)
        return self._odometry.since_accepted

    def _hold(
        self,
        record: ServoRecord,
        hold: str,
        message: str,
        now: float,
        start: float,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """Finish ``record`` as a held step (zero twist, nothing remembered), or stop with
        ``"sensor_outage"`` when the holds have lasted longer than ``max_outage``."""
        self._clock.hold(record, hold, message, now, self.params.faults.max_outage)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record
