"""The ``spectral-vs`` command line: ``align``, ``demo`` and ``translate``."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

import numpy as np

import spectral_vs as svs
from spectral_vs.poses import pose_error
from spectral_vs.registration import prepare

DEFAULT_DATA = Path(os.environ.get("SPECTRAL_VS_DATA", "../shared/data"))
MILK_MODEL = "milk.pcd"
MILK_SCENE = "milk_cartoon_all_small_clorox.pcd"
#: Ground-truth errors above these fail a run (exit code 1): degrees, millimetres.
MAX_ROTATION_ERROR = 5.0
MAX_TRANSLATION_ERROR = 10.0
CLOUD_SUFFIXES = (".pcd", ".ply")
#: servo-sim fails (exit code 1) above these final camera pose errors: mm, degrees.
MAX_SERVO_ERROR_MM = 5.0
MAX_SERVO_ERROR_DEG = 1.0


class InputError(Exception):
    """Bad input on the command line; the message names the argument (exit code 2)."""


class Progress:
    """Stage lines with their elapsed time on stderr, e.g. ``loading scene.pcd ... 12 ms``."""

    def __init__(self, enabled: bool, stream: TextIO | None = None) -> None:
        self.enabled = enabled
        self.stream = stream if stream is not None else sys.stderr

    @contextlib.contextmanager
    def stage(self, text: str) -> Iterator[list[str]]:
        """Print ``text ...``, run the block, then the notes it appended and the time taken."""
        notes: list[str] = []
        if self.enabled:
            print(f"{text} ...", end=" ", file=self.stream, flush=True)
        start = time.perf_counter()
        try:
            yield notes
        except BaseException:
            if self.enabled:
                print("failed", file=self.stream, flush=True)
            raise
        if self.enabled:
            notes.append(_duration(time.perf_counter() - start))
            print(", ".join(notes), file=self.stream, flush=True)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _duration(seconds: float) -> str:
    return f"{1000 * seconds:.0f} ms" if seconds < 1 else f"{seconds:.1f} s"


def _translation(t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def rotation_about(axis: Any, angle_deg: float) -> np.ndarray:
    """Rotation matrix of ``angle_deg`` degrees about ``axis`` (Rodrigues' formula)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    angle = np.radians(angle_deg)
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def axis_angle(R: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle (degrees, in [0, 180]) of a rotation matrix."""
    angle = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-9:
        return np.array([0.0, 0.0, 1.0]), 0.0
    if angle < 170:
        return w / np.linalg.norm(w), angle
    # Near 180 degrees the skew part vanishes: the axis is the eigenvector of eigenvalue 1.
    values, vectors = np.linalg.eig(R)
    axis = np.real(vectors[:, np.argmin(np.abs(values - 1))])
    if w @ axis < 0:
        axis = -axis
    return axis / np.linalg.norm(axis), angle


def describe_transform(T: np.ndarray) -> str:
    """``rotation 120.0 deg about [...], translation [...] mm``."""
    axis, angle = axis_angle(np.asarray(T)[:3, :3])
    axis_text = np.array2string(axis, precision=3, suppress_small=True)
    t_text = np.array2string(1000 * np.asarray(T)[:3, 3], precision=1, suppress_small=True)
    return f"rotation {angle:6.2f} deg about {axis_text}, translation {t_text} mm"


def _strip_argument(message: str) -> str:
    """The core's I/O messages start with ``path: ``; the CLI names its own argument instead."""
    return message[len("path: ") :] if message.startswith("path: ") else message


def read_cloud(path: Path, argument: str) -> svs.PointCloud:
    """Load a PCD/PLY file; a missing or unreadable file is an :class:`InputError`."""
    if path.is_dir():
        raise InputError(f"{argument}: {path} is a folder, not a .pcd or .ply file")
    try:
        return svs.load_cloud(path)
    except (ValueError, OSError) as error:
        raise InputError(f"{argument}: {_strip_argument(str(error))}") from error


def read_transform(path: Path, argument: str) -> np.ndarray:
    """A rigid 4x4 transform from whitespace-separated text or a ``.npy`` file."""
    if not path.is_file():
        raise InputError(f"{argument}: no such file: {path}")
    try:
        T = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, ndmin=2)
    except (ValueError, OSError) as error:
        raise InputError(f"{argument}: {path} is not a matrix of numbers ({error})") from error
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(f"{argument}: {path} must hold a finite 4x4 matrix, got shape {T.shape}")
    R = T[:3, :3]
    rigid = np.allclose(R.T @ R, np.eye(3), atol=1e-4) and np.linalg.det(R) > 0
    if not rigid or not np.allclose(T[3], [0, 0, 0, 1]):
        raise InputError(f"{argument}: {path} is not a rigid transform (rotation and translation)")
    return T


def _check_output(path: Path | None, argument: str, suffixes: tuple[str, ...]) -> None:
    """Refuse an output file with a wrong extension before a long alignment starts."""
    if path is not None and path.suffix.lower() not in suffixes:
        raise InputError(f"{argument}: {path} must end in {' or '.join(suffixes)}")


def _plotting(argument: str) -> Any:
    """The plotting module, or an :class:`InputError` telling how to install matplotlib."""
    try:
        from spectral_vs import plotting

        plotting._new_figure(1, 1)
    except ImportError as error:
        raise InputError(f"{argument}: {error}") from error
    return plotting


def _errors(T: np.ndarray, truth: np.ndarray, center: np.ndarray) -> tuple[float, float]:
    """(rotation in degrees, translation in mm): the order of the limits and the report."""
    error = pose_error(T, truth, center=center)
    return error.rotation_deg, error.translation_mm


def _within(errors: tuple[float, float], limits: tuple[float, float]) -> bool:
    return errors[0] <= limits[0] and errors[1] <= limits[1]


def _write(path: Path, draw: Any, *args: Any, **kwargs: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    draw(*args, path, **kwargs)


# ----------------------------------------------------------------------------- align


def run_align(args: argparse.Namespace) -> int:
    """Align MODEL onto SCENE and report the pose (and its error against a ground truth)."""
    progress = Progress(not (args.quiet or args.json))
    for path, argument in ((args.model, "MODEL"), (args.scene, "SCENE")):
        if not path.exists():  # before any progress line, so the error is the only output
            raise InputError(f"{argument}: no such file: {path}")
        if path.is_dir():
            raise InputError(f"{argument}: {path} is a folder, not a .pcd or .ply file")
    _check_output(args.plot, "--plot", (".png", ".pdf", ".svg"))
    _check_output(args.render, "--render", (".png", ".pdf", ".svg"))
    _check_output(args.save_aligned, "--save-aligned", CLOUD_SUFFIXES)
    plotting: Any = (
        _plotting("--plot" if args.plot else "--render") if (args.plot or args.render) else None
    )
    initial = read_transform(args.initial_guess, "--initial-guess") if args.initial_guess else None
    truth = read_transform(args.ground_truth, "--ground-truth") if args.ground_truth else None

    timings: dict[str, float] = {}
    start = time.perf_counter()
    with progress.stage(f"loading model {args.model.name}") as notes:
        model = read_cloud(args.model, "MODEL")
        notes.append(f"{len(model)} points")
    with progress.stage(f"loading scene {args.scene.name}") as notes:
        scene = read_cloud(args.scene, "SCENE")
        notes.append(f"{len(scene)} points")
    timings["load"] = time.perf_counter() - start

    settings = svs.AlignParams()
    settings.voxel_size = args.voxel_size
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

    start = time.perf_counter()
    with progress.stage("downsampling and estimating normals") as notes:
        model_ready = prepare(model, "model", args.voxel_size, True, args.viewpoint)
        scene_ready = prepare(scene, "scene", args.voxel_size, True, args.viewpoint)
        notes.append(f"{len(model_ready)} and {len(scene_ready)} points")
    timings["prepare"] = time.perf_counter() - start

    mode = (
        f"global search over {settings.hypotheses} hypotheses"
        if settings.global_search
        else "local, from the initial guess"
    )
    start = time.perf_counter()
    with progress.stage(f"aligning ({1000 * args.voxel_size:g} mm voxels, {mode})") as notes:
        result = svs.align(model_ready, scene_ready, settings, downsample=False)
        notes.append(_count(result.iterations, "iteration"))
    timings["align"] = time.perf_counter() - start

    T = np.asarray(result.T_scene_model)
    center = np.asarray(model.centroid())
    errors = _errors(T, truth, center) if truth is not None else None
    # Settled: converged, or a verified hypothesis kept over where Algorithm 1 went.
    passed = bool(result.converged or result.stop_reason == "kept_start") and (
        errors is None or _within(errors, (args.max_rotation_error, args.max_translation_error))
    )

    if args.save_aligned:
        with progress.stage(f"writing {args.save_aligned}"):
            args.save_aligned.parent.mkdir(parents=True, exist_ok=True)
            svs.save_cloud(args.save_aligned, model.transformed(T))
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
                model_ready,
                scene_ready,
                result,
                initial_T=np.asarray(settings.initial_guess),
                title=f"{args.model.name} onto {args.scene.name}",
            )

    if args.json:
        report: dict[str, Any] = {
            "T_scene_model": T.tolist(),
            "converged": bool(result.converged),
            "stop_reason": result.stop_reason,
            "iterations": int(result.iterations),
            "fitness": float(result.fitness),
            "correlation": float(result.correlation),
            "translation_peak": float(result.translation_peak),
            "hypothesis": int(result.hypothesis),
            "time_s": timings["align"],
            "timings_s": timings,
            "voxel_size_m": settings.voxel_size,
            "model_points": len(model),
            "scene_points": len(scene),
        }
        if errors is not None:
            report["rotation_error_deg"] = errors[0]
            report["translation_error_mm"] = errors[1]
        report["passed"] = passed
        print(json.dumps(report, indent=2))
        return 0 if passed else 1

    with np.printoptions(precision=6, suppress=True):
        print("T_scene_model (moves MODEL coordinates into the SCENE frame, metres):")
        print(T)
    print(describe_transform(T))
    state = (
        "converged" if result.converged or result.stop_reason == "kept_start" else "NOT converged"
    )
    print(
        f"{state} after {_count(result.iterations, 'iteration')}, fitness {result.fitness:.3f}, "
        f"correlation {result.correlation:.3f}, {_duration(timings['align'])}"
    )
    if errors is not None:
        verdict = (
            "ok"
            if _within(errors, (args.max_rotation_error, args.max_translation_error))
            else "TOO LARGE"
        )
        print(
            f"error against the ground truth: rotation {errors[0]:.2f} deg, translation "
            f"{errors[1]:.1f} mm at the model centroid ({verdict}; limits "
            f"{args.max_rotation_error:g} deg, {args.max_translation_error:g} mm)"
        )
    return 0 if passed else 1


# ----------------------------------------------------------------------------- demo


def milk_split(model: svs.PointCloud, scene: svs.PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint samples of the milk carton scan: the model and the scene share no point.

    ``milk.pcd`` was cut out of the scene scan, so each of its points is a scene point.
    The scene's finite points are numbered in file order; the model keeps the carton points
    whose scene number is odd, the scene keeps the points with an even number.
    """
    scene_rows = np.ascontiguousarray(scene.points.astype(np.float32))
    number = {row: i for i, row in enumerate(map(tuple, scene_rows.tolist()))}
    model_rows = model.points.astype(np.float32).tolist()
    matches = np.array([number.get(tuple(row), -1) for row in model_rows])
    if np.any(matches < 0):
        raise InputError(
            f"--data: {np.sum(matches < 0)} points of {MILK_MODEL} are not in {MILK_SCENE}"
        )
    model_part = np.asarray(model.points)[matches % 2 == 1]
    scene_part = np.asarray(scene.points)[0::2]
    shared = set(map(tuple, model_part.astype(np.float32).tolist()))
    shared &= set(map(tuple, scene_part.astype(np.float32).tolist()))
    if shared:
        raise RuntimeError(f"the demo's model and scene share {len(shared)} points")
    return model_part, scene_part


def _box_surface(
    rng: np.random.Generator, half: np.ndarray, density: float, bottom: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward normals on a box's faces, ``density`` points per square metre."""
    points, normals = [], []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        count = int(density * 4 * half[a] * half[b])
        for sign in (1.0, -1.0):
            if axis == 2 and sign < 0 and not bottom:
                continue
            u = rng.uniform(-1, 1, size=(count, 3)) * half
            u[:, axis] = sign * half[axis]
            n = np.zeros((count, 3))
            n[:, axis] = sign
            points.append(u)
            normals.append(n)
    return np.vstack(points), np.vstack(normals)


def _box_with_ball(rng: np.random.Generator, density: float) -> tuple[np.ndarray, np.ndarray]:
    """A 20 x 12 x 8 cm box with a 7 cm ball on its top, origin on the bottom face's centre."""
    half = np.array([0.10, 0.06, 0.04])
    points, normals = _box_surface(rng, half, density)
    count = int(density * 4 * np.pi * 0.035**2)
    ball = rng.normal(size=(count, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    ball_points = np.array([0.05, 0.0, 0.04]) + 0.035 * ball
    keep = ball_points[:, 2] > 0.04
    # Drop the box top under the ball, which the ball hides.
    top = (points[:, 2] > 0.0399) & (np.linalg.norm(points[:, :2] - [0.05, 0.0], axis=1) < 0.035)
    points = np.vstack([points[~top], ball_points[keep]])
    normals = np.vstack([normals[~top], ball[keep]])
    return points + np.array([0.0, 0.0, 0.04]), normals


def _placed(points: np.ndarray, normals: np.ndarray, yaw_deg: float, position: Any):
    R = rotation_about([0, 0, 1], yaw_deg)
    return points @ R.T + position, normals @ R.T


def synthetic_scene(seed: int = 0) -> tuple[svs.PointCloud, svs.PointCloud]:
    """A seeded table-top scene and, sampled independently, the object to find in it.

    The object is a box with a ball on top; it stands among two other boxes on a plane
    (z = 0, z up). Returns ``(object, scene)`` in scene coordinates with exact normals;
    the scene has 1 mm of noise.
    """
    rng = np.random.default_rng(seed)
    density = 60000.0  # points per square metre, about one per 4 mm
    pose = (25.0, [0.02, -0.03, 0.0])
    obstacles = [
        (np.array([0.06, 0.05, 0.07]), 10.0, [0.22, 0.13, 0.07]),
        (np.array([0.09, 0.04, 0.03]), -30.0, [-0.2, -0.17, 0.03]),
    ]
    target_points, target_normals = _placed(*_box_with_ball(rng, density), *pose)
    parts = [(target_points, target_normals)]
    plane = rng.uniform([-0.45, -0.35, 0], [0.45, 0.35, 0], size=(int(density * 0.63), 3))
    hidden = np.zeros(len(plane), dtype=bool)
    footprints = [(np.array([0.10, 0.06]), *pose)]
    footprints += [(half[:2], yaw, position) for half, yaw, position in obstacles]
    for half, yaw, position in footprints:
        R = rotation_about([0, 0, 1], yaw)
        local = (plane - np.asarray(position, dtype=float)) @ R
        hidden |= np.all(np.abs(local[:, :2]) <= half, axis=1)
    plane = plane[~hidden]
    parts.append((plane, np.tile([0.0, 0.0, 1.0], (len(plane), 1))))
    for half, yaw, position in obstacles:
        parts.append(_placed(*_box_surface(rng, half, density), yaw, position))
    scene_points = np.vstack([p for p, _ in parts])
    scene_points = scene_points + rng.normal(0, 0.001, scene_points.shape)
    scene = svs.PointCloud(scene_points, np.vstack([n for _, n in parts]))
    model = svs.PointCloud(*_placed(*_box_with_ball(rng, density), *pose))
    return model, scene


def run_alignment_demo(args: argparse.Namespace) -> int:
    """Move an object's cloud by a known transform and align it back onto a cluttered scene."""
    progress = Progress(not args.quiet)
    try:
        plotting: Any = _plotting("demo")
    except InputError as error:
        plotting = None
        print(f"no figures: {error.__cause__}")
    voxel = args.voxel_size
    have_scans = (args.data / MILK_MODEL).is_file() and (args.data / MILK_SCENE).is_file()
    if have_scans and not args.synthetic:
        with progress.stage("loading the Kinect scans") as notes:
            carton = read_cloud(args.data / MILK_MODEL, "--data")
            full_scene = read_cloud(args.data / MILK_SCENE, "--data")
            notes.append(f"{len(carton)} and {len(full_scene)} points")
        with progress.stage("splitting into disjoint samples"):
            model_points, scene_points = milk_split(carton, full_scene)
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
    state = "converged" if result.converged else "not converged"
    print(
        f"{_count(result.iterations, 'iteration')} ({state}), fitness {result.fitness:.3f}, "
        f"correlation {result.correlation:.3f}, {_duration(elapsed)}"
    )

    status = 0 if _within(errors, limits) or not args.check else 1
    if plotting is None:
        return status
    convergence = args.output / "convergence.png"
    alignment = args.output / "alignment.png"
    with progress.stage(f"writing {convergence} and {alignment.name}"):
        title = f"{name}: {args.angle:g} deg, {1000 * voxel:g} mm voxels"
        _write(
            convergence,
            plotting.plot_convergence,
            result,
            title=title,
            tolerance=settings.tolerance,
            voxel_size=voxel,
            ground_truth=truth,
            center=np.asarray(model.centroid()),
        )
        _write(alignment, plotting.render_alignment, model, scene, result, title=title)
    print(f"wrote {convergence} and {alignment}")
    return status


def estimate_translation(
    moving: svs.PointCloud,
    target: svs.PointCloud,
    voxel_size: float,
    occupancy: str = "trilinear",
) -> tuple[svs.TranslationEstimate, svs.GridSpec]:
    """Translation of ``moving`` onto ``target`` by phase correlation on a shared grid."""
    spec = svs.make_grid_spec(moving, target, voxel_size)
    correlation = svs.PhaseCorrelation(spec)
    correlation.set_target(svs.voxelize(target, spec, occupancy=occupancy))
    return correlation.estimate(svs.voxelize(moving, spec, occupancy=occupancy)), spec


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


def run_translate(args: argparse.Namespace) -> int:
    """Translation between two point cloud files."""
    moving = read_cloud(args.moving, "MOVING")
    target = read_cloud(args.target, "TARGET")
    start = time.perf_counter()
    estimate, spec = estimate_translation(moving, target, args.voxel_size, args.occupancy)
    elapsed = time.perf_counter() - start
    result = {
        "translation_m": list(map(float, estimate.shift)),
        "translation_voxels": list(map(float, estimate.shift_voxels)),
        "peak": float(estimate.peak),
        "grid_dims": list(map(int, spec.dims)),
        "time_s": elapsed,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        t_mm = 1000 * np.asarray(estimate.shift)
        print(f"translation [mm]: {np.array2string(t_mm, precision=2)}  (moves MOVING onto TARGET)")
        print(f"peak {estimate.peak:.3f}, grid {result['grid_dims']}, {1000 * elapsed:.1f} ms")
    return 0


# ----------------------------------------------------------------------------- servo-sim


def _servo_step_line(record: Any, T_world_reference: np.ndarray, servo_lib: Any) -> str:
    true_t, true_r = servo_lib.pose_error(
        np.linalg.inv(np.asarray(record.T_base_camera)) @ T_world_reference
    )
    return (
        f"step {record.step:3d}  t {record.time:5.1f} s  error {1000 * true_t:7.1f} mm "
        f"{np.degrees(true_r):6.2f} deg  (estimate {1000 * record.translation_error:7.1f}"
        f" mm {np.degrees(record.rotation_error):5.2f} deg)  fitness "
        f"{record.fitness:4.2f}  |v| {1000 * np.linalg.norm(record.twist[:3]):5.1f} mm/s"
        f"  {1000 * record.seconds:4.0f} ms"
        + (f"  relocalized (score {record.relocalization_score:.2f})" if record.relocalized else "")
        + (f"  held: {record.hold}" if record.hold else "")
        + (f"  recovering: {record.recovery}" if record.recovery else "")
    )


def run_servo_sim(args: argparse.Namespace) -> int:
    """Servo the simulated arm (--robot) from seeded starts back to the reference pose."""
    from spectral_vs import servo as servo_lib

    try:
        from spectral_vs import sim
    except ImportError as error:
        raise InputError(f"servo-sim: {error}") from error
    plotting = None if args.no_figures else _plotting("--out")
    noise = sim.DepthNoise.kinect(seed=args.seed) if args.noise else sim.DepthNoise()
    sim_params = sim.SimParams(
        mode=args.sim_mode,
        robot=sim.robot_model(args.robot),
        camera=sim.CameraParams(noise=noise),
    )
    params = servo_lib.ServoParams(mode=args.mode, warm_start=args.warm_start)
    talk = not (args.json or args.quiet)
    per_step = talk and args.starts == 1
    runs: list[dict[str, Any]] = []
    with sim.PyBulletRobot(sim_params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        home_q = sim_params.robot.home_q
        spec = servo_lib.START_SETS[args.set]
        accept = robot.view_check(spec["min_view_share"]) if "min_view_share" in spec else None
        starts = servo_lib.start_poses(
            robot.kinematics, args.set, args.starts, args.seed, q_reference=home_q, accept=accept
        )

        def progress(record: servo_lib.ServoRecord) -> None:
            print(_servo_step_line(record, T_world_reference, servo_lib), flush=True)

        if talk:
            warm = ", warm-started" if args.warm_start else ""
            print(
                f"{args.robot}: reference captured at home ({len(reference)} points); "
                f"{_count(args.starts, 'start')} of the {args.set} set (seed {args.seed}); "
                f"'{args.mode}' estimate{warm}, {args.sim_mode} simulation"
                f"{', depth noise' if args.noise else ''}, control period {args.dt:g} s, "
                f"{args.max_steps} steps max"
            )
        for index, (q, t, r) in enumerate(starts):
            robot.reset_joint_positions(q)
            if per_step:
                print(f"start {index}: camera {1000 * t:.0f} mm and {np.degrees(r):.1f} deg away")
            recorder = servo_lib.CloudRecorder(robot)
            log = servo_lib.run_servo(
                recorder,
                robot.kinematics,
                servo_lib.SpectralServo(reference, params),
                dt=args.dt,
                max_steps=args.max_steps,
                stop_at_joint_limit=args.stop_at_joint_limits,
                callback=progress if per_step else None,
            )
            final_t, final_r = servo_lib.pose_error(
                np.linalg.inv(robot.camera_pose()) @ T_world_reference
            )
            run: dict[str, Any] = {
                "index": index,
                "start_mm": 1000 * t,
                "start_deg": float(np.degrees(r)),
                "final_mm": 1000 * final_t,
                "final_deg": float(np.degrees(final_r)),
                "steps": len(log.records),
                "reason": log.reason,
                "success": bool(
                    1000 * final_t < MAX_SERVO_ERROR_MM
                    and np.degrees(final_r) < MAX_SERVO_ERROR_DEG
                ),
                "servo_step_ms_median": 1000 * float(np.median(log.array("seconds"))),
                "servo_step_cpu_ms": [
                    round(1000 * float(ms), 3) for ms in log.array("cpu_seconds")
                ],
                "wall_s": log.wall_seconds,
                "recovery_steps": int(sum(bool(r.recovery) for r in log.records)),
                "relocalizations": int(sum(r.relocalized for r in log.records)),
            }
            runs.append(run)
            if talk:
                print(
                    f"start {index}: {run['start_mm']:.0f} mm {run['start_deg']:.1f} deg -> "
                    f"{log.reason} after {_count(run['steps'], 'step')}; final error "
                    f"{run['final_mm']:.2f} mm, {run['final_deg']:.3f} deg "
                    f"({'ok' if run['success'] else 'TOO LARGE'}), {log.wall_seconds:.1f} s wall",
                    flush=True,
                )
            if plotting is not None:
                name = "servo.png" if args.starts == 1 else f"servo_{index}.png"
                path = args.out / name
                path.parent.mkdir(parents=True, exist_ok=True)
                servo_lib.plot_servo(
                    log,
                    T_world_reference,
                    path,
                    reference=reference,
                    clouds=dict(enumerate(recorder.clouds)),
                    title=f"servo-sim: {args.robot}, {args.set} start {index}, seed {args.seed}, "
                    f"'{args.mode}' estimate",
                )
                if talk:
                    print(f"wrote {path}")
    successes = sum(run["success"] for run in runs)
    if args.json:
        summary = {
            "robot": args.robot,
            "set": args.set,
            "seed": args.seed,
            "mode": args.mode,
            "warm_start": args.warm_start,
            "sim_mode": args.sim_mode,
            "noise": args.noise,
            "stop_at_joint_limits": args.stop_at_joint_limits,
            "success_mm": MAX_SERVO_ERROR_MM,
            "success_deg": MAX_SERVO_ERROR_DEG,
            "successes": successes,
            "starts": runs,
        }
        print(json.dumps(summary, indent=1))
    elif talk:
        print(
            f"{successes}/{len(runs)} within {MAX_SERVO_ERROR_MM:g} mm and "
            f"{MAX_SERVO_ERROR_DEG:g} deg of the reference pose"
        )
    return 0 if successes == len(runs) else 1


# ----------------------------------------------------------------------------- parser

ALIGN_DESCRIPTION = """\
Find the rigid transform T_scene_model that moves MODEL onto where the same object lies
in SCENE, without point correspondences: rotation from the Extended Gaussian Images
(normals on the sphere) correlated on SO(3), translation from the 3D phase correlation
of voxel grids (Algorithm 1 of "3D Spectral Domain Registration-Based Visual Servoing").

T_scene_model is a 4x4 matrix [R t; 0 0 0 1] that maps a point p of the model, in model
coordinates, to R p + t in scene coordinates. Units: metres (clouds, --voxel-size, t),
degrees and millimetres for the errors against --ground-truth.

Both clouds are downsampled to half a voxel; normals are read from the files when they
have them, otherwise estimated (radius 2 voxels) and turned toward --viewpoint, the
sensor's position (the origin for a scan in camera coordinates).

Exit code: 0 when the alignment converged (and is within the error limits when a ground
truth is given), 1 when it did not, 2 on bad input."""

ALIGN_EPILOG = """\
example:
  spectral-vs align milk.pcd scene.pcd --voxel-size 0.008 --plot convergence.png \\
      --render alignment.png --save-aligned milk_in_scene.ply
  spectral-vs align model.ply scene.ply --ground-truth T_true.txt --json

A transform file (--initial-guess, --ground-truth) holds 4 lines of 4 numbers, or a
(4, 4) array saved with numpy.save (.npy)."""


def _positive_float(text: str) -> float:
    value = float(text)
    if not np.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="spectral-vs",
        description="Correspondence-free point cloud registration in the spectral domain.",
    )
    parser.add_argument("--version", action="version", version=f"spectral_vs {svs.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    formatter = argparse.RawDescriptionHelpFormatter

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
    settings.add_argument(
        "--voxel-size",
        type=_positive_float,
        default=0.008,
        metavar="M",
        help="voxel edge of the translation grid, metres (default: 0.008)",
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
    settings.add_argument(
        "--viewpoint",
        type=float,
        nargs=3,
        default=(0.0, 0.0, 0.0),
        metavar=("X", "Y", "Z"),
        help="sensor position that estimated normals face, metres (default: 0 0 0)",
    )
    check = align.add_argument_group("checking against a known answer")
    check.add_argument(
        "--ground-truth",
        type=Path,
        metavar="FILE",
        help="true T_scene_model: prints the rotation error (degrees) and the "
        "translation error (mm, at the model's centroid)",
    )
    check.add_argument(
        "--max-rotation-error",
        type=float,
        default=MAX_ROTATION_ERROR,
        metavar="DEG",
        help=f"exit 1 above this rotation error (default: {MAX_ROTATION_ERROR:g})",
    )
    check.add_argument(
        "--max-translation-error",
        type=float,
        default=MAX_TRANSLATION_ERROR,
        metavar="MM",
        help=f"exit 1 above this translation error (default: {MAX_TRANSLATION_ERROR:g})",
    )
    output = align.add_argument_group("output")
    output.add_argument(
        "--json",
        action="store_true",
        help="print the result as JSON (transform, converged, iterations, fitness, "
        "correlation, time, errors) and no progress",
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
    output.add_argument(
        "--save-aligned",
        type=Path,
        metavar="FILE",
        help="write MODEL moved by T_scene_model (.pcd or .ply)",
    )
    output.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    align.set_defaults(run=run_align)

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
        "--seed", type=int, default=0, help="seed of the generated scene (default: 0)"
    )
    demo.add_argument(
        "--check",
        action="store_true",
        help="exit with status 1 when the alignment misses 5 deg / 10 mm (default: report only)",
    )
    demo.add_argument(
        "--translation-only",
        action="store_true",
        help="only recover a translation of the carton by phase correlation",
    )
    demo.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    demo.set_defaults(run=run_demo)

    translate = commands.add_parser(
        "translate", help="translation between two clouds (PCD/PLY) by 3D phase correlation"
    )
    translate.add_argument("moving", type=Path, help="cloud to move (.pcd or .ply)")
    translate.add_argument("target", type=Path, help="cloud to move it onto (.pcd or .ply)")
    translate.add_argument(
        "--voxel-size", type=_positive_float, default=0.008, help="voxel edge in metres"
    )
    translate.add_argument(
        "--occupancy",
        choices=["binary", "count", "trilinear"],
        default="trilinear",
        help="voxel values: the paper's binary grid or a weighted one (default: trilinear)",
    )
    translate.add_argument("--json", action="store_true", help="print machine-readable JSON")
    translate.set_defaults(run=run_translate)

    servo = commands.add_parser(
        "servo-sim",
        aliases=["servo-demo"],
        help="servo a simulated robot arm's camera back to a reference pose (needs pybullet)",
        description="The paper's robot experiment in PyBullet: capture the reference cloud at "
        "the home pose, move every joint of the arm (--robot) to seeded random starts, then "
        "servo the wrist camera back with spectral_vs.servo, printing every step (one start) "
        "or one line per start, and the final error against the simulation's ground truth. Writes "
        "servo.png (errors over time, camera path, clouds over the reference; servo_<i>.png "
        "for several starts) to --out. Exit code 1 when a final error exceeds "
        f"{MAX_SERVO_ERROR_MM:g} mm or {MAX_SERVO_ERROR_DEG:g} degree.",
    )
    servo.add_argument("--seed", type=int, default=0, help="seed of the start poses (default: 0)")
    servo.add_argument(
        "--starts",
        type=_positive_int,
        default=1,
        metavar="N",
        help="random start poses (default: 1)",
    )
    servo.add_argument(
        "--robot",
        choices=["iiwa", "panda"],  # the keys of sim.ROBOT_MODELS (test_cli checks)
        default="iiwa",
        help="the arm: KUKA LBR iiwa (default) or Franka Emika Panda, both with the camera "
        "0.55 m above the table at home",
    )
    servo.add_argument(
        "--set",
        choices=["moderate", "large", "extreme"],  # the keys of servo.START_SETS
        default="moderate",
        help="starts under 0.2 m and 30 deg away (moderate, default), beyond that up to "
        "0.45 m and 60 deg (large), or beyond that up to 0.6 m and 90 deg with at least 30%% "
        "of the reference still in view and the camera above the table (extreme)",
    )
    servo.add_argument(
        "--mode",
        choices=["iteration", "pose"],
        default="iteration",
        help="one update of Algorithm 1 per step (the paper, default) or a full "
        "registration per step",
    )
    servo.add_argument(
        "--warm-start",
        action="store_true",
        help="start each registration from the previous estimate moved by the camera's "
        "measured motion (the most robust with --mode pose)",
    )
    servo.add_argument(
        "--sim-mode",
        choices=["kinematic", "dynamic"],
        default="kinematic",
        help="joints integrate the command exactly (default) or PyBullet's torque-limited "
        "velocity motors under gravity",
    )
    servo.add_argument(
        "--noise",
        action="store_true",
        help="Kinect-like depth noise (0.5 mm + 1.9 mm/m^2 z^2, 2%% missing pixels)",
    )
    servo.add_argument(
        "--dt", type=_positive_float, default=0.1, metavar="S", help="control period, s"
    )
    servo.add_argument(
        "--max-steps", type=_positive_int, default=150, metavar="N", help="step budget per start"
    )
    servo.add_argument(
        "--stop-at-joint-limits",
        action="store_true",
        help="stop (reason joint_limit) as soon as the joint command has to clamp a joint at "
        "a position limit; by default the clamped command is sent and the other joints go "
        "on (run_servo's stop_at_joint_limit=False; no joint ever crosses its limit): "
        "14-16 of 20 large iiwa starts instead of 12 (docs/kinematics.md)",
    )
    servo.add_argument(
        "--out",
        "--output",
        dest="out",
        type=Path,
        default=Path("results/servo"),
        metavar="DIR",
        help="folder for the figures (default: results/servo)",
    )
    servo.add_argument(
        "--no-figures", action="store_true", help="do not draw (no matplotlib needed)"
    )
    servo.add_argument(
        "--json",
        action="store_true",
        help="print a machine-readable summary: per start the final translation error (mm), "
        "rotation error (deg), steps, reason and success",
    )
    servo.add_argument("--quiet", action="store_true", help="print only the summary")
    servo.set_defaults(run=run_servo_sim)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as error:
        print(f"error: {_strip_argument(str(error))}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
