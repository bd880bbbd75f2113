"""The clouds every entry point takes: a :class:`spectral_vs.PointCloud`, an (N, 3) or
(N, 6) array (points, or points and normals), or an ``open3d.geometry.PointCloud``, read
through its arrays without importing Open3D (:func:`from_open3d`). One module for the
inputs, below :mod:`spectral_vs.registration`, :mod:`spectral_vs.views`, the servo and
:mod:`spectral_vs.interop`, which builds Open3D clouds from them."""

from __future__ import annotations

from typing import Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.sanity import check_normal_columns


def is_open3d_cloud(cloud: Any) -> bool:
    """Whether ``cloud`` is an ``open3d.geometry.PointCloud`` (checked without importing
    Open3D: an object of that class exists only if Open3D is imported already)."""
    cls = type(cloud)
    return cls.__name__ == "PointCloud" and cls.__module__.startswith("open3d")


def from_open3d(cloud: Any, *, drop_non_finite: bool = True) -> PointCloud:
    """A :class:`spectral_vs.PointCloud` with the points and normals of an Open3D cloud.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud
        Its ``points`` (metres) and, when it has them, its ``normals`` are copied (as
        float64); its colours are not (``np.asarray(cloud.colors)`` has them).
    drop_non_finite : bool
        Drop points with a non-finite coordinate or normal, or a zero normal (what
        :func:`spectral_vs.load_cloud` does with a file; Open3D keeps NaN points unless
        told otherwise). False: such a point raises ``ValueError``.

    Returns
    -------
    PointCloud

    Raises
    ------
    TypeError
        If ``cloud`` is not an ``open3d.geometry.PointCloud``.
    ValueError
        For non-finite points with ``drop_non_finite=False``.
    """
    if not is_open3d_cloud(cloud):
        raise TypeError(
            f"cloud must be an open3d.geometry.PointCloud, got {type(cloud).__module__}."
            f"{type(cloud).__name__}"
        )
    points = np.asarray(cloud.points, dtype=np.float64)
    normals = np.asarray(cloud.normals, dtype=np.float64) if cloud.has_normals() else None
    return PointCloud(points.reshape(-1, 3), normals, drop_non_finite=drop_non_finite)


CloudLike = PointCloud | np.ndarray


#: Rows of an (N, 6) array whose normal columns are checked when its non-finite rows are
#: dropped (evenly strided): a depth sensor's raw buffer at every control step.
_CHECKED_ROWS = 4096


def as_cloud(cloud: CloudLike, argument: str, drop_non_finite: bool = False) -> PointCloud:
    """A :class:`PointCloud` from a cloud, an Open3D cloud or an (N, 3) / (N, 6) array
    (points, normals).

    Parameters
    ----------
    cloud : PointCloud, open3d.geometry.PointCloud or ndarray
        Returned as is; an Open3D cloud's points and normals (:func:`spectral_vs.from_open3d`,
        non-finite points dropped); or an (N, 3) array of points or (N, 6) array of points
        and normals, metres. The normals of an (N, 6) array must be unit vectors (lengths
        within 10% of 1 are normalised); ``PointCloud(points, normals)`` is the explicit
        form, which takes any non-zero lengths.
    argument : str
        Name of the argument, for the error message.
    drop_non_finite : bool
        Drop the rows of an array that hold a non-finite value (a depth sensor's invalid
        returns) instead of refusing them; the normal columns are then checked on up to
        4096 evenly spaced finite rows, cheap enough for every frame of a servo.

    Returns
    -------
    PointCloud

    Raises
    ------
    ValueError
        If the array has another shape or non-finite entries, or if the last three columns
        of an (N, 6) array are not unit normals (colours in [0, 1] or [0, 255]: the median
        length off 1 by more than 10%, more than 10% of the rows so, or every column >= 0
        with lengths off 1 by more than 1%), naming ``argument``.
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
    if drop_non_finite and array.dtype.kind in "fiu":
        if array.shape[1] == 3:
            return PointCloud(array, drop_non_finite=True)
        sample = array[:: max(1, len(array) // _CHECKED_ROWS)]
        check_normal_columns(sample[np.isfinite(sample).all(axis=1), 3:], argument)
        return PointCloud(array[:, :3], array[:, 3:], drop_non_finite=True)
    if array.shape[1] == 6:
        check_normal_columns(array[:, 3:], argument)
        return PointCloud(array[:, :3], array[:, 3:])
    return PointCloud(array)
