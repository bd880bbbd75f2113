"""Figures written to image files: an alignment's convergence (the paper's Fig. 3 and 5),
the model's path onto the scene (Fig. 1), and a servo run (Fig. 6, :func:`plot_servo`).

matplotlib is optional (``pip install spectral_vs[plot]``) and imported only when a figure
is drawn. Figures are made without ``pyplot`` on the Agg canvas, so drawing works without a
display and leaves the caller's matplotlib backend alone.
"""

from __future__ import annotations

import os
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from spectral_vs._core import AlignParams, AlignResult, PointCloud
from spectral_vs.poses import pose_error

if TYPE_CHECKING:
    from spectral_vs.servo.records import ServoLog

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


def pose_errors(
    T_estimate: np.ndarray, T_true: np.ndarray, center: np.ndarray | None = None
) -> tuple[float, float]:
    """Deprecated (removed in 0.3): ``(rotation_deg, translation_mm)`` of an estimated pose.

    Use :func:`spectral_vs.pose_error`, which returns ``(translation_m, rotation_rad)``
    with ``.rotation_deg`` and ``.translation_mm``: this is
    ``e = pose_error(T_estimate, T_true, center=center); (e.rotation_deg, e.translation_mm)``.
    """
    warnings.warn(
        "spectral_vs.plotting.pose_errors is deprecated and will be removed in 0.3: use "
        "spectral_vs.pose_error(T_estimate, T_true, center=center), which returns "
        "(translation_m, rotation_rad) with .rotation_deg and .translation_mm",
        DeprecationWarning,
        stacklevel=2,
    )
    error = pose_error(T_estimate, T_true, center=center)
    return error.rotation_deg, error.translation_mm


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


def _series(history: list[Any], name: str) -> np.ndarray:
    """One field of every iteration's record."""
    return np.array([getattr(step, name) for step in history], dtype=float)


def _plot_stop_rule(stop: Any, history: list[Any], eps_g: float, voxel_size: float | None) -> None:
    """The two terms of the stop rule (eq. 17), their sum and the tolerance."""
    iterations = np.arange(1, len(history) + 1)
    step = _series(history, "translation_step")
    gradient = _series(history, "rotation_gradient")
    step_label = "translation step (voxels)"
    if voxel_size:
        step_label = f"translation step (voxels of {1000 * voxel_size:g} mm)"
    stop.plot(iterations, step, "o-", color="tab:blue", markersize=3, label=step_label)
    stop.plot(
        iterations,
        gradient,
        "s-",
        color="tab:purple",
        markersize=3,
        label=r"$|\nabla C_r|$ (per radian)",
    )
    stop.plot(iterations, step + gradient, "-", color="black", linewidth=1.5, label="sum (eq. 17)")
    stop.axhline(
        eps_g, color="tab:red", linestyle="--", label=rf"tolerance $\epsilon_g$ = {eps_g:g}"
    )
    _set_scale(stop, np.concatenate([step, gradient, [eps_g]]))
    stop.set_title("stop rule: gradient norms")
    stop.set_xlabel("iteration")
    stop.set_ylabel("norm")
    stop.legend(fontsize="small", loc="best")


def _plot_errors(
    last: Any, poses: list[np.ndarray], ground_truth: np.ndarray, center: np.ndarray | None
) -> None:
    """The rotation and translation errors of ``poses`` (the start first)."""
    errors = np.array(
        [
            (e.rotation_deg, e.translation_mm)
            for e in (pose_error(T, ground_truth, center=center) for T in poses)
        ],
        dtype=float,
    )
    steps = np.arange(len(poses))
    rotation_line = last.plot(
        steps, errors[:, 0], "o-", color="tab:purple", markersize=4, label="rotation (left)"
    )
    last.set_ylabel("rotation error (degrees)", color="tab:purple")
    right = last.twinx()
    translation_line = right.plot(
        steps, errors[:, 1], "s--", color="tab:blue", markersize=3, label="translation (right)"
    )
    last.legend(handles=rotation_line + translation_line, fontsize="small")
    right.set_ylabel("translation error (mm)", color="tab:blue")
    _set_scale(last, errors[:, 0], from_zero=True)
    _set_scale(right, errors[:, 1], from_zero=True)
    last.set_title("error against the ground truth (0 = start)")


