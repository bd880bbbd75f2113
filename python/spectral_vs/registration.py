"""Model-to-scene alignment from Python: input conversion and defaults over the C++ aligner."""

from __future__ import annotations

import copy
import difflib
import math
import numbers
from typing import Any

import numpy as np

from spectral_vs._core import (
    AlignParams,
    AlignResult,
    PointCloud,
    _align,
    alignment_voxel_size,
    prepare_cloud,
)
from spectral_vs.clouds import CloudLike, as_cloud

#: Keywords removed in 0.3 (0.2's deprecated aliases) and what stands for each now.
_REMOVED_KEYWORDS = {
    "viewpoint": "sensor_origin",
    "scene_viewpoint": "sensor_origin (and scene_view='single_view')",
    "current_viewpoint": "sensor_origin",
    "reference_viewpoint": "reference_sensor_origin",
}


def with_overrides(params: Any, kind: type, overrides: dict[str, Any], what: str) -> Any:
    """A copy of ``params`` (a ``kind``, or ``kind()`` for None) with the fields of
    ``overrides`` set: the caller's settings never change.

    Raises
    ------
    TypeError
        For ``params`` of another type, a value of the wrong type, or a field that
        ``kind`` does not have (named as ``what``, with the closest field names): as
        ``kind(name=...)`` refuses it, an unexpected keyword argument.
    """
    if params is not None and not isinstance(params, kind):
        raise TypeError(f"params must be of type {kind.__name__}, got {type(params).__name__}")
    settings = copy.copy(params) if params is not None else kind()
    for name, value in overrides.items():
        if not hasattr(settings, name) or name.startswith("_"):
            fields = [f for f in dir(settings) if not f.startswith("_")]
            close = difflib.get_close_matches(name, fields, 3, 0.6)
            hint = f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
            if name in _REMOVED_KEYWORDS:
                hint = f" (removed in 0.3: use {_REMOVED_KEYWORDS[name]})"
            raise TypeError(f"unknown {what} {name!r}: no {kind.__name__} field of that name{hint}")
        try:
            setattr(settings, name, value)
        except (TypeError, AttributeError) as error:  # AttributeError: a read-only property
            raise TypeError(f"{what} {name!r}: {error}") from error
    return settings


def check_voxel_size(voxel_size: Any) -> None:
    """Raise ``ValueError`` unless ``voxel_size`` is a finite number > 0 (metres)."""
    if isinstance(voxel_size, bool) or not isinstance(voxel_size, numbers.Real):
        raise ValueError(f"voxel_size must be a number of metres, got {voxel_size!r}")
    if not (math.isfinite(float(voxel_size)) and float(voxel_size) > 0):
        raise ValueError(f"voxel_size must be finite and > 0 metres, got {voxel_size}")


