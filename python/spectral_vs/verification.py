"""How far a scene supports a model pose: inliers, their RMSE and the confidence of align()."""

from __future__ import annotations

from typing import Any

import numpy as np

from spectral_vs._core import CONFIDENCE_THRESHOLD, PoseVerification, _verify_pose
from spectral_vs.registration import CloudLike, as_cloud, check_viewpoint, prepare

__all__ = ["CONFIDENCE_THRESHOLD", "PoseVerification", "verify_pose"]


def verify_pose(
    model: CloudLike,
    scene: CloudLike,
    T_scene_model: Any,
    voxel_size: float = 0.008,
    scene_viewpoint: Any = None,
    downsample: bool = True,
    viewpoint: Any = (0.0, 0.0, 0.0),
) -> PoseVerification:
    """The scene's support of ``model`` at ``T_scene_model``: what ``align`` reports.

    With the clouds, voxel size and ``scene_viewpoint`` of an ``align`` call and its
    ``T_scene_model``, the figures are the result's ``confidence``, ``inliers`` and
    ``inlier_rmse``: the clouds are prepared as ``align`` prepares them.

    Parameters
    ----------
    model, scene : PointCloud or ndarray
        As for :func:`spectral_vs.align`, metres.
    T_scene_model : array_like, shape (4, 4)
        The pose to check: a rigid transform mapping model coordinates into the scene.
    voxel_size : float
        The alignment's voxel edge, metres: the inlier distance d is one voxel, the tight
        distance a quarter of one.
    scene_viewpoint : array_like (3,), optional
        The sensor origin of a single-view scene, metres: only the model points it would
        see are checked (facing it, in view, not behind a nearer scene surface). None for a
        scene seen from all sides.
    downsample, viewpoint
        As for :func:`spectral_vs.align` (half-voxel downsampling, the origin toward which
        estimated normals point).

    Returns
    -------
    PoseVerification
        ``inliers`` (model points within d of their nearest scene point), ``inlier_rmse``
        (metres, over the inliers), ``inlier_fraction``, ``visible``, ``tight``,
        ``seen_through`` and ``confidence`` = tight / visible * (1 - seen_through /
        visible); a pose with ``confidence > CONFIDENCE_THRESHOLD`` is taken as right.

    Raises
    ------
    ValueError
        For an empty cloud, a voxel size that is not finite and positive, a T that is not
        a rigid 4x4 transform or a viewpoint that is not 3 finite numbers.
    """
    orient = check_viewpoint(viewpoint)
    model_cloud = prepare(as_cloud(model, "model"), "model", voxel_size, downsample, orient)
    scene_cloud = prepare(as_cloud(scene, "scene"), "scene", voxel_size, downsample, orient)
    sensor = None if scene_viewpoint is None else check_viewpoint(scene_viewpoint)
    T = np.asarray(T_scene_model, dtype=float)
    return _verify_pose(model_cloud, scene_cloud, T, voxel_size, sensor)
