"""``spectral-vs align-views``: two views of one scene registered globally, from files."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs.cli.common import (
    CLOUD_SUFFIXES,
    Progress,
    _check_output,
    _duration,
    _positive_float,
    _positive_int,
    add_check_arguments,
    add_report_arguments,
    add_save_aligned,
    add_sensor_origin,
    check_paths,
    covariance_report,
    error_report,
    ground_truth_errors,
    load_clouds,
    print_errors,
    print_transform,
    read_transform,
    save_moved,
    verdict_line,
)

DESCRIPTION = """\
Register REFERENCE onto CURRENT, two views of one scene that overlap in part (two depth
frames, each in its camera's coordinates), over every rotation and the translations
within the views: the EGIs correlated on SO(3), the voxel grids by phase correlation,
each hypothesis checked against what the current sensor saw (docs/views.md).

T_current_reference is a 4x4 matrix [R t; 0 0 0 1] that maps a point of REFERENCE to
R p + t in CURRENT's coordinates: for two camera frames, the reference camera's pose in
the current camera's frame. Units: metres; every length (voxel, search voxel) is derived
from the views unless given.

Every answer carries its verdict (docs/trust.md): "reliable" (its calibrated confidence
is at least svs.RELIABLE_CONFIDENCE and no other pose fits as well), "ambiguous",
"doubtful", "no_support" (the views share nothing, or too little to find it),
"max_seconds" or "bad_scale".

Exit code: 0 when the answer is reliable (and within the error limits when a ground truth
is given), 1 when it is not (the reason is printed), 2 on bad input."""

EPILOG = """\
example:
  spectral-vs align-views frame_000.pcd frame_030.pcd --json
  spectral-vs align-views ref.ply cur.ply --ground-truth T_cur_ref.txt \\
      --save-aligned ref_in_cur.ply

A transform file (--ground-truth, --prior) holds 4 lines of 4 numbers, or a (4, 4) array
saved with numpy.save (.npy)."""


def add_parser(commands: Any, formatter: Any) -> None:
    """Add the subcommand to ``commands``, the parser's subparsers."""
    views = commands.add_parser(
        "align-views",
        help="register two views of one scene (two depth frames) onto each other",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter,
    )
    views.add_argument(
        "reference", type=Path, metavar="REFERENCE", help="the view to move (.pcd or .ply)"
    )
    views.add_argument(
        "current", type=Path, metavar="CURRENT", help="the view to move it onto (.pcd or .ply)"
    )
    settings = views.add_argument_group("registration settings")
    defaults = svs.ViewAlignParams()
    settings.add_argument(
        "--voxel-size",
        type=_positive_float,
        metavar="M",
        help="voxel edge of the fine grids, metres (default: derived from the views)",
    )
    settings.add_argument(
        "--hypotheses",
        type=_positive_int,
        metavar="N",
        help=f"rotations of the search placed and checked (default: {defaults.hypotheses})",
    )
    settings.add_argument(
        "--threads",
        type=_positive_int,
        default=1,
        metavar="N",
        help="threads for the FFTs and the search (default: 1)",
    )
    settings.add_argument(
        "--max-seconds",
        type=_positive_float,
        metavar="S",
        help="time budget; past it the best pose so far is returned with status "
        "max_seconds (default: none)",
    )
    settings.add_argument(
        "--prior",
        type=Path,
        metavar="FILE",
        help="a T_current_reference known from elsewhere (a tracker): refined beside the "
        "search's hypotheses and kept unless a searched pose is better supported",
    )
    add_sensor_origin(
        settings,
        "the current view's sensor: the support check sees from it and estimated normals face it",
    )
    add_sensor_origin(
        settings,
        "the reference view's sensor, which its estimated normals face",
        "--reference-sensor-origin",
    )
    add_check_arguments(
        views.add_argument_group("checking against a known answer"),
        "true T_current_reference: prints the rotation error (degrees) and the translation "
        "error (mm, at the reference's centroid)",
    )
    output = views.add_argument_group("output")
    add_report_arguments(output, "transform, status, support, scale, time, errors")
    add_save_aligned(output, "REFERENCE moved by T_current_reference")
    views.set_defaults(run=run_views)


def run_views(args: argparse.Namespace) -> int:
    """Register REFERENCE onto CURRENT and report the pose (and its error)."""
    progress = Progress(not (args.quiet or args.json))
    check_paths(args, ("reference", "current"))
    _check_output(args.save_aligned, "--save-aligned", CLOUD_SUFFIXES)
    prior = read_transform(args.prior, "--prior") if args.prior else None
    truth = read_transform(args.ground_truth, "--ground-truth") if args.ground_truth else None

    timings: dict[str, float] = {}
    (reference, current), timings["load"] = load_clouds(
        progress, args, (("reference", "reference"), ("current", "current"))
    )

    settings = _settings(args)
    origin = args.reference_sensor_origin or (0.0, 0.0, 0.0)
    start = time.perf_counter()
    with progress.stage("registering (normals, search, check, refinement)") as notes:
        result = svs.align_views(
            reference, current, settings, reference_sensor_origin=origin, prior=prior
        )
        notes.append(f"{1000 * result.scale.voxel_size:.3g} mm voxels, status {result.status}")
    timings["align"] = time.perf_counter() - start

    T = np.asarray(result.T_current_reference)
    center = np.asarray(reference.centroid())
    errors, within = ground_truth_errors(args, T, truth, center)
    passed = bool(result.reliable) and within
    save_moved(progress, args.save_aligned, reference, T)

    if args.json:
        report = _report(result, timings, (len(reference), len(current)), errors)
        report["passed"] = passed
        print(json.dumps(report, indent=2))
    else:
        _print_result(args, result, timings, errors)
    return 0 if passed else 1


def _settings(args: argparse.Namespace) -> svs.ViewAlignParams:
    """The ViewAlignParams of the command line."""
    settings = svs.ViewAlignParams()
    if args.voxel_size is not None:
        settings.voxel_size = args.voxel_size
    if args.hypotheses is not None:
        settings.hypotheses = args.hypotheses
    if args.max_seconds is not None:
        settings.max_seconds = args.max_seconds
    if args.sensor_origin is not None:
        settings.sensor_origin = args.sensor_origin
    settings.threads = args.threads
    return settings


def _report(
    result: svs.ViewAlignResult,
    timings: dict[str, float],
    points: tuple[int, int],
    errors: tuple[float, float] | None,
) -> dict[str, Any]:
    """The --json report, without "passed"; ``points``: of the two views read."""
    support = result.support
    report: dict[str, Any] = {
        "T_current_reference": np.asarray(result.T_current_reference).tolist(),
        "reliable": bool(result.reliable),
        "status": result.status,
        "confidence": float(result.confidence),
        "score": float(result.score),
        **covariance_report(result.covariance),
        "ambiguous": bool(result.ambiguous),
        "alternatives": [
            {
                "T_current_reference": np.asarray(a.T_current_reference).tolist(),
                "confidence": float(a.confidence),
                "score": float(a.score),
            }
            for a in result.alternatives
        ],
        "inliers": int(result.inliers),
        "inlier_fraction": float(result.inlier_fraction),
        "inlier_rmse_mm": 1000 * float(result.inlier_rmse),
        "converged": bool(result.converged),
        "support_score": float(support.score),
        "fitness": float(support.fitness),
        "overlap": float(support.overlap),
        "confirmed": int(support.confirmed),
        "contradicted": int(support.contradicted),
        "hidden": int(support.hidden),
        "correlation": float(result.correlation),
        "hypothesis": int(result.hypothesis),
        "hypotheses_checked": len(result.hypotheses),
        "windows": int(result.windows),
        "voxel_size_m": float(result.scale.voxel_size),
        "search_voxel_size_m": float(result.scale.search_voxel_size),
        "extent_m": float(result.scale.extent),
        "time_s": timings["align"],
        "timings_s": timings,
        "reference_points": points[0],
        "current_points": points[1],
        **error_report(errors),
    }
    return report


def _print_result(
    args: argparse.Namespace,
    result: svs.ViewAlignResult,
    timings: dict[str, float],
    errors: tuple[float, float] | None,
) -> None:
    """The pose, the support and the errors, as text."""
    print_transform(
        "T_current_reference (moves REFERENCE coordinates into CURRENT's frame, metres):",
        np.asarray(result.T_current_reference),
    )
    support = result.support
    source = "the prior" if result.hypothesis == -1 else f"hypothesis {result.hypothesis}"
    print(verdict_line(result))
    print(
        f"support score {support.score:.3f} (fitness {support.fitness:.2f}, "
        f"overlap {support.overlap:.2f}), {source} of {len(result.hypotheses)} checked"
        + (f" ({result.windows} windows searched)" if result.windows else "")
        + f", {1000 * result.scale.voxel_size:.3g} mm voxels, {_duration(timings['align'])}"
    )
    print_errors(args, errors, "the reference's centroid")
