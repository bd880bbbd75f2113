"""Model-to-scene alignment from Python: input conversion and defaults over the C++ aligner."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from spectral_vs._core import (
    AlignParams,
    AlignResult,
    PointCloud,
    _align,
    estimate_normals,
    voxel_downsample,
)

CloudLike = PointCloud | np.ndarray


def as_cloud(cloud: CloudLike, argument: str) -> PointCloud:
    """A :class:`PointCloud` from a cloud or an (N, 3) / (N, 6) array (points, normals).

    Parameters
    ----------
    cloud : PointCloud or ndarray
        Returned as is, or an (N, 3) array of points or (N, 6) array of points and
        normals, metres.
    argument : str
        Name of the argument, for the error message.

    Returns
    -------
    PointCloud

    Raises
    ------
    ValueError
        If the array has another shape or non-finite entries.
    """
    if isinstance(cloud, PointCloud):
        return cloud
    array = np.asarray(cloud)
    if array.ndim != 2 or array.shape[1] not in (3, 6):
        raise ValueError(
            f"{argument} must be a PointCloud or an (N, 3) / (N, 6) array, got shape {array.shape}"
        )
    if array.shape[1] == 6:
        return PointCloud(array[:, :3], array[:, 3:])
    return PointCloud(array)


def prepare(
    cloud: PointCloud, argument: str, voxel_size: float, downsample: bool, viewpoint: Any
) -> PointCloud:
    """Downsample to half a voxel (the EGI and the grid see no finer detail) and add normals.

    Parameters
    ----------
    cloud : PointCloud
        The model or the scene, metres.
    argument : str
        Name of the argument, for the error message.
    voxel_size : float
        Voxel edge of the alignment, metres: the cloud is downsampled to half of it and
        missing normals are fitted over a radius of twice it.
    downsample : bool
        Downsample first (otherwise only normals are added when missing).
    viewpoint : array_like, shape (3,)
        Sensor origin toward which estimated normals point, metres.

    Returns
    -------
    PointCloud
        A cloud with normals.
    """
    if len(cloud) == 0:
        raise ValueError(f"{argument} is empty: at least 1 finite point is needed")
    if downsample:
        cloud = voxel_downsample(cloud, voxel_size / 2)
    if not cloud.has_normals:
        cloud = estimate_normals(cloud, radius=2 * voxel_size, viewpoint=viewpoint)
    return cloud


def align(
    model: CloudLike,
    scene: CloudLike,
    params: AlignParams | None = None,
    *,
    downsample: bool = True,
    viewpoint: Any = (0.0, 0.0, 0.0),
    **overrides: Any,
) -> AlignResult:
    """Align ``model`` onto ``scene``: Algorithm 1 with, by default, a global rotation search.

    Parameters
    ----------
    model, scene : PointCloud or ndarray
        Clouds in metres, as :class:`PointCloud` or (N, 3) / (N, 6) arrays (points, normals).
        Missing normals are estimated (radius 2 x voxel_size, oriented toward ``viewpoint``,
        the sensor origin of a scan).
    params : AlignParams, optional
        Settings; defaults to ``AlignParams()``.
    downsample : bool
        Voxel-downsample both clouds to half the voxel size first (default True).
    viewpoint : array_like (3,)
        Sensor origin used to orient estimated normals, metres.
    **overrides
        Any :class:`AlignParams` field, e.g. ``voxel_size=0.005, global_search=False``.

    Returns
    -------
    AlignResult
        ``T_scene_model`` maps model coordinates into the scene; ``converged``,
        ``iterations``, ``fitness`` (share of model voxels next to scene points) and the
        per-iteration ``history`` of J_t, J_r and the gradients. Not converging within
        ``max_iterations`` gives ``converged = False``, not an exception.

    Raises
    ------
    ValueError
        For an empty cloud or an array of the wrong shape, an unknown setting in
        ``overrides``, or a setting out of its range (the message names it).
    """
    # A copy: overrides never change the caller's settings.
    settings = copy.copy(params) if params is not None else AlignParams()
    for name, value in overrides.items():
        if not hasattr(settings, name) or name.startswith("_"):
            raise ValueError(f"unknown alignment setting {name!r}")
        setattr(settings, name, value)
    model_cloud = prepare(
        as_cloud(model, "model"), "model", settings.voxel_size, downsample, viewpoint
    )
    scene_cloud = prepare(
        as_cloud(scene, "scene"), "scene", settings.voxel_size, downsample, viewpoint
    )
    return _align(model_cloud, scene_cloud, settings)
