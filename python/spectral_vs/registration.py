"""Model-to-scene alignment from Python: input conversion and defaults over the C++ aligner."""

from __future__ import annotations

import copy
import math
import numbers
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
from spectral_vs.interop import from_open3d, is_open3d_cloud

CloudLike = PointCloud | np.ndarray


def as_cloud(cloud: CloudLike, argument: str) -> PointCloud:
    """A :class:`PointCloud` from a cloud, an Open3D cloud or an (N, 3) / (N, 6) array
    (points, normals).

    Parameters
    ----------
    cloud : PointCloud, open3d.geometry.PointCloud or ndarray
        Returned as is; an Open3D cloud's points and normals (:func:`spectral_vs.from_open3d`,
        non-finite points dropped); or an (N, 3) array of points or (N, 6) array of points
        and normals, metres.
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
    if is_open3d_cloud(cloud):
        return from_open3d(cloud)
    array = np.asarray(cloud)
    if array.ndim != 2 or array.shape[1] not in (3, 6):
        raise ValueError(
            f"{argument} must be a PointCloud or an (N, 3) / (N, 6) array (or an "
            f"open3d.geometry.PointCloud), got shape {array.shape}"
        )
    if array.shape[1] == 6:
        return PointCloud(array[:, :3], array[:, 3:])
    return PointCloud(array)


def with_overrides(params: Any, kind: type, overrides: dict[str, Any], what: str) -> Any:
    """A copy of ``params`` (a ``kind``, or ``kind()`` for None) with the fields of
    ``overrides`` set: the caller's settings never change.

    Raises
    ------
    TypeError
        For ``params`` of another type, or a value of the wrong type.
    ValueError
        For a field that ``kind`` does not have (named as ``what``).
    """
    if params is not None and not isinstance(params, kind):
        raise TypeError(f"params must be of type {kind.__name__}, got {type(params).__name__}")
    settings = copy.copy(params) if params is not None else kind()
    for name, value in overrides.items():
        if not hasattr(settings, name) or name.startswith("_"):
            raise ValueError(f"unknown {what} {name!r}")
        try:
            setattr(settings, name, value)
        except TypeError as error:
            raise TypeError(f"{what} {name!r}: {error}") from error
    return settings


def check_voxel_size(voxel_size: Any) -> None:
    """Raise ``ValueError`` unless ``voxel_size`` is a finite number > 0 (metres)."""
    if isinstance(voxel_size, bool) or not isinstance(voxel_size, numbers.Real):
        raise ValueError(f"voxel_size must be a number of metres, got {voxel_size!r}")
    if not (math.isfinite(float(voxel_size)) and float(voxel_size) > 0):
        raise ValueError(f"voxel_size must be finite and > 0 metres, got {voxel_size}")


def check_viewpoint(viewpoint: Any) -> np.ndarray:
    """The sensor origin as a finite (3,) float array; ``ValueError`` otherwise."""
    try:
        point = np.asarray(viewpoint, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"viewpoint must be 3 numbers (metres), got {viewpoint!r}") from error
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError(f"viewpoint must be 3 finite numbers (metres), got {viewpoint!r}")
    return point


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

    Raises
    ------
    ValueError
        For an empty cloud, a voxel size that is not finite and positive or too fine for
        the cloud's extent, or a cloud in which no normal can be fitted (coincident or
        collinear points).
    """
    if len(cloud) == 0:
        raise ValueError(f"{argument} is empty: at least 1 finite point is needed")
    check_voxel_size(voxel_size)
    if downsample:
        try:
            cloud = voxel_downsample(cloud, voxel_size / 2)
        except ValueError as error:  # the core names half the voxel size: say why
            raise ValueError(
                f"{argument}: downsampling to half of voxel_size = {voxel_size} m: {error}"
            ) from error
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
    model, scene : PointCloud, open3d.geometry.PointCloud or ndarray
        Clouds in metres, as :class:`PointCloud`, Open3D clouds (their points and normals)
        or (N, 3) / (N, 6) arrays (points, normals).
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
        ``iterations``, ``fitness`` (in [0, 1]: the share of model voxels next to scene
        points, or with ``scene_viewpoint`` the share of the model's rendered view that the
        scan confirms, hidden pixels counted half; see ``AlignResult.fitness``) and the
        per-iteration ``history`` of J_t, J_r and the gradients. Not converging within
        ``max_iterations`` gives ``converged = False``, not an exception.

    Raises
    ------
    ValueError
        For an empty cloud, an array of the wrong shape or dtype (integers are refused),
        non-finite coordinates, an unknown setting in ``overrides``, a setting out of its
        range, or a grid over ``max_voxels`` (refused before it is allocated); the message
        names the argument or the limit.
    TypeError
        For ``params`` that is not an :class:`AlignParams`, or a setting of the wrong type.

    Notes
    -----
    Degenerate input is not an error when it has a defined answer: a model of one point
    or of coincident points returns ``converged = False``; docs/reliability.md lists each
    case. ``max_seconds`` counts from the start of the C++ alignment, after downsampling
    and normal estimation.
    """
    settings = with_overrides(params, AlignParams, overrides, "alignment setting")
    viewpoint = check_viewpoint(viewpoint)
    model_cloud = prepare(
        as_cloud(model, "model"), "model", settings.voxel_size, downsample, viewpoint
    )
    scene_cloud = prepare(
        as_cloud(scene, "scene"), "scene", settings.voxel_size, downsample, viewpoint
    )
    return _align(model_cloud, scene_cloud, settings)