def _plot_similarity(last: Any, history: list[Any]) -> None:
    """The EGI correlation and the phase-correlation peak of every iteration."""
    iterations = np.arange(1, len(history) + 1)
    last.plot(
        iterations,
        _series(history, "correlation"),
        "o-",
        color="tab:purple",
        markersize=3,
        label="EGI correlation $C_r$",
    )
    last.plot(
        iterations,
        _series(history, "translation_peak"),
        "s-",
        color="tab:blue",
        markersize=3,
        label="phase-correlation peak",
    )
    last.set_ylim(min(0.0, float(_series(history, "correlation").min())) - 0.05, 1.05)
    last.set_ylabel("dimensionless")
    last.set_title("similarity")
    last.legend(fontsize="small")


def plot_convergence(
    result: AlignResult,
    path: str | os.PathLike[str],
    title: str | None = None,
    *,
    tolerance: float | None = None,
    voxel_size: float | None = None,
    ground_truth: np.ndarray | None = None,
    center: np.ndarray | None = None,
    initial_T: np.ndarray | None = None,
) -> None:
    """Plot the per-iteration costs and gradients of an alignment (the paper's Fig. 3 and 5).

    Four panels over the iterations of Algorithm 1: the translation cost J_t (eq. 9), the
    rotation cost J_r (eq. 16), the two terms of the stop rule (eq. 17) with the tolerance
    eps_g, and either the pose error against ``ground_truth`` or, without it, the EGI
    correlation and the phase-correlation peak.

    Parameters
    ----------
    result : AlignResult
        Output of :func:`spectral_vs.align`; its ``history`` is plotted.
    path : str or PathLike
        Image file to write; the format follows the extension (``.png``, ``.pdf``, ``.svg``).
    title : str, optional
        Title above the panels.
    tolerance : float, optional
        eps_g of eq. (17) used in the run; defaults to ``AlignParams().tolerance``.
    voxel_size : float, optional
        Voxel edge of the run, metres, to label the translation step also in millimetres.
    ground_truth : ndarray (4, 4), optional
        True ``T_scene_model``; adds the rotation error (degrees) and translation error
        (millimetres) of every iteration.
    center : ndarray (3,), optional
        Model point at which the translation error is measured (see
        :func:`spectral_vs.pose_error`).
    initial_T : ndarray (4, 4), optional
        ``T_scene_model`` the model started from (identity when omitted); its error is
        drawn at iteration 0, before the global search and the first update.
    """
    history = list(result.history)
    eps_g = AlignParams().tolerance if tolerance is None else tolerance
    iterations = np.arange(1, len(history) + 1)
    figure = _new_figure(10.0, 7.0)
    (cost_t, cost_r), (stop, last) = figure.subplots(2, 2, sharex=True)
    if title:
        figure.suptitle(title)
    if not history:
        figure.text(0.5, 0.5, "no iterations recorded", ha="center", va="center")
        figure.savefig(path)
        return

    j_t = _series(history, "translation_cost")
    cost_t.plot(iterations, j_t, "o-", color="tab:blue", markersize=3)
    _set_scale(cost_t, j_t)
    cost_t.set_title("translation cost $J_t$ (eq. 9)")
    cost_t.set_ylabel("$J_t$ (voxel grid units)")

    j_r = _series(history, "rotation_cost")
    cost_r.plot(iterations, j_r, "o-", color="tab:purple", markersize=3)
    _set_scale(cost_r, j_r)
    cost_r.set_title("rotation cost $J_r$ (eq. 16)")
    cost_r.set_ylabel("$J_r$ (normalised EGI units)")

    _plot_stop_rule(stop, history, eps_g, voxel_size)
    if ground_truth is not None:
        start = np.eye(4) if initial_T is None else np.asarray(initial_T, dtype=float)
        _plot_errors(
            last, [start] + [np.asarray(s.T_scene_model) for s in history], ground_truth, center
        )
    else:
        _plot_similarity(last, history)
    last.set_xlabel("iteration")
    first = 0 if ground_truth is not None else 1
    for axis in (cost_t, cost_r, stop, last):
        axis.grid(True, which="major", alpha=0.3)
        axis.xaxis.get_major_locator().set_params(integer=True)
        axis.set_xlim(first - 0.3, len(history) + 0.3)
    figure.savefig(path)


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


