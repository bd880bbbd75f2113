"""``spectral-vs align``: a model cloud onto a scene cloud, from files."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs.cli.align_output import json_report, print_result
from spectral_vs.cli.common import (
    CLOUD_SUFFIXES,
    Progress,
    _check_output,
    _count,
    _plotting,
    _positive_float,
    _positive_int,
    _write,
    add_check_arguments,
    add_report_arguments,
    add_save_aligned,
    add_sensor_origin,
    check_paths,
    ground_truth_errors,
    load_clouds,
    read_transform,
    save_moved,
    sensor_origin_of,
)
from spectral_vs.registration import derived_voxel_size, prepare

ALIGN_DESCRIPTION = """\
Find the rigid transform T_scene_model that moves MODEL onto where the same object lies
in SCENE, without point correspondences: rotation from the Extended Gaussian Images
(normals on the sphere) correlated on SO(3), translation from the 3D phase correlation
of voxel grids (Algorithm 1 of "3D Spectral Domain Registration-Based Visual Servoing").

T_scene_model is a 4x4 matrix [R t; 0 0 0 1] that maps a point p of the model, in model
coordinates, to R p + t in scene coordinates. Units: metres (clouds, --voxel-size, t),
degrees and millimetres for the errors against --ground-truth.

The voxel is derived from the clouds (their extent and point spacing) unless
--voxel-size gives it. Both clouds are downsampled to half a voxel; normals are read from
the files when they have them, otherwise estimated (radius 2 voxels) and turned toward
--sensor-origin, the sensor's position (the origin for a scan in camera coordinates). A
scene that is a single view from there (a depth camera's cloud) is detected and its
hypotheses are checked against what the sensor saw (--scene-view).

Every answer carries its verdict (docs/trust.md): "reliable" (its calibrated confidence
is at least svs.RELIABLE_CONFIDENCE and no other pose fits as well), "ambiguous" (other
poses, listed as alternatives, fit about as well: a symmetric object), "doubtful",
"floating" (in a view of a table, the pose neither rests on it nor stands on anything;
--may-float for an object held above it), "undetermined", "no_support", "max_seconds" or
"bad_scale" (a voxel out of range of the model's size).

Exit code: 0 when the answer is reliable (and within the error limits when a ground truth
is given), 1 when it is not (the reason is printed), 2 on bad input."""

ALIGN_EPILOG = """\
example:
  spectral-vs align milk.pcd scene.pcd --voxel-size 0.008 --plot convergence.png \\
      --render alignment.png --save-aligned milk_in_scene.ply
  spectral-vs align model.ply scene.ply --ground-truth T_true.txt --json

A transform file (--initial-guess, --ground-truth) holds 4 lines of 4 numbers, or a
(4, 4) array saved with numpy.save (.npy)."""


def add_parser(commands: Any, formatter: Any) -> None:
    """Add the subcommand to ``commands``, the parser's subparsers."""
    align = commands.add_parser(
        "align",
        help="align a model cloud onto a scene cloud (rotation and translation)",
        description=ALIGN_DESCRIPTION,
        epilog=ALIGN_EPILOG,
        formatter_class=formatter,
    )
    align.add_argument(
        "model", type=Path, metavar="MODEL", help="cloud of the object (.pcd or .ply)"
    )
    align.add_argument(
        "scene", type=Path, metavar="SCENE", help="cloud to find it in (.pcd or .ply)"
    )
    settings = align.add_argument_group("alignment settings")
    _add_search_settings(settings)
    _add_start_settings(settings)
    add_check_arguments(
        align.add_argument_group("checking against a known answer"),
        "true T_scene_model: prints the rotation error (degrees) and the translation error "
        "(mm, at the model's centroid)",
    )
    _add_output_arguments(align.add_argument_group("output"))
    align.set_defaults(run=run_align)


def _add_search_settings(settings: Any) -> None:
    """The grid, the bandwidth and the search: --voxel-size to --refinement-iterations."""
    settings.add_argument(
        "--voxel-size",
        type=_positive_float,
        metavar="M",
        help="voxel edge of the translation grid, metres (default: derived from the clouds, "
        "spectral_vs.alignment_voxel_size)",
    )
    settings.add_argument(
        "--bandwidth",
        type=_positive_int,
        default=16,
        metavar="B",
        help="EGI bandwidth: spherical harmonics of degree < B (default: 16)",
    )
    settings.add_argument(
        "--paper",
        action="store_true",
        help="the paper's Algorithm 1 alone: local ascent from --initial-guess without "
        "the global rotation search (faster; needs a close initial guess)",
    )
    settings.add_argument(
        "--hypotheses",
        type=_positive_int,
        metavar="N",
        help="rotations of the global search that are placed and verified "
        f"(default: {svs.AlignParams().hypotheses})",
    )
    settings.add_argument(
        "--max-iterations",
        type=_positive_int,
        metavar="N",
        help="iterations of Algorithm 1 in the paper's mode "
        f"(default: {svs.AlignParams().max_iterations})",
    )
    settings.add_argument(
        "--refinement-iterations",
        type=_positive_int,
        metavar="N",
        help="with global search: iterations of Algorithm 1 per refined hypothesis "
        f"(default: {svs.AlignParams().refinement_iterations})",
    )


def _add_start_settings(settings: Any) -> None:
    """The threads, the start and the normals' viewpoint."""
    settings.add_argument(
        "--threads",
        type=_positive_int,
        default=1,
        metavar="N",
        help="threads for the FFTs and the search (default: 1)",
    )
    settings.add_argument(
        "--initial-guess",
        type=Path,
        metavar="FILE",
        help="T_scene_model to start --paper from (the global search ignores its rotation)",
    )
    add_sensor_origin(
        settings,
        "the scene's sensor: estimated normals face it and a single view is detected from it",
    )
    settings.add_argument(
        "--scene-view",
        choices=("auto", "single_view", "all_sides"),
        default="auto",
        help="the scene as a single view from --sensor-origin (checked against what it "
        "saw), seen from all sides (a full model, a fused map), or auto: detected "
        "(default: auto)",
    )
    settings.add_argument(
        "--may-float",
        action="store_true",
        help="the object may hang above the table (held in a gripper): a pose that neither "
        "rests on the scene's support plane nor stands on anything is not 'floating' "
        "(expect_resting=False)",
    )


def _add_output_arguments(output: Any) -> None:
    """What is printed and written."""
    add_report_arguments(
        output,
        "transform, verdict, confidence, covariance, inliers, alternatives, voxel, time, errors",
    )
    output.add_argument(
        "--plot",
        type=Path,
        metavar="PNG",
        help="write the per-iteration costs and gradients (needs matplotlib)",
    )
    output.add_argument(
        "--render",
        type=Path,
        metavar="PNG",
        help="write a picture of the model moving onto the scene (needs matplotlib)",
    )
    add_save_aligned(output, "MODEL moved by T_scene_model")


def run_align(args: argparse.Namespace) -> int:
    """Align MODEL onto SCENE and report the pose (and its error against a ground truth)."""
    progress = Progress(not (args.quiet or args.json))
    _check_paths(args)
    plotting: Any = (
        _plotting("--plot" if args.plot else "--render") if (args.plot or args.render) else None
    )
    initial = read_transform(args.initial_guess, "--initial-guess") if args.initial_guess else None
    truth = read_transform(args.ground_truth, "--ground-truth") if args.ground_truth else None

    timings: dict[str, float] = {}
    (model, scene), timings["load"] = load_clouds(
        progress, args, (("model", "model"), ("scene", "scene"))
    )

    settings = derived_voxel_size(_settings(args, initial), model, scene)
    origin = np.asarray(settings.sensor_origin)

    start = time.perf_counter()
    with progress.stage("downsampling and estimating normals") as notes:
        model_ready = prepare(model, "model", settings.voxel_size, True, origin)
        scene_ready = prepare(scene, "scene", settings.voxel_size, True, origin)
        notes.append(f"{len(model_ready)} and {len(scene_ready)} points")
    timings["prepare"] = time.perf_counter() - start

    mode = (
        f"global search over {settings.hypotheses} hypotheses"
        if settings.global_search
        else "local, from the initial guess"
    )
    start = time.perf_counter()
    voxel = f"{1000 * settings.voxel_size:.3g} mm voxels"
    if args.voxel_size is None:
        voxel += " (derived)"
    with progress.stage(f"aligning ({voxel}, {mode})") as notes:
        result = svs.align(model_ready, scene_ready, settings, downsample=False)
        notes.append(_count(result.iterations, "iteration"))
    timings["align"] = time.perf_counter() - start

    T = np.asarray(result.T_scene_model)
    center = np.asarray(model.centroid())
    errors, within = ground_truth_errors(args, T, truth, center)
    passed = bool(result.reliable) and within

    save_moved(progress, args.save_aligned, model, T)
    clouds = (model_ready, scene_ready)
    _write_figures(args, progress, plotting, clouds, result, settings, truth, center)

    if args.json:
        summary = json_report(result, settings, timings, (len(model), len(scene)), errors)
        summary["passed"] = passed
        print(json.dumps(summary, indent=2))
        return 0 if passed else 1
    print_result(args, result, timings, errors)
    return 0 if passed else 1


def _check_paths(args: argparse.Namespace) -> None:
    """The input files exist and the outputs have a known suffix."""
    check_paths(args, ("model", "scene"))
    _check_output(args.plot, "--plot", (".png", ".pdf", ".svg"))
    _check_output(args.render, "--render", (".png", ".pdf", ".svg"))
    _check_output(args.save_aligned, "--save-aligned", CLOUD_SUFFIXES)


def _settings(args: argparse.Namespace, initial: np.ndarray | None) -> svs.AlignParams:
    """The AlignParams of the command line."""
    settings = svs.AlignParams()
    settings.voxel_size = 0.0 if args.voxel_size is None else args.voxel_size
    settings.sensor_origin = sensor_origin_of(args)
    settings.scene_view = args.scene_view
    settings.expect_resting = not args.may_float
    settings.bandwidth = args.bandwidth
    settings.global_search = not args.paper
    settings.threads = args.threads
    if args.hypotheses is not None:
        settings.hypotheses = args.hypotheses
    if args.max_iterations is not None:
        settings.max_iterations = args.max_iterations
    if args.refinement_iterations is not None:
        settings.refinement_iterations = args.refinement_iterations
    if initial is not None:
        settings.initial_guess = initial
    return settings


def _write_figures(
    args: argparse.Namespace,
    progress: Progress,
    plotting: Any,
    clouds: tuple[svs.PointCloud, svs.PointCloud],
    result: svs.AlignResult,
    settings: svs.AlignParams,
    truth: np.ndarray | None,
    center: np.ndarray,
) -> None:
    """--plot and --render; ``clouds``: the model and the scene as aligned, ``center``:
    the model's centroid, where the translation error is measured."""
    if args.plot:
        with progress.stage(f"plotting {args.plot}"):
            _write(
                args.plot,
                plotting.plot_convergence,
                result,
                title=f"{args.model.name} onto {args.scene.name}",
                tolerance=settings.tolerance,
                voxel_size=settings.voxel_size,
                ground_truth=truth,
                center=center,
                initial_T=np.asarray(settings.initial_guess),
            )
    if args.render:
        with progress.stage(f"rendering {args.render}"):
            _write(
                args.render,
                plotting.render_alignment,
                clouds[0],
                clouds[1],
                result,
                initial_T=np.asarray(settings.initial_guess),
                title=f"{args.model.name} onto {args.scene.name}",
            )
