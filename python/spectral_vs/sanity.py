"""Input that is accepted but probably not what was meant: the checks and their warning.

Each check names the argument at fault. A warning (:class:`InputWarning`, a
``UserWarning``) leaves the result as computed; an input that cannot be right (an (N, 6)
array whose last columns are not normals) is a ``ValueError``. README.md, "Input
sanity", lists them with the measurements behind their thresholds.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from spectral_vs._core import InputWarning, PointCloud
from spectral_vs._core import estimate_normals as _estimate_normals

#: The largest relative error of a normal's length that is normalised as it is: an (N, 6)
#: array whose median row is farther from unit length, or more than
#: :data:`NON_UNIT_SHARE` of whose rows are, holds no normals (colours in [0, 1] have
#: lengths 0-1.7, in [0, 255] up to 442).
NORMAL_LENGTH_TOLERANCE = 0.1
#: The share of rows whose length may be off unit by more than the tolerance.
NON_UNIT_SHARE = 0.1
#: Normals whose three columns are all >= 0 (colours are) must be unit to this tolerance:
#: a grey scene's colours (0.55, 0.55, 0.55) are 0.95 long.
NON_NEGATIVE_LENGTH_TOLERANCE = 0.01


def inside_bounding_box(points: np.ndarray, point: Any) -> bool:
    """Whether ``point`` lies strictly inside the axis-aligned box of ``points`` (N, 3).

    A depth camera's cloud in its frame lies in front of the camera (z > 0), so its sensor
    origin is outside; a model centred at the origin holds the origin.
    """
    if len(points) == 0:
        return False
    p = np.asarray(point, dtype=float)
    return bool(np.all(points.min(axis=0) < p) and np.all(p < points.max(axis=0)))


def check_normal_columns(normals: np.ndarray, argument: str) -> None:
    """Raise ``ValueError`` naming ``argument`` when the last three columns of an (N, 6)
    array are not unit normals (colours, intensities): see the module's constants."""
    if len(normals) == 0 or not np.all(np.isfinite(normals)):
        return  # PointCloud names non-finite rows
    lengths = np.linalg.norm(normals, axis=1)
    median = float(np.median(lengths))
    off = int(np.count_nonzero(np.abs(lengths - 1.0) > NORMAL_LENGTH_TOLERANCE))
    non_negative = bool(np.all(normals >= 0.0))
    reason = None
    if abs(median - 1.0) > NORMAL_LENGTH_TOLERANCE or off > NON_UNIT_SHARE * len(normals):
        reason = (
            f"their lengths are not 1: median {median:.3g}, and {off} of {len(normals)} rows "
            f"are off 1 by more than {NORMAL_LENGTH_TOLERANCE:.0%}"
        )
    elif non_negative and np.any(np.abs(lengths - 1.0) > NON_NEGATIVE_LENGTH_TOLERANCE):
        reason = (
            f"all three columns are >= 0, as colours are, and their lengths are not 1 "
            f"(from {lengths.min():.3g} to {lengths.max():.3g})"
        )
    if reason is not None:
        raise ValueError(
            f"{argument}: the last three columns of an (N, 6) array are taken as unit normals, "
            f"but {reason}: are they colours? Pass the points alone as an (N, 3) array "
            f"(normals are then estimated), or give normals explicitly as "
            f"PointCloud(points, normals)"
        )


def estimate_normals(
    cloud: PointCloud,
    radius: float = 0.015,
    k_neighbors: int = 0,
    viewpoint: Any = (0.0, 0.0, 0.0),
    orientation: str = "toward_viewpoint",
    threads: int = 1,
) -> PointCloud:
    """Plane-fit normals (PCL's NormalEstimationOMP), each oriented toward ``viewpoint``
    or ``"outward"`` from the centroid of the points that get one.

    Parameters
    ----------
    cloud : PointCloud
        Points in metres.
    radius : float
        Neighbourhood radius in metres (used when ``k_neighbors`` is 0).
    k_neighbors : int
        If > 0, this many nearest neighbours instead of a radius.
    viewpoint : array_like (3,)
        The sensor origin, metres, for ``orientation="toward_viewpoint"``.
    orientation : str
        ``"toward_viewpoint"`` (a scan) or ``"outward"`` (a closed, roughly star-shaped
        model).
    threads : int
        OpenMP threads in [1, 256]; the result does not depend on it.

    Returns
    -------
    PointCloud
        The points that have a normal (3 or more neighbours, not all coincident): isolated
        points, far outliers among them, are dropped.

    Warns
    -----
    InputWarning
        With ``"toward_viewpoint"``, when ``viewpoint`` lies inside the cloud's bounding
        box: a model centred at the origin gets normals pointing into it (use
        ``orientation="outward"``). A depth camera's cloud in its frame lies in front of
        the camera and never warns; a scan taken from inside the scene (a 360-degree
        sensor) is right as it is.

    Raises
    ------
    ValueError
        For an empty cloud, a radius or k_neighbors out of range, a viewpoint that is not
        finite, or when no point has a normal.
    """
    result = _estimate_normals(cloud, radius, k_neighbors, viewpoint, orientation, threads)
    if orientation == "toward_viewpoint" and inside_bounding_box(cloud.points, viewpoint):
        points = cloud.points
        warnings.warn(
            f"viewpoint {np.asarray(viewpoint, dtype=float).tolist()} lies inside the cloud's "
            f"bounding box ({points.min(axis=0).round(4).tolist()} to "
            f"{points.max(axis=0).round(4).tolist()} m): normals turned toward it point into a "
            f"closed model (one centred at the origin) on the surfaces around it. For a model, "
            f"use orientation='outward'; for a scan, give its sensor's origin as viewpoint (a "
            f"scan taken from inside the scene is right as it is)",
            InputWarning,
            stacklevel=2,
        )
    return result
