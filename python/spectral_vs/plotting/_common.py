"""What the figures share: the Agg figure without pyplot, colours, axis scales, point
sampling and the view box."""

from __future__ import annotations

from typing import Any

import numpy as np

from spectral_vs._core import PointCloud

_SCENE_COLOR = "0.45"
_INITIAL_COLOR = "tab:red"
_STEP_COLOR = "tab:orange"
_FINAL_COLOR = "tab:green"
_PATH_COLOR = "black"


def _new_figure(width: float, height: float) -> Any:
    """A matplotlib ``Figure`` on the Agg canvas, with a clear message if matplotlib is missing."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as error:
        raise ImportError(
            "spectral_vs.plotting needs matplotlib: pip install spectral_vs[plot]"
        ) from error
    figure = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _set_scale(axis: Any, values: np.ndarray, from_zero: bool = False) -> None:
    """Log scale for positive values spanning more than a decade, else linear.

    A linear axis spans at least 1% of the values' size (or starts at zero with
    ``from_zero``), so that a nearly constant series reads as constant instead of being
    stretched over an offset axis.
    """
    finite = values[np.isfinite(values)]
    if not finite.size:
        return
    low, high = float(finite.min()), float(finite.max())
    if low > 0 and high > 10 * low:
        axis.set_yscale("log")
    elif from_zero and low >= 0:
        axis.set_ylim(0.0, 1.1 * high if high > 0 else 1.0)
    else:
        pad = max(0.08 * (high - low), 0.005 * max(abs(low), abs(high)), 1e-12)
        axis.set_ylim(low - pad, high + pad)
    if axis.get_yscale() == "linear":
        axis.ticklabel_format(axis="y", useOffset=False)


def _points(cloud: PointCloud | np.ndarray) -> np.ndarray:
    if isinstance(cloud, PointCloud):
        return np.asarray(cloud.points)
    return np.asarray(cloud, dtype=float)[:, :3]


def _moved(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    return points @ T[:3, :3].T + T[:3, 3]


def _subsample(points: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    if len(points) <= count:
        return points
    return points[rng.choice(len(points), size=count, replace=False)]


def _view_box(clouds: list[np.ndarray], size: float) -> tuple[np.ndarray, float]:
    """Centre and half edge of a cube holding ``clouds`` with a margin of 0.6 ``size``."""
    stacked = np.vstack(clouds)
    low, high = stacked.min(axis=0) - 0.6 * size, stacked.max(axis=0) + 0.6 * size
    return (low + high) / 2, float(np.max(high - low)) / 2
