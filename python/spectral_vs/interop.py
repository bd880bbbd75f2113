"""Point clouds to and from Open3D, without a dependency on it.

Open3D (``pip install open3d``, or the ``bench`` extra: ``pip install spectral_vs[bench]``)
is imported only when :func:`to_open3d` builds one of its clouds; :func:`from_open3d` and
:func:`spectral_vs.align` read an ``open3d.geometry.PointCloud`` through its arrays. ::

    pcd = o3d.io.read_point_cloud("scene.ply")
    result = svs.align(svs.from_open3d(model_pcd), pcd)    # or pass either directly
    o3d.visualization.draw_geometries([svs.to_open3d(svs.from_open3d(model_pcd)
                                       .transformed(result.T_scene_model)), pcd])

Colours: a :class:`spectral_vs.PointCloud` holds points and normals only. ``pcd.colors``
(an (N, 3) array in [0, 1]) stays with the caller; :func:`to_open3d` takes colours to
attach, one row per point.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from spectral_vs._core import PointCloud

_INSTALL = "pip install open3d (or the bench extra: pip install spectral_vs[bench])"


def is_open3d_cloud(cloud: Any) -> bool:
    """Whether ``cloud`` is an ``open3d.geometry.PointCloud`` (checked without importing
    Open3D: an object of that class exists only if Open3D is imported already)."""
    cls = type(cloud)
    return cls.__name__ == "PointCloud" and cls.__module__.startswith("open3d")


def _open3d() -> Any:
    try:
        import open3d
    except ImportError as error:
        raise ImportError(f"spectral_vs.to_open3d needs Open3D: {_INSTALL}") from error
    return open3d


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


def to_open3d(cloud: Any, colors: npt.ArrayLike | None = None) -> Any:
    """An ``open3d.geometry.PointCloud`` with the points and normals of ``cloud``.

    Parameters
    ----------
    cloud : PointCloud or ndarray
        A :class:`spectral_vs.PointCloud`, or an (N, 3) / (N, 6) array (points, normals),
        metres.
    colors : array_like (N, 3), optional
        RGB colours in [0, 1], one row per point.

    Returns
    -------
    open3d.geometry.PointCloud

    Raises
    ------
    ImportError
        If Open3D is not installed (the message says how to install it).
    ValueError
        For a cloud array of another shape, or colours that are not (N, 3) in [0, 1].
    """
    from spectral_vs.registration import as_cloud

    source = as_cloud(cloud, "cloud")
    o3d = _open3d()
    out = o3d.geometry.PointCloud()
    out.points = o3d.utility.Vector3dVector(np.array(source.points, dtype=np.float64))
    if source.has_normals:
        out.normals = o3d.utility.Vector3dVector(np.array(source.normals, dtype=np.float64))
    if colors is not None:
        rgb = np.array(colors, dtype=np.float64)
        if rgb.shape != (len(source), 3):
            raise ValueError(
                f"colors must have shape ({len(source)}, 3), one RGB row per point, got {rgb.shape}"
            )
        if not (np.all(np.isfinite(rgb)) and np.all((rgb >= 0.0) & (rgb <= 1.0))):
            raise ValueError("colors must be finite RGB values in [0, 1]")
        out.colors = o3d.utility.Vector3dVector(rgb)
    return out
