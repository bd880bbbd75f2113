"""``spectral-vs demo``: the milk carton and a synthetic scene aligned against their known
poses, and the phase correlation's translation."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs.cli.common import (
    DEFAULT_DATA,
    MAX_ROTATION_ERROR,
    MAX_TRANSLATION_ERROR,
    InputError,
    Progress,
    _count,
    _duration,
    _errors,
    _plotting,
    _positive_float,
    _positive_int,
    _seed,
    _translation,
    _within,
    _write,
    describe_transform,
    read_cloud,
    rotation_about,
    verdict_line,
)
from spectral_vs.cli.translate import estimate_translation
from spectral_vs.data import MILK_MODEL, MILK_SCENE, milk_split, synthetic_scene
from spectral_vs.registration import prepare

#: How the run that produced the returned pose ended (``AlignResult.stop_reason``), in words.
STOP_REASONS = {
    "converged": "converged",
    "max_iterations": "iteration limit",
    "max_seconds": "time budget",
    "kept_start": "the search's hypothesis kept: Algorithm 1 from it ended less fit",
    "reselected": "an alternative the scene supports clearly better returned instead",
}


def add_parser(commands: Any, formatter: Any) -> None:
    """Add the subcommand to ``commands``, the parser's subparsers."""
    demo = commands.add_parser(
        "demo",
        help="move a scanned object by a known transform and align it back onto its scene",
        description="Cut a milk carton's scan in two disjoint samples (model and scene), move "
        "the model by a known rotation and shift, align it back with a global search, print "
        "the errors and write convergence.png and alignment.png. Without the scans a generated "
        "table-top scene is used. Exit code 1 when the error exceeds "
        f"{MAX_ROTATION_ERROR:g} degrees or {MAX_TRANSLATION_ERROR:g} mm.",
    )
    demo.add_argument(
        "--data",
        type=Path,
        default=DEFAULT_DATA,
        help=f"folder holding {MILK_MODEL} and {MILK_SCENE} (default: {DEFAULT_DATA})",
    )
    demo.add_argument(
        "--output",
        type=Path,
        default=Path("results/demo"),
        metavar="DIR",
        help="folder for the figures (default: results/demo)",
    )
    demo.add_argument(
        "--voxel-size",
        type=_positive_float,
        default=0.008,
        metavar="M",
        help="voxel edge in metres (default: 0.008)",
    )
    demo.add_argument(
        "--angle",
        type=float,
        default=120.0,
        metavar="DEG",
        help="rotation applied to the model, degrees (default: 120)",
    )
    demo.add_argument(
        "--axis",
        type=float,
        nargs=3,
        default=(1.0, 1.0, 0.5),
        metavar=("X", "Y", "Z"),
        help="axis of that rotation (default: 1 1 0.5)",
    )
    demo.add_argument(
        "--shift",
        type=float,
        nargs=3,
        default=(0.10, -0.08, 0.08),
        metavar=("X", "Y", "Z"),
        help="shift applied to the model, metres (default: 0.10 -0.08 0.08)",
    )
    demo.add_argument(
        "--threads",
        type=_positive_int,
        default=os.cpu_count() or 1,
        metavar="N",
        help="threads (default: all cores)",
    )
    demo.add_argument(
        "--synthetic", action="store_true", help="use the generated scene even if the scans exist"
    )
    demo.add_argument(
        "--seed", type=_seed, default=0, help="seed of the generated scene (default: 0)"
    )
    demo.add_argument(
        "--check",
        action="store_true",
        help="exit with status 1 when the answer is not reliable or misses 5 deg / 10 mm "
        "(default: report only)",
    )
    demo.add_argument(
        "--translation-only",
        action="store_true",
        help="only recover a translation of the carton by phase correlation",
    )
    demo.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    demo.set_defaults(run=run_demo)