def check_viewpoint(viewpoint: Any, argument: str = "viewpoint") -> np.ndarray:
    """The sensor origin as a finite (3,) float array; ``ValueError`` naming ``argument``
    otherwise."""
    try:
        point = np.asarray(viewpoint, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{argument} must be 3 numbers (metres), got {viewpoint!r}") from error
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError(f"{argument} must be 3 finite numbers (metres), got {viewpoint!r}")
    return point


def prepare(
    cloud: PointCloud, argument: str, voxel_size: float, downsample: bool, viewpoint: Any
) -> PointCloud:
    """The one preparation of every registration (:func:`spectral_vs.prepare_cloud`, C++
    ``prepare_cloud``): downsampled to half of ``voxel_size`` when ``downsample``, normals
    fitted over twice it where missing, turned toward ``viewpoint`` (outward from a closed
    model that holds it). Errors name ``argument``; ``ValueError`` for a voxel size that is
    not a finite number > 0, an empty cloud, or a cloud in which no normal can be fitted."""
    check_voxel_size(voxel_size)  # a number, before the core reads it as one
    return prepare_cloud(
        cloud, float(voxel_size), downsample, check_viewpoint(viewpoint), argument=argument
    )


def derived_voxel_size(settings: AlignParams, model: PointCloud, scene: PointCloud) -> AlignParams:
    """``settings`` with ``voxel_size = 0`` replaced by :func:`alignment_voxel_size` of the
    clouds as given (before any downsampling): both are then prepared at it."""
    if settings.voxel_size == 0:
        for cloud, argument in ((model, "model"), (scene, "scene")):
            if len(cloud) == 0:
                raise ValueError(f"{argument} is empty: at least 1 finite point is needed")
        settings.voxel_size = alignment_voxel_size(model, scene)
    return settings


def align(
    model: CloudLike,
    scene: CloudLike,
    params: AlignParams | None = None,
    *,
    downsample: bool = True,
    **overrides: Any,
) -> AlignResult:
    """Align ``model`` onto ``scene``: Algorithm 1 with, by default, a global rotation search.

    Parameters
    ----------
    model, scene : PointCloud, open3d.geometry.PointCloud or ndarray
        Clouds in metres, as :class:`PointCloud`, Open3D clouds (their points and normals)
        or (N, 3) / (N, 6) arrays (points, normals).
        Missing normals are estimated (radius 2 x voxel_size, oriented toward
        ``sensor_origin``, the origin by default: a depth camera's cloud in its own frame;
        outward from the cloud's centroid when ``sensor_origin`` lies inside the cloud's
        bounding box, as it does in a model centred at the origin). The last three columns
        of an (N, 6) array must be unit normals (``ValueError`` otherwise: colours are
        not); ``PointCloud(points, normals)`` gives normals explicitly.
    params : AlignParams, optional
        Settings; defaults to ``AlignParams()``.
    downsample : bool
        Voxel-downsample both clouds to half the voxel size first (default True).
    **overrides
        Any :class:`AlignParams` field, e.g. ``voxel_size=0.005, global_search=False``.
        The sensor: ``sensor_origin`` (metres, default the origin) orients estimated
        normals, and with ``scene_view='auto'`` (default) the scene is checked as a single
        view from it when :func:`detect_single_view` finds one; ``'single_view'`` declares
        one, ``'all_sides'`` never (a full model, a fused map).
        ``voxel_size=0`` (default) derives the voxel from the model
        (:func:`alignment_voxel_size`).

    Returns
    -------
    AlignResult
        ``T_scene_model`` maps model coordinates into the scene; ``converged``,
        ``iterations`` and the per-iteration ``history`` of J_t, J_r and the gradients
        (of the Algorithm 1 run that produced the returned pose), ``fitness`` (in [0, 1]:
        the share of model voxels next to scene points, or for a single view the share of
        the model's rendered view that the scan confirms, hidden pixels counted half; see
        ``AlignResult.fitness``), ``voxel_size`` (the one used) and ``single_view``. Not
        converging within ``max_iterations`` gives ``converged = False``, not an exception.

    Raises
    ------
    ValueError
        For an empty cloud, an array of the wrong shape or dtype (integers are refused),
        non-finite coordinates, a setting out of its range, or a grid over ``max_voxels``
        (refused before it is allocated); the message names the argument or the limit.
    TypeError
        For ``params`` that is not an :class:`AlignParams`, a setting of the wrong type,
        or an unknown setting in ``overrides`` (named, as ``AlignParams(name=...)`` names
        it).

    Notes
    -----
    Degenerate input is not an error when it has a defined answer: a model of one point
    or of coincident points returns ``converged = False``; docs/reliability.md lists each
    case. ``max_seconds`` counts from the start of the C++ alignment, after downsampling
    and normal estimation.
    """
    settings = with_overrides(params, AlignParams, overrides, "alignment setting")
    origin = np.asarray(settings.sensor_origin, dtype=float)
    model_cloud, scene_cloud = as_cloud(model, "model"), as_cloud(scene, "scene")
    settings = derived_voxel_size(settings, model_cloud, scene_cloud)
    model_cloud = prepare(model_cloud, "model", settings.voxel_size, downsample, origin)
    scene_cloud = prepare(scene_cloud, "scene", settings.voxel_size, downsample, origin)
    return _align(model_cloud, scene_cloud, settings)
