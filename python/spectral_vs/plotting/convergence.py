"""An alignment's convergence: costs, gradients and errors per iteration (the paper's
Fig. 3 and 5)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from spectral_vs._core import AlignParams, AlignResult
from spectral_vs.plotting._common import (
    _new_figure,
    _set_scale,
)
from spectral_vs.poses import pose_error


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
