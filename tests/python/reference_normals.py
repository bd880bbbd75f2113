"""The NumPy reference of the core's normals of an organized depth image
(:func:`spectral_vs.cloud_from_depth`), for the tests that check the core against it."""

from __future__ import annotations

import numpy as np

from spectral_vs.sim import NormalParams


def _box_sum(image: np.ndarray, window: int) -> np.ndarray:
    """Sum over a window x window neighbourhood of each pixel (zero padding), separably."""
    r = window // 2
    if r == 0:
        return image
    padded = np.pad(image, r)
    h, w = image.shape
    rows = padded[0:h].copy()
    for i in range(1, window):
        rows += padded[i : i + h]
    out = rows[:, 0:w].copy()
    for j in range(1, window):
        out += rows[:, j : j + w]
    return out


def organized_normals(
    points: np.ndarray, params: NormalParams | None = None, dtype: type[np.floating] = np.float32
) -> np.ndarray:
    """Unit normals (H, W, 3) of organized points, oriented toward the camera origin;
    NaN where no reliable normal exists (see :class:`NormalParams`).

    The NumPy reference of the core's normals (:func:`spectral_vs.cloud_from_depth`,
    which :func:`spectral_vs.sim.depth_to_cloud` uses). Computed per coordinate plane, in float32 by
    default (4x faster than interleaved float64; the normals differ by about 1e-5 rad).

    Parameters
    ----------
    points : ndarray, shape (H, W, 3)
        Organized points in the camera frame (:func:`back_project`), metres.
    params : NormalParams
        Stencil, averaging window and depth-jump threshold.
    dtype : type
        Floating type of the computation (``np.float32`` or ``np.float64``).

    Returns
    -------
    ndarray, shape (H, W, 3)
        Unit normals; NaN rows where none is reliable (including a border of
        ``normal_step`` pixels).
    """
    params = params if params is not None else NormalParams()
    s = params.normal_step
    h, w = points.shape[:2]
    normals = np.full((h, w, 3), np.nan)
    if h <= 2 * s or w <= 2 * s:
        return normals
    x, y, z = (np.asarray(points[..., i], dtype=np.dtype(dtype)) for i in range(3))
    # The pixel and its four stencil neighbours, on the interior where all exist.
    center = (slice(s, -s), slice(s, -s))
    right, left = (slice(s, -s), slice(2 * s, None)), (slice(s, -s), slice(None, -2 * s))
    down, up = (slice(2 * s, None), slice(s, -s)), (slice(None, -2 * s), slice(s, -s))
    depth = z[center]
    limit = params.max_depth_jump * depth
    with np.errstate(invalid="ignore"):
        reliable = np.isfinite(depth)
        for neighbour in (right, left, down, up):
            reliable &= np.abs(z[neighbour] - depth) <= limit
    # Central differences along the columns (u) and the rows (v), and their cross product.
    ux, uy, uz = x[right] - x[left], y[right] - y[left], z[right] - z[left]
    vx, vy, vz = x[down] - x[up], y[down] - y[up], z[down] - z[up]
    cross = [vy * uz - vz * uy, vz * ux - vx * uz, vx * uy - vy * ux]
    for component in cross:
        component[~reliable] = 0.0
    nx, ny, nz = (_box_sum(component, params.window) for component in cross)
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    valid = reliable & (norm > 0.0)
    # Toward the camera: n . (0 - p) > 0, so flip where n . p > 0.
    toward = np.where(nx * x[center] + ny * y[center] + nz * depth > 0.0, -1.0, 1.0)
    scale = np.where(valid, toward / np.where(valid, norm, 1.0), np.nan)
    interior = normals[center]
    for i, component in enumerate((nx, ny, nz)):
        interior[..., i] = component * scale
    return normals