def _display_frame(
    points: np.ndarray, normals: np.ndarray | None
) -> tuple[np.ndarray, list[str], str]:
    """A rotation whose third row, "up", is the normal of the scene's main plane.

    The normal is the direction of least spread of ``points``, turned toward where most
    ``normals`` point (toward the sensor above a table). Within 10 degrees of a coordinate
    axis it snaps to that axis, so the axes keep their names (e.g. ``-y`` for a scan in
    camera coordinates, y pointing down); otherwise the frame is tilted and its axes are
    named x', y' and up. Returns the rows (display axes in scene coordinates), the axis
    labels and the name of the up direction.
    """
    if len(points) < 4:
        return np.eye(3), ["x (m)", "y (m)", "z (m)"], "+z"
    centred = points - points.mean(axis=0)
    up = np.linalg.eigh(centred.T @ centred)[1][:, 0]
    if normals is not None and len(normals):
        up = up if float(np.mean(normals @ up)) >= 0 else -up
    else:
        up = up if up[np.argmax(np.abs(up))] >= 0 else -up
    names = "xyz"
    k = int(np.argmax(np.abs(up)))
    if abs(up[k]) > np.cos(np.radians(10.0)):
        first, second = (k + 1) % 3, (k + 2) % 3  # e_first x e_second = e_k
        unit = np.eye(3)
        if up[k] > 0:
            rows = np.array([unit[first], unit[second], unit[k]])
            return rows, [f"{names[i]} (m)" for i in (first, second, k)], f"+{names[k]}"
        rows = np.array([unit[second], unit[first], -unit[k]])
        labels = [f"{names[second]} (m)", f"{names[first]} (m)", f"-{names[k]} (m)"]
        return rows, labels, f"-{names[k]}"
    across = np.eye(3)[int(np.argmin(np.abs(up)))]
    across = across - (across @ up) * up
    across /= np.linalg.norm(across)
    rows = np.array([across, np.cross(up, across), up])
    return rows, ["x' (m)", "y' (m)", "up (m)"], "the main plane's normal"