def run_alignment_demo(args: argparse.Namespace) -> int:
    """Move an object's cloud by a known transform and align it back onto a cluttered scene."""
    progress = Progress(not args.quiet)
    try:
        plotting: Any = _plotting("demo")
    except InputError as error:
        plotting = None
        print(f"no figures: {error.__cause__}")
    voxel = args.voxel_size
    model, scene, name = _demo_clouds(args, progress, voxel)

    # The model leaves its place in the scene: a rotation about its centroid and a shift.
    center = np.asarray(model.centroid())
    moved = np.eye(4)
    moved[:3, :3] = rotation_about(args.axis, args.angle)
    moved[:3, 3] = center - moved[:3, :3] @ center + np.asarray(args.shift)
    model = model.transformed(moved)
    truth = np.linalg.inv(moved)
    print(
        f"model moved by {args.angle:g} deg about {np.round(args.axis, 2).tolist()} "
        f"(through its centroid) and {1000 * np.linalg.norm(args.shift):.0f} mm"
    )

    settings = svs.AlignParams()
    settings.voxel_size = voxel
    settings.threads = args.threads
    start = time.perf_counter()
    with progress.stage(
        f"aligning ({1000 * voxel:g} mm voxels, global search, {args.threads} threads)"
    ):
        result = svs.align(model, scene, settings, downsample=False)
    elapsed = time.perf_counter() - start

    T = np.asarray(result.T_scene_model)
    errors = _errors(T, truth, np.asarray(model.centroid()))
    limits = (MAX_ROTATION_ERROR, MAX_TRANSLATION_ERROR)
    print(f"true      T_scene_model: {describe_transform(truth)}")
    print(f"estimated T_scene_model: {describe_transform(T)}")
    verdict = "ok" if _within(errors, limits) else "FAILED"
    print(
        f"error: rotation {errors[0]:.2f} deg, translation {errors[1]:.1f} mm at the model "
        f"centroid ({verdict}; limits {limits[0]:g} deg, {limits[1]:g} mm)"
    )
    print(
        f"Algorithm 1: {_count(result.iterations, 'iteration')} "
        f"({STOP_REASONS[result.stop_reason]}), {_count(result.icp_iterations, 'ICP step')}; "
        f"fitness {result.fitness:.3f}, correlation {result.correlation:.3f}, "
        f"{_duration(elapsed)}"
    )
    print(verdict_line(result))

    # With --check the demo passes only on a reliable answer within the limits: a right
    # pose whose verdict is not reliable is not one a robot could act on.
    status = 0 if not args.check or (result.reliable and _within(errors, limits)) else 1
    if plotting is None:
        return status
    convergence = args.output / "convergence.png"
    alignment = args.output / "alignment.png"
    with progress.stage(f"writing {convergence} and {alignment.name}"):
        title = f"{name}: {args.angle:g} deg, {1000 * voxel:g} mm voxels"
        run, run_start, note = _convergence_run(model, scene, settings, result, args.axis)
        _write(
            convergence,
            plotting.plot_convergence,
            run,
            title=title + note,
            tolerance=settings.tolerance,
            voxel_size=voxel,
            ground_truth=truth,
            center=np.asarray(model.centroid()),
            initial_T=run_start,
        )
        _write(alignment, plotting.render_alignment, model, scene, result, title=title)
    print(f"wrote {convergence} and {alignment}")
    return status


#: How far the convergence figure's run starts from the result when the search kept its
#: hypothesis, degrees: inside the local controller's basin (docs/alignment.md).
CONVERGENCE_START_DEG = 20.0


def _convergence_run(
    model: Any, scene: Any, settings: Any, result: Any, axis: Any
) -> tuple[Any, np.ndarray | None, str]:
    """The run the convergence figure draws, its start and a note for its title: the
    returned pose's Algorithm 1 run; or, where the search kept its hypothesis (a pose with
    no run of its own), the paper's Algorithm 1 (no global search) from the result turned
    CONVERGENCE_START_DEG about ``axis`` through the model's centroid, so that the figure
    shows the local controller converging as the paper's Fig. 3 and 5 do."""
    if result.history:
        return result, None, ""
    T = np.asarray(result.T_scene_model, dtype=float)
    centre = T[:3, :3] @ np.asarray(model.centroid()) + T[:3, 3]
    turn = rotation_about(axis, CONVERGENCE_START_DEG)
    start = np.eye(4)
    start[:3, :3] = turn @ T[:3, :3]
    start[:3, 3] = turn @ (T[:3, 3] - centre) + centre
    local = svs.AlignParams(
        voxel_size=settings.voxel_size, threads=settings.threads, global_search=False
    )
    local.initial_guess = start
    note = f"; Algorithm 1 from the result turned {CONVERGENCE_START_DEG:g} deg"
    return svs.align(model, scene, local, downsample=False), start, note


