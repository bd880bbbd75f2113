"""The model's path onto the scene, in 3D and from above (the paper's Fig. 1)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from spectral_vs._core import AlignResult, PointCloud
from spectral_vs.plotting._common import (
    _FINAL_COLOR,
    _INITIAL_COLOR,
    _PATH_COLOR,
    _SCENE_COLOR,
    _STEP_COLOR,
    _moved,
    _new_figure,
    _points,
    _subsample,
    _view_box,
)


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
