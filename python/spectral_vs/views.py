"""Scene-to-scene registration from Python: two views of one scene, registered globally.

The reference view (the desired camera's cloud in direct visual servoing) is registered
onto the current view: ``T_current_reference`` moves the reference's points onto the same
surfaces in the current view's coordinates. Every length is derived from the views
(:func:`spectral_vs.view_scale`) unless given; docs/views.md has the rule.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from spectral_vs._core import (
    PointCloud,
    ViewAlignParams,
    ViewAlignResult,
    estimate_normals,
)
from spectral_vs._core import align_views as _align_views
from spectral_vs.clouds import CloudLike, as_cloud
from spectral_vs.registration import check_viewpoint, with_overrides
from spectral_vs.sanity import InputWarning, inside_bounding_box

#: Neighbours of an estimated normal's plane fit: a count, not a radius, because a depth
#: camera's point spacing grows with the square of the depth (2 mm at 1 m, 50 mm at 10 m).
NORMAL_NEIGHBORS = 20


def _view(cloud: CloudLike, argument: str, viewpoint: Any, origin_argument: str) -> PointCloud:
    view = as_cloud(cloud, argument)
    if len(view) == 0:
        raise ValueError(f"{argument} is empty: at least 1 finite point is needed")
    if not view.has_normals:
        view = estimate_normals(view, k_neighbors=NORMAL_NEIGHBORS, viewpoint=viewpoint)
        if inside_bounding_box(view.points, viewpoint):
            warnings.warn(
                f"{origin_argument} {np.asarray(viewpoint, dtype=float).tolist()} lies inside "
                f"the bounding box of {argument}: its estimated normals, turned toward it, "
                f"point into the surfaces around it if {argument} is a closed model rather "
                f"than a depth camera's view from there. Give {argument}'s sensor origin, or "
                f"its normals (PointCloud(points, normals), e.g. from "
                f"estimate_normals(..., orientation='outward'))",
                InputWarning,
                stacklevel=3,
            )
    return view


def align_views(
    reference: CloudLike,
    current: CloudLike,
    params: ViewAlignParams | None = None,
    *,
    reference_sensor_origin: Any = (0.0, 0.0, 0.0),
    prior: Any = None,
    **overrides: Any,
) -> ViewAlignResult:
    """Register the ``reference`` view onto the ``current`` view of the same scene.

    Parameters
    ----------
    reference, current : PointCloud, open3d.geometry.PointCloud or ndarray
        The two views, metres, as :class:`PointCloud`, Open3D clouds or (N, 3) / (N, 6)
        arrays (points, normals; the normals unit vectors, see :func:`align`). Missing
        normals are estimated (20 nearest neighbours) and turned toward the view's sensor;
        an ``InputWarning`` names the sensor origin when it lies inside the view's
        bounding box (a closed model, not a view, gets normals into it).
    params : ViewAlignParams, optional
        Settings; defaults to ``ViewAlignParams()`` (every length derived from the views).
    reference_sensor_origin : array_like (3,)
        The reference view's sensor origin in its coordinates, metres (default the
        origin); used only to orient estimated normals.
    prior : array_like (4, 4), optional
        A ``T_current_reference`` known from elsewhere (a tracker's estimate): refined and
        scored beside the search's hypotheses, and returned (``hypothesis`` -1) unless a
        searched pose is better supported.
    **overrides
        Any :class:`ViewAlignParams` field, e.g. ``hypotheses=24, voxel_size=0.02``.
        The current view's sensor: ``sensor_origin`` (metres, in its coordinates, default
        the origin: a depth camera's cloud in its own frame), as in :func:`align`; the
        support check renders from it and estimated normals turn toward it.

    Returns
    -------
    ViewAlignResult
        ``T_current_reference`` (4 x 4), ``support`` (its ``score`` in [0, 1] separates
        right from wrong poses: docs/views.md), ``converged`` and ``status``
        (``"converged"``, ``"no_support"`` or ``"max_seconds"``), the ``scale`` used and
        every checked hypothesis.

    Raises
    ------
    ValueError
        For an empty view, an array of the wrong shape, non-finite coordinates, a
        sensor origin that is not 3 finite numbers, an out-of-range setting, or a
        grid over ``max_voxels``, a prior that is not a rigid 4 x 4 transform; the message
        names the argument. Views that share no
        surface are not an error: the result's ``status`` is ``"no_support"``.
    TypeError
        For ``params`` that is not a :class:`ViewAlignParams`, or an unknown setting in
        ``overrides`` (named).
    """
    settings = with_overrides(params, ViewAlignParams, overrides, "view alignment setting")
    current_origin = check_viewpoint(settings.sensor_origin, "sensor_origin")
    reference_origin = check_viewpoint(reference_sensor_origin, "reference_sensor_origin")
    reference_view = _view(reference, "reference", reference_origin, "reference_sensor_origin")
    current_view = _view(current, "current", current_origin, "sensor_origin")
    return _align_views(reference_view, current_view, settings, prior)
