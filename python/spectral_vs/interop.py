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

from spectral_vs.clouds import as_cloud, from_open3d, is_open3d_cloud

__all__ = ["from_open3d", "is_open3d_cloud", "to_open3d"]

_INSTALL = "pip install open3d (or the bench extra: pip install spectral_vs[bench])"


def _open3d() -> Any:
    try:
        import open3d
    except ImportError as error:
        raise ImportError(f"spectral_vs.to_open3d needs Open3D: {_INSTALL}") from error
    return open3d


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
