"""How far a scene supports a model pose: inliers, their RMSE and the confidence of align()."""

from __future__ import annotations

from typing import Any

import numpy as np

from spectral_vs._core import (
    CONFIDENCE_THRESHOLD,
    AlignParams,
    PoseVerification,
    _verify_pose,
    detect_single_view,
)
from spectral_vs.registration import (
    CloudLike,
    as_cloud,
    check_viewpoint,
    check_voxel_size,
    derived_voxel_size,
    prepare,
)

__all__ = ["CONFIDENCE_THRESHOLD", "PoseVerification", "verify_pose"]


def verify_pose(
    model: CloudLike,
    scene: CloudLike,
    T_scene_model: Any,
    voxel_size: float = 0.0,
    *,
    sensor_origin: Any = (0.0, 0.0, 0.0),
    scene_view: str = "auto",
    downsample: bool = True,
) -> PoseVerification:
    """The scene's support of ``model`` at ``T_scene_model``: what ``align`` reports.

    With the clouds and the settings ``voxel_size``, ``sensor_origin`` and ``scene_view``
    of an ``align`` call and its ``T_scene_model``, the figures are the result's
    ``confidence``, ``inliers`` and ``inlier_rmse``: the clouds are prepared as ``align``
    prepares them and the scene is taken as a single view when ``align`` takes it as one.

    Parameters
    ----------
    model, scene : PointCloud or ndarray
        As for :func:`spectral_vs.align`, metres.
    T_scene_model : array_like, shape (4, 4)
        The pose to check: a rigid transform mapping model coordinates into the scene.
    voxel_size : float
        The alignment's voxel edge, metres: the inlier distance d is one voxel, the tight
        distance half of one. 0 (default): derived from the clouds as ``align``
        derives it (:func:`alignment_voxel_size`).
    sensor_origin : array_like (3,)
        The scene's sensor, metres: estimated normals point toward it, and in a single
        view only the model points it would see are checked (facing it, in view, not
        behind a nearer scene surface).
    scene_view : str
        'auto' (default: a single view when :func:`detect_single_view` finds one),
        'single_view' or 'all_sides', as for ``AlignParams.scene_view``.
    downsample : bool
        As for :func:`spectral_vs.align` (half-voxel downsampling).

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
        For an empty cloud, a voxel size that is not finite and >= 0, a T that is not a
        rigid 4x4 transform, a sensor_origin that is not 3 finite numbers or an unknown
        scene_view.
    """
    if scene_view not in _SCENE_VIEWS:
        raise ValueError(f"scene_view must be one of {_SCENE_VIEWS}, got {scene_view!r}")
    origin = check_viewpoint(sensor_origin, "sensor_origin")
    if voxel_size != 0:
        check_voxel_size(voxel_size)
    settings = derived_voxel_size(
        AlignParams(voxel_size=voxel_size),
        as_cloud(model, "model"),
        as_cloud(scene, "scene"),
    )
    voxel = settings.voxel_size
    model_cloud = prepare(as_cloud(model, "model"), "model", voxel, downsample, origin)
    scene_cloud = prepare(as_cloud(scene, "scene"), "scene", voxel, downsample, origin)
    single = scene_view == "single_view" or (
        scene_view == "auto" and detect_single_view(scene_cloud, origin, voxel).single_view
    )
    T = np.asarray(T_scene_model, dtype=float)
    return _verify_pose(model_cloud, scene_cloud, T, voxel, origin if single else None)


_SCENE_VIEWS = ("auto", "single_view", "all_sides")