def _poses_between(
    result: AlignResult, start: np.ndarray, steps: int, model_points: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The iterations drawn between the start and the end (about ``steps`` of them, as
    indices and poses) and the path of the model's centroid through every pose."""
    history = [np.asarray(step.T_scene_model) for step in result.history]
    final = np.asarray(result.T_scene_model)
    picks = np.unique(np.linspace(0, len(history) - 1, steps + 2).round().astype(int))[1:-1]
    between = [history[i] for i in picks] if len(history) > 2 else []
    centroid = model_points.mean(axis=0)
    path_points = np.array([_moved(centroid[None], T)[0] for T in [start, *history, final]])
    return picks, between, path_points


def _two_panel_figure(title: str | None) -> tuple[Any, Any, Any]:
    """A figure with a 3D view (drawn in order: the model over the scene) and a 2D view."""
    figure = _new_figure(13.0, 6.2)
    figure.get_layout_engine().set(w_pad=0.2)
    view3d = figure.add_subplot(1, 2, 1, projection="3d")
    view3d.computed_zorder = False  # draw in order: the model over the scene
    view2d = figure.add_subplot(1, 2, 2)
    if title:
        figure.suptitle(title)
    return figure, view3d, view2d


def render_alignment(
    model: PointCloud | np.ndarray,
    scene: PointCloud | np.ndarray,
    result: AlignResult,
    path: str | os.PathLike[str],
    initial_T: np.ndarray | None = None,
    *,
    title: str | None = None,
    max_points: int = 3000,
    steps: int = 4,
) -> None:
    """Draw the model moving onto the scene (the paper's Fig. 1), without a display.

    Two panels: a 3D view and a top view, both of the region around the model's poses
    with equal scaling on all axes. "Up" is the normal of the scene's main plane (a
    table), so a scan in camera coordinates is shown upright. The scene is grey, the
    model red at its initial pose, faint orange at a few intermediate iterations and
    green at the final pose; a black line follows the model's centroid.

    Parameters
    ----------
    model, scene : PointCloud or ndarray (N, 3)
        The clouds given to :func:`spectral_vs.align`, in model and scene coordinates.
        The scene's normals, if any, tell up from down.
    result : AlignResult
        Output of :func:`spectral_vs.align`.
    path : str or PathLike
        Image file to write; the format follows the extension.
    initial_T : ndarray (4, 4), optional
        ``T_scene_model`` the model starts from; identity when omitted (the model drawn
        where its coordinates put it).
    title : str, optional
        Title above the panels.
    max_points : int
        At most this many model points are drawn per pose, twice as many scene points.
    steps : int
        Number of intermediate poses drawn from ``result.history``.
    """
    rng = np.random.default_rng(0)
    model_points = _subsample(_points(model), max_points, rng)
    scene_points = _points(scene)
    start = np.eye(4) if initial_T is None else np.asarray(initial_T, dtype=float)
    final = np.asarray(result.T_scene_model)
    picks, between, path_points = _poses_between(result, start, steps, model_points)
    initial = _moved(model_points, start)
    aligned = _moved(model_points, final)
    size = float(np.max(np.ptp(model_points, axis=0)))

    # Up from the scene around the model's first and last pose, then the view in that frame.
    poses = [initial, aligned, path_points]
    rows, labels, up_name = _upright_frame(scene, scene_points, poses, size)

    def display(points: np.ndarray) -> np.ndarray:
        return points @ rows.T

    middle, half = _view_box([display(initial), display(aligned), display(path_points)], size)
    shown = display(scene_points)
    shown = _subsample(shown[np.all(np.abs(shown - middle) <= half, axis=1)], 2 * max_points, rng)

    figure, view3d, view2d = _two_panel_figure(title)

    def draw(points: np.ndarray, **style: Any) -> None:
        points = display(points)
        view3d.scatter(points[:, 0], points[:, 1], points[:, 2], depthshade=False, **style)
        view2d.scatter(points[:, 0], points[:, 1], **style)

    view3d.scatter(
        *shown.T,
        s=1.5,
        color=_SCENE_COLOR,
        alpha=0.5,
        depthshade=False,
        label=f"scene ({len(scene_points)} points)",
    )
    view2d.scatter(shown[:, 0], shown[:, 1], s=1.5, color=_SCENE_COLOR, alpha=0.5)
    draw(initial, s=2, color=_INITIAL_COLOR, alpha=0.8, label="model, initial pose")
    for i, T in enumerate(between):
        label = f"iterations {', '.join(str(p + 1) for p in picks)}" if i == 0 else None
        draw(_moved(model_points, T), s=1, color=_STEP_COLOR, alpha=0.2, label=label)
    draw(aligned, s=2, color=_FINAL_COLOR, alpha=0.6, label="model, final pose")
    path_shown = display(path_points)
    style = {"color": _PATH_COLOR, "markersize": 2.5, "linewidth": 1.2}
    view3d.plot(*path_shown.T, "o-", label="path of the model centroid", **style)
    view2d.plot(path_shown[:, 0], path_shown[:, 1], "o-", **style)

    _frame_views(view3d, view2d, (middle, half), labels, up_name)
    figure.savefig(path)


def _upright_frame(
    scene: PointCloud | np.ndarray,
    scene_points: np.ndarray,
    model_poses: list[np.ndarray],
    size: float,
) -> tuple[np.ndarray, list[str], str]:
    """The display frame (_display_frame) from the scene in the view box (_view_box, of
    ``size``) around the model's poses: up is the normal of the scene's main plane there."""
    middle, half = _view_box(model_poses, size)
    near = np.linalg.norm(scene_points - middle, axis=1) <= half
    normals = None
    if isinstance(scene, PointCloud) and scene.has_normals:
        normals = np.asarray(scene.normals)[near]
    return _display_frame(scene_points[near], normals)


def _frame_views(
    view3d: Any,
    view2d: Any,
    box: tuple[np.ndarray, float],
    labels: list[str],
    up_name: str,
) -> None:
    """Limits, labels and titles of both views over the cube ``box`` (middle, half-width)."""
    middle, half = box
    for i, axis in enumerate("xyz"):
        getattr(view3d, f"set_{axis}lim")(middle[i] - half, middle[i] + half)
        getattr(view3d, f"set_{axis}label")(labels[i])
    view3d.set_box_aspect((1, 1, 1))
    view3d.view_init(elev=25, azim=-60)
    view3d.set_title(f"3D view, up = {up_name}")
    view2d.set_xlim(middle[0] - half, middle[0] + half)
    view2d.set_ylim(middle[1] - half, middle[1] + half)
    view2d.set_aspect("equal")
    view2d.set_xlabel(labels[0])
    view2d.set_ylabel(labels[1])
    view2d.set_title(f"top view, seen from {up_name}")
    view2d.grid(True, alpha=0.3)
    legend = view3d.legend(loc="upper left", fontsize="small", markerscale=4)
    for handle in legend.legend_handles:
        handle.set_alpha(1.0)


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
