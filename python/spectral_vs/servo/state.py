"""What the parts of the controller share: its settings, the reference's prepared sides,
the state it keeps between steps, and the helpers every part uses (the crop to
``max_depth``, the downsampling, the prediction of the estimate, the control law)."""

from __future__ import annotations

import numpy as np

from spectral_vs._core import ModelAligner, PointCloud, ViewAlignParams, voxel_downsample
from spectral_vs.poses import _pose, rotation_vector
from spectral_vs.registration import prepare
from spectral_vs.servo.arrival import ArrivalCheck
from spectral_vs.servo.estimate import TrackedEstimate
from spectral_vs.servo.frames import Odometry, StaleFrames, StepClock
from spectral_vs.servo.law import _saturated_twist
from spectral_vs.servo.recovery import Recovery
from spectral_vs.servo.scale import ServoScale, crop_to_depth
from spectral_vs.servo.schedule import RelocalizationSchedule
from spectral_vs.servo.settings import ServoParams


class ControllerState:
    """The base of :class:`~spectral_vs.servo.SpectralServo` and of the two files its step
    is split over (:class:`~spectral_vs.servo.faults.SensorFaults`,
    :class:`~spectral_vs.servo.relocalization.Relocalization`): the reference's prepared
    sides, and the parts that own what the servo remembers between steps (each with its
    own state and methods: the clock, the odometry, the last frame, the estimate held, the
    recovery, the arrival check, the relocalizations' schedule, and in the controller the
    stop rule). Only the step count and the last plane turn are kept here."""

    params: ServoParams  #: the settings with every scale length resolved
    scale: ServoScale  #: the scale lengths resolved, and the reference's extent
    reference: PointCloud  #: the reference, downsampled, with normals
    _reference_view: PointCloud  #: the reference as captured (cropped), for relocalization
    _view_params: ViewAlignParams
    _aligner: ModelAligner
    _tracking_aligner: ModelAligner | None
    _centroid: np.ndarray
    _occlusion_reference: np.ndarray  #: a strided subsample of the reference's points
    _clock: StepClock  #: the steps' times and the outage
    _stale_frames: StaleFrames  #: the last frame, for the stale-frame test
    _odometry: Odometry  #: the camera's measured motion
    _tracked: TrackedEstimate  #: the estimate held and the trust in it
    _recovery: Recovery  #: the recovery, before the run's first estimate
    _arrival: ArrivalCheck  #: the estimates refuted on arrival
    _schedule: RelocalizationSchedule  #: when the next global registration may run

    # What the controller remembers between steps (set by reset()).
    _steps: int
    _last_turn: float  #: the plane turn of the last estimate, rad

    def _crop(self, cloud: PointCloud) -> PointCloud:
        """The points within ``max_depth`` of the camera (along its optical axis)."""
        return crop_to_depth(cloud, self.params.registration.max_depth)

    def _prepare(self, cloud: PointCloud, argument: str) -> PointCloud:
        """The cloud downsampled to ``downsample_size`` (resolved), with normals."""
        size = self.params.registration.downsample_size
        try:
            cloud = voxel_downsample(cloud, size) if len(cloud) else cloud
        except ValueError as error:
            raise ValueError(f"{argument}: downsampling to {size} m: {error}") from error
        return prepare(cloud, argument, self.params.registration.voxel_size, False, (0, 0, 0))

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
