"""What ``spectral-vs align`` prints of a result: the text (:func:`print_result`) and the
``--json`` report (:func:`json_report`)."""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs.cli.common import (
    _count,
    _duration,
    covariance_report,
    error_report,
    print_errors,
    print_transform,
    verdict_line,
)


def json_report(
    result: svs.AlignResult,
    settings: svs.AlignParams,
    timings: dict[str, float],
    points: tuple[int, int],
    errors: tuple[float, float] | None,
) -> dict[str, Any]:
    """The --json report, without "passed"; ``points``: of the model and the scene read."""
    report: dict[str, Any] = {
        "T_scene_model": np.asarray(result.T_scene_model).tolist(),
        "converged": bool(result.converged),
        "stop_reason": result.stop_reason,
        "iterations": int(result.iterations),
        "fitness": float(result.fitness),
        "correlation": float(result.correlation),
        "translation_peak": float(result.translation_peak),
        "hypothesis": int(result.hypothesis),
        "reliable": bool(result.reliable),
        "status": result.status,
        "rests": bool(result.rests),
        "confidence": float(result.confidence),
        "score": float(result.score),
        **covariance_report(result.covariance),
        "inliers": int(result.inliers),
        "inlier_fraction": float(result.inlier_fraction),
        "inlier_rmse_mm": 1000 * float(result.inlier_rmse),
        "inlier_distance_mm": 1000 * float(result.inlier_distance),
        "ambiguous": bool(result.ambiguous),
        "alternatives": [_alternative(a) for a in result.alternatives],
        "single_view": bool(result.single_view),
        "time_s": timings["align"],
        "timings_s": timings,
        "voxel_size_m": float(result.voxel_size),
        "model_points": points[0],
        "scene_points": points[1],
        **error_report(errors),
    }
    return report


def _alternative(alternative: svs.AlignAlternative) -> dict[str, Any]:
    return {
        "T_scene_model": np.asarray(alternative.T_scene_model).tolist(),
        "confidence": float(alternative.confidence),
        "score": float(alternative.score),
        "inliers": int(alternative.inliers),
        "inlier_rmse_mm": 1000 * float(alternative.inlier_rmse),
        "rotation_apart_deg": math.degrees(alternative.rotation_apart),
        "translation_apart_mm": 1000 * float(alternative.translation_apart),
    }


def print_result(
    args: argparse.Namespace,
    result: svs.AlignResult,
    timings: dict[str, float],
    errors: tuple[float, float] | None,
) -> None:
    """The pose, the state and the errors, as text."""
    print_transform(
        "T_scene_model (moves MODEL coordinates into the SCENE frame, metres):",
        np.asarray(result.T_scene_model),
    )
    ending = "ended normally" if result.converged else f"stopped ({result.stop_reason})"
    print(
        f"search {ending}, {_count(result.iterations, 'iteration')} of Algorithm 1, fitness "
        f"{result.fitness:.3f}, correlation {result.correlation:.3f}, "
        f"{1000 * result.voxel_size:.3g} mm voxels, {_duration(timings['align'])}"
    )
    print(verdict_line(result))
    deviations = covariance_report(result.covariance)
    print(
        f"{result.inliers} inliers within {1000 * result.inlier_distance:.3g} mm "
        f"({100 * result.inlier_fraction:.0f}% of the model), RMSE "
        f"{1000 * result.inlier_rmse:.2f} mm; standard deviation "
        f"{max(deviations['rotation_std_deg']):.2g} deg, "
        f"{max(deviations['translation_std_mm']):.2g} mm"
        + (", single view" if result.single_view else "")
    )
    print_errors(args, errors, "the model centroid")