def _demo_clouds(
    args: argparse.Namespace, progress: Progress, voxel: float
) -> tuple[svs.PointCloud, svs.PointCloud, str]:
    """The demo's model and scene, with normals, and the case's name: disjoint samples of
    the milk carton's Kinect scan when the data folder has it, else a generated scene."""
    have_scans = (args.data / MILK_MODEL).is_file() and (args.data / MILK_SCENE).is_file()
    if have_scans and not args.synthetic:
        with progress.stage("loading the Kinect scans") as notes:
            carton = read_cloud(args.data / MILK_MODEL, "--data")
            full_scene = read_cloud(args.data / MILK_SCENE, "--data")
            notes.append(f"{len(carton)} and {len(full_scene)} points")
        with progress.stage("splitting into disjoint samples"):
            try:
                model_points, scene_points = milk_split(carton, full_scene)
            except ValueError as error:
                raise InputError(f"--data: {error}") from error
        print(f"scene: {MILK_SCENE} (Kinect, milk carton among clutter), {len(full_scene)} points")
        print(
            f"model: {MILK_MODEL}, cut out of that scan; disjoint samples: the model keeps "
            f"{len(model_points)} of its {len(carton)} points, the scene {len(scene_points)} "
            "points, 0 shared"
        )
        with progress.stage("estimating normals") as notes:
            # A model is stored with its normals: estimate them before the model is moved.
            model = prepare(svs.PointCloud(model_points), "model", voxel, True, (0.0, 0.0, 0.0))
            scene = prepare(svs.PointCloud(scene_points), "scene", voxel, True, (0.0, 0.0, 0.0))
            notes.append(f"{len(model)} and {len(scene)} points after downsampling")
        name = "milk carton in the Kinect scene"
    else:
        if not args.synthetic:
            print(f"no {MILK_MODEL} and {MILK_SCENE} in {args.data}: using a generated scene")
        with progress.stage("generating a table-top scene"):
            model, scene = synthetic_scene(args.seed)
        print(
            f"scene: generated table top with three boxes, {len(scene)} points, 1 mm noise; "
            f"model: the box with a ball, sampled independently, {len(model)} points"
        )
        name = "box with ball in a generated scene"
    return model, scene, name


def run_translation_demo(args: argparse.Namespace) -> int:
    """Recover a known translation of the real Kinect scan of a milk carton."""
    path = args.data / MILK_MODEL
    if not path.is_file():
        raise InputError(f"--data: {path} not found; pass --data DIR holding {MILK_MODEL}")
    milk = svs.load_cloud(path)
    t_true = np.array([0.0373, -0.0218, 0.0124])
    # Disjoint samples (even and odd points) so the two clouds share no point.
    moving = svs.PointCloud(milk.points[0::2])
    target = svs.PointCloud(milk.points[1::2]).transformed(_translation(t_true))
    start = time.perf_counter()
    estimate, spec = estimate_translation(moving, target, args.voxel_size)
    elapsed = time.perf_counter() - start
    error_mm = 1000 * np.linalg.norm(np.asarray(estimate.shift) - t_true)
    print(f"milk carton scan: {len(milk)} points, split into two disjoint halves")
    print(f"grid: {' x '.join(map(str, spec.dims))} voxels of {1000 * spec.resolution:.0f} mm")
    print(f"true translation      [mm]: {np.array2string(1000 * t_true, precision=2)}")
    shift_mm = 1000 * np.asarray(estimate.shift)
    print(f"estimated translation [mm]: {np.array2string(shift_mm, precision=2)}")
    print(
        f"error: {error_mm:.2f} mm, correlation peak {estimate.peak:.3f}, {1000 * elapsed:.1f} ms"
    )
    return 0 if error_mm < args.voxel_size * 1000 / 2 else 1


def run_demo(args: argparse.Namespace) -> int:
    if args.translation_only:
        return run_translation_demo(args)
    return run_alignment_demo(args)
