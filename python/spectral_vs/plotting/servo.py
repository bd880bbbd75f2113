"""A servo run: pose error over time, the camera's path and the clouds over the reference
(the paper's Fig. 6)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.plotting._common import (
    _new_figure,
    _points,
    _subsample,
)

if TYPE_CHECKING:
    from spectral_vs.servo.records import ServoLog


def plot_servo(
    log: ServoLog,
    T_base_reference: np.ndarray,
    path: Any,
    *,
    reference: PointCloud | np.ndarray | None = None,
    clouds: dict[int, np.ndarray] | None = None,
    title: str | None = None,
    max_points: int = 4000,
) -> None:
    """A servo run in the layout of the paper's Fig. 6.

    Top row (with ``reference`` and ``clouds``): the current clouds at three steps (start,
    middle, end) over the reference cloud, both in their own camera frames as the camera
    sees them (image plane, X right, Y down). Bottom row: the camera pose error over time
    (true, from the kinematics, and the servo's estimate: in ``"iteration"`` mode the
    one-iteration step, whose rotation is capped at ``max_rotation_step``) and the 3D
    trajectory of the camera in the base frame.

    Parameters
    ----------
    log : ServoLog
        A run of :func:`run_servo`.
    T_base_reference : ndarray (4, 4)
        The camera pose where the reference was captured.
    path : str or PathLike
        Image file to write (``.png``, ``.pdf``, ``.svg``).
    reference : PointCloud or ndarray (N, 3), optional
        The reference cloud, camera frame.
    clouds : dict of int to ndarray (N, 3), optional
        Current clouds by step index; the first, a middle and the last one are drawn.
    title : str, optional
        Title above the panels.
    max_points : int
        Points drawn per cloud (a seeded subsample).
    """
    rng = np.random.default_rng(0)
    show_clouds = reference is not None and bool(clouds)
    figure = _new_figure(13.0, 8.0 if show_clouds else 4.5)
    grid = figure.add_gridspec(2 if show_clouds else 1, 3)
    row = 0
    if show_clouds and reference is not None and clouds is not None:
        _servo_clouds(figure, grid, reference, clouds, lambda p: _servo_points(p, max_points, rng))
        row = 1
    _servo_errors(figure, grid, row, log, T_base_reference)
    _servo_trajectory(figure.add_subplot(grid[row, 2], projection="3d"), log, T_base_reference)
    if title:
        figure.suptitle(title)
    figure.savefig(path)


def _servo_points(points: Any, max_points: int, rng: np.random.Generator) -> np.ndarray:
    """The points of a cloud or array, at most ``max_points`` (a seeded subsample)."""
    return _subsample(_points(points), max_points, rng)


def _servo_clouds(
    figure: Any,
    grid: Any,
    reference: PointCloud | np.ndarray,
    clouds: dict[int, np.ndarray],
    subsample: Any,
) -> None:
    """The top row of :func:`plot_servo`: the first, a middle and the last of ``clouds``
    over the reference, as the camera sees them, shaded by depth."""
    ref_points = subsample(reference)
    steps = sorted(clouds)
    chosen = [steps[0], steps[len(steps) // 2], steps[-1]] if len(steps) >= 3 else steps
    names = ["initial", "intermediate", "final"]
    # Depth shades the points so that the objects stand out from the table.
    low, high = np.percentile(ref_points[:, 2], [1, 99])
    for column, (step, name) in enumerate(zip(chosen, names, strict=False)):
        axis = figure.add_subplot(grid[0, column])
        # The reference in greys, the current cloud in warm colours, both shaded by depth.
        for points, cmap, margin, label in (
            (ref_points, "Greys_r", 0.1, "reference"),
            (subsample(clouds[step]), "autumn", 0.0, f"current, step {step}"),
        ):
            axis.scatter(
                points[:, 0],
                points[:, 1],
                s=0.4,
                c=points[:, 2],
                cmap=cmap,
                vmin=low - margin,
                vmax=high + margin,
                label=label,
            )
        axis.set_title(f"{name} cloud (step {step}) over the reference")
        axis.set_xlabel("x (m, camera frame; colour: depth)")
        axis.set_ylabel("y (m)")
        axis.set_aspect("equal")
        axis.invert_yaxis()
        axis.legend(loc="upper right", fontsize="small", markerscale=10)


def _servo_errors(
    figure: Any, grid: Any, row: int, log: ServoLog, T_base_reference: np.ndarray
) -> None:
    """Two panels of :func:`plot_servo`: the true and the estimated translation and
    rotation errors over time, on log scales."""
    from spectral_vs.experiment import true_errors

    time_s = log.array("time")
    errors = true_errors(log, T_base_reference)
    estimates = (1000.0 * log.array("translation_error"), np.degrees(log.array("rotation_error")))
    panels = (
        ("tab:blue", "translation error (mm)", "camera translation error"),
        ("tab:purple", "rotation error (degrees)", "camera rotation error"),
    )
    for column, (color, label, title) in enumerate(panels):
        axis = figure.add_subplot(grid[row, column])
        axis.plot(time_s, errors[:, column], "-", color=color, label="true")
        axis.plot(
            time_s,
            estimates[column],
            ".",
            color=color,
            alpha=0.5,
            markersize=4,
            label="servo's estimate",
        )
        axis.set_yscale("log")
        axis.set_xlabel("time (s)")
        axis.set_ylabel(label)
        axis.set_title(title)
        axis.legend(fontsize="small")
        axis.grid(True, which="both", alpha=0.3)


def _servo_trajectory(path3d: Any, log: ServoLog, T_base_reference: np.ndarray) -> None:
    """The 3D panel of :func:`plot_servo`: the camera's path in the base frame, its start
    and the reference pose with their optical axes."""
    positions = np.array([record.T_base_camera[:3, 3] for record in log.records])  # type: ignore[index]
    path3d.plot(positions[:, 0], positions[:, 1], positions[:, 2], "-", color="black", linewidth=1)
    path3d.scatter(*positions[0], color="tab:red", s=30, label="start")
    path3d.scatter(*positions[-1], color="tab:green", s=30, label="end")
    goal = np.asarray(T_base_reference)[:3, 3]
    path3d.scatter(*goal, color="tab:blue", marker="*", s=80, label="reference pose")
    for T, color in ((log.records[0].T_base_camera, "tab:red"), (T_base_reference, "tab:blue")):
        axis_end = np.asarray(T)[:3, 3] + 0.05 * np.asarray(T)[:3, 2]
        start = np.asarray(T)[:3, 3]
        path3d.plot(*zip(start, axis_end, strict=True), color=color, linewidth=2)
    path3d.set_xlabel("x (m)")
    path3d.set_ylabel("y (m)")
    path3d.set_zlabel("z (m)")
    path3d.set_title("camera trajectory (base frame)")
    path3d.legend(fontsize="small", loc="upper left")
    extent = np.vstack([positions, goal])
    span = max(float(np.ptp(extent, axis=0).max()), 0.02)
    centre = (extent.max(axis=0) + extent.min(axis=0)) / 2
    for setter, c in zip((path3d.set_xlim, path3d.set_ylim, path3d.set_zlim), centre, strict=True):
        setter(c - 0.6 * span, c + 0.6 * span)
