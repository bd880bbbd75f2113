"""The reference's prepared sides, a part of the servo made once per reference: the cloud
as captured and downsampled, its centroid, the subsample the occluder test reads, and the
two registrations prepared on it (the full bound and the tracking bound), with the crop and
the downsampling every part applies to a current cloud the same way."""

from __future__ import annotations

import copy
import math

import numpy as np

from spectral_vs._core import ModelAligner, PointCloud, ViewAlignParams, voxel_downsample
from spectral_vs.registration import prepare
from spectral_vs.servo.scale import crop_to_depth
from spectral_vs.servo.settings import ServoParams

#: Reference points kept for the occluder test (a strided subsample of the reference as
#: captured): its bins (2.9 degrees) then hold about 10 points each at 160 x 120.
OCCLUSION_REFERENCE_POINTS = 5000


def check_points(reference: PointCloud, min_points: int) -> None:
    """Refuse a reference with fewer than ``min_points`` points (ValueError)."""
    if len(reference) < min_points:
        raise ValueError(
            f"reference has {len(reference)} points, fewer than min_points = {min_points}"
        )


class ServoReference:
    """The reference of a servo, prepared once (``params`` with its scale resolved; ``raw``
    the reference as given, camera frame, m).

    Attributes
    ----------
    cloud : PointCloud
        The reference cropped to ``max_depth``, downsampled, with normals: the model of
        every step's registration.
    view : PointCloud
        The reference as captured (cropped), with its normals when it had them: what the
        relocalization, the plane turn and the recovery read.
    centroid : ndarray, shape (3,)
        Centroid of ``cloud``, m.
    occlusion_points : ndarray, shape (M, 3)
        A strided subsample of the cropped reference (:data:`OCCLUSION_REFERENCE_POINTS`),
        for the occluder test and the field share.
    align_params, view_params
        The settings of the registration and of the relocalization's ``align_views``.
    aligner : ModelAligner
        The registration within ``max_translation``.
    tracking_aligner : ModelAligner or None
        The registration within ``tracking_translation`` (None when the servo never tracks).
    """

    def __init__(self, raw: PointCloud, params: ServoParams) -> None:
        self.params = params
        cloud = self.crop(raw)
        check_points(cloud, params.faults.min_points)
        self.align_params = params.align_params()
        self.view_params = ViewAlignParams(**params.relocalization.view_overrides)
        self.cloud = self.prepare(cloud, "reference")
        self.view = cloud if cloud.has_normals else self.cloud
        self.centroid = np.asarray(self.cloud.centroid())
        points = np.asarray(cloud.points)
        stride = max(1, math.ceil(len(points) / OCCLUSION_REFERENCE_POINTS))
        self.occlusion_points = np.array(points[::stride], dtype=float)
        # The reference's side of the registration (its EGI coefficients, centred points)
        # is prepared once here; each step adds only the current cloud's work.
        self.aligner = ModelAligner(self.cloud, self.align_params)
        self.tracking_aligner: ModelAligner | None = None
        if params.uses_tracking():
            tracking = copy.copy(self.align_params)
            tracking.max_translation = params.registration.tracking_translation
            tracking.local_icp = params.registration.tracking_icp
            self.tracking_aligner = ModelAligner(self.cloud, tracking)

    def crop(self, cloud: PointCloud) -> PointCloud:
        """The points within ``max_depth`` of the camera (along its optical axis)."""
        return crop_to_depth(cloud, self.params.registration.max_depth)

    def prepare(self, cloud: PointCloud, argument: str) -> PointCloud:
        """The cloud downsampled to ``downsample_size`` (resolved), with normals."""
        size = self.params.registration.downsample_size
        try:
            cloud = voxel_downsample(cloud, size) if len(cloud) else cloud
        except ValueError as error:
            raise ValueError(f"{argument}: downsampling to {size} m: {error}") from error
        return prepare(cloud, argument, self.params.registration.voxel_size, False, (0, 0, 0))
