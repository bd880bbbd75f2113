"""The windows of an organized scan that :func:`spectral_vs.data.make_view_pair` cuts its
two views out of: their size and places, and the points of a window's pixels."""

from __future__ import annotations

import math

import numpy as np


def window_offsets(
    rng: np.random.Generator, size: tuple[int, int], window: tuple[int, int], overlap: float
) -> tuple[int, int]:
    """Signed (du, dv) of the current window from the reference window, pixels, such that
    (w - |du|)(h - |dv|) is as near ``overlap`` w h as integers allow and both windows fit
    in the image. The split of the overlap between columns and rows is drawn (log-uniform
    over the feasible range)."""
    (W, H), (w, h) = size, window
    # 1D overlap fractions fu, fv with fu fv = overlap, fu >= 1 - (W - w) / w, likewise fv.
    fu_min, fv_min = max(1.0 - (W - w) / w, 1.0 / w), max(1.0 - (H - h) / h, 1.0 / h)
    low = max(math.log(fu_min), math.log(overlap))
    high = min(0.0, math.log(overlap) - math.log(fv_min))
    if low > high + 1e-12:
        least = fu_min * fv_min
        raise ValueError(
            f"overlap must be >= {least:.3f} for this window_share (the windows would not "
            f"fit in the {W}x{H} image), got {overlap}"
        )
    fu = math.exp(rng.uniform(low, high)) if high > low else math.exp(low)
    du = min(round(w * (1.0 - fu)), W - w)
    # The rows that bring the area nearest the requested overlap, given the columns.
    dv = min(max(round(h - overlap * w * h / (w - du)), 0), H - h)
    signs = rng.choice([-1, 1], size=2)
    return int(signs[0] * du), int(signs[1] * dv)


def place_windows(
    rng: np.random.Generator, size: tuple[int, int], window_share: float, overlap: float
) -> tuple[tuple[int, int], tuple[tuple[int, int], tuple[int, int]]]:
    """The windows' size and their top-left corners (reference, current) in an image of
    ``size`` (W, H), at random with ``overlap`` of a window inside the other."""
    W, H = size
    scale = math.sqrt(window_share)
    window = (max(2, round(scale * W)), max(2, round(scale * H)))
    du, dv = window_offsets(rng, (W, H), window, overlap)
    u0 = int(rng.integers(max(0, -du), W - window[0] - max(0, du) + 1))
    v0 = int(rng.integers(max(0, -dv), H - window[1] - max(0, dv) + 1))
    return window, ((u0, v0), (u0 + du, v0 + dv))


def window_view(
    image: np.ndarray, corner: tuple[int, int], window: tuple[int, int], parity: int
) -> tuple[np.ndarray, np.ndarray]:
    """Finite points and their (u, v) pixels in a window, of the pixels with
    (u + v) % 2 == parity."""
    (u0, v0), (w, h) = corner, window
    v, u = np.mgrid[v0 : v0 + h, u0 : u0 + w]
    points = image[v, u]
    keep = ((u + v) % 2 == parity) & np.all(np.isfinite(points), axis=2)
    return points[keep], np.stack([u[keep], v[keep]], axis=1)
