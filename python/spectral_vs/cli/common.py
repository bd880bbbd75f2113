"""What the subcommands share: input checks that name the argument, progress lines, the
error limits of the runs against a ground truth, and pose formatting."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

import numpy as np

import spectral_vs as svs
from spectral_vs.poses import pose_error

DEFAULT_DATA = Path(os.environ.get("SPECTRAL_VS_DATA", "../shared/data"))
#: Ground-truth errors above these fail a run (exit code 1): degrees, millimetres.
MAX_ROTATION_ERROR = 5.0
MAX_TRANSLATION_ERROR = 10.0
CLOUD_SUFFIXES = (".pcd", ".ply")
#: servo-sim fails (exit code 1) above these final camera pose errors: mm, degrees.
MAX_SERVO_ERROR_MM = 5.0
MAX_SERVO_ERROR_DEG = 1.0


#: Why an answer is not reliable, by status: what the command line prints beside it.
VERDICT_REASONS = {
    "ambiguous": "other poses fit about as well (a symmetric object, or a view that hides "
    "what tells them apart)",
    "doubtful": "the scene supports the pose too little",
    "floating": "the pose neither rests on the table nor stands on anything (an object "
    "flush with another's face, the rest of it inside that object); for an object held "
    "above the table, --may-float (expect_resting=False)",
    "undetermined": "the scene leaves a direction of the pose free (a plane on a plane): "
    "its covariance is wider than 5 degrees or 10 mm",
    "no_support": "the scene supports no part of the answer (nothing shared)",
    "max_seconds": "the time budget ran out before the search ended",
    "bad_scale": "the voxel is over half, or under 1/1000, of the cloud's typical size",
    "unverified": "the verification was turned off",
}


def verdict_line(result: Any) -> str:
    """The verdict of an AlignResult or a ViewAlignResult in words: its status, its
    calibrated confidence and, when not reliable, why."""
    line = (
        f"{result.status}: confidence {result.confidence:.3f} "
        f"(reliable at {svs.RELIABLE_CONFIDENCE:g} or more with no alternative as good)"
    )
    if not result.reliable:
        line += f"; not reliable: {VERDICT_REASONS.get(result.status, result.status)}"
    # The other answers that make it ambiguous (not those of the object's own symmetry).
    others = [a for a in result.alternatives if not a.symmetric]
    if result.ambiguous and others:
        best = max(others, key=lambda a: a.confidence)
        line += (
            f"\n  {len(others)} other pose{'s fit' if len(others) > 1 else ' fits'} as well; the "
            f"best {math.degrees(best.rotation_apart):.0f} deg and "
            f"{1000 * best.translation_apart:.0f} mm away, confidence {best.confidence:.3f}"
        )
    return line


def covariance_report(covariance: Any) -> dict[str, Any]:
    """The --json form of a 6x6 pose covariance (rotation vector in rad, then translation
    in m), with its standard deviations in degrees and millimetres."""
    matrix = np.asarray(covariance, dtype=float)
    deviations = np.sqrt(np.clip(np.diag(matrix), 0.0, None))
    return {
        "covariance": matrix.tolist(),
        "rotation_std_deg": np.degrees(deviations[:3]).tolist(),
        "translation_std_mm": (1000 * deviations[3:]).tolist(),
    }


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
    """Rotation matrix of ``angle_deg`` degrees about ``axis``."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return svs.so3_exp(k * np.radians(angle_deg))


def axis_angle(R: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle (degrees, in [0, 180]) of a rotation matrix (the z axis for the
    identity)."""
    rotation_vector = svs.so3_log(np.asarray(R, dtype=float))
    angle = float(np.linalg.norm(rotation_vector))
    if angle < 1e-12:
        return np.array([0.0, 0.0, 1.0]), 0.0
    return rotation_vector / angle, float(np.degrees(angle))


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


def _seed(text: str) -> int:
    """A seed of NumPy's generators: an integer in [0, 2**32)."""
    value = int(text)
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2**32), got {value}")
    return value


def add_sensor_origin(group: Any, role: str, flag: str = "--sensor-origin") -> None:
    """``flag X Y Z``: a sensor's position in its cloud's coordinates, metres (default the
    origin: a depth camera's cloud in its own frame); ``role`` says what it is used for."""
    group.add_argument(
        flag,
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help=f"{role}; metres, in the cloud's coordinates (default: 0 0 0)",
    )


def sensor_origin_of(args: argparse.Namespace) -> tuple[float, float, float]:
    """--sensor-origin, the origin by default."""
    return tuple(args.sensor_origin) if args.sensor_origin is not None else (0.0, 0.0, 0.0)


def add_check_arguments(check: Any, ground_truth: str) -> None:
    """--ground-truth (``ground_truth``: what the file holds and what is printed) and the
    error limits above which the command exits with 1."""
    check.add_argument("--ground-truth", type=Path, metavar="FILE", help=ground_truth)
    check.add_argument(
        "--max-rotation-error",
        type=_positive_float,
        default=MAX_ROTATION_ERROR,
        metavar="DEG",
        help=f"exit 1 above this rotation error (default: {MAX_ROTATION_ERROR:g})",
    )
    check.add_argument(
        "--max-translation-error",
        type=_positive_float,
        default=MAX_TRANSLATION_ERROR,
        metavar="MM",
        help=f"exit 1 above this translation error (default: {MAX_TRANSLATION_ERROR:g})",
    )


def check_paths(args: argparse.Namespace, inputs: tuple[str, ...]) -> None:
    """The input files (``args`` attributes ``inputs``, named in upper case) exist and are
    files, before any progress line, so that the error is the only output."""
    for name in inputs:
        path = getattr(args, name)
        argument = name.upper()
        if not path.exists():
            raise InputError(f"{argument}: no such file: {path}")
        if path.is_dir():
            raise InputError(f"{argument}: {path} is a folder, not a .pcd or .ply file")


def load_clouds(
    progress: Progress, args: argparse.Namespace, inputs: tuple[tuple[str, str], ...]
) -> tuple[list[svs.PointCloud], float]:
    """The clouds of ``args`` attributes ``inputs`` ((attribute, label) each; the argument
    named in upper case in errors), loaded with a progress line each, and the seconds taken."""
    start = time.perf_counter()
    clouds = []
    for name, label in inputs:
        path = getattr(args, name)
        with progress.stage(f"loading {label} {path.name}") as notes:
            clouds.append(read_cloud(path, name.upper()))
            notes.append(f"{len(clouds[-1])} points")
    return clouds, time.perf_counter() - start


def save_moved(progress: Progress, path: Path | None, cloud: svs.PointCloud, T: np.ndarray) -> None:
    """--save-aligned: ``cloud`` moved by ``T``, written to ``path`` when one is given."""
    if path is not None:
        with progress.stage(f"writing {path}"):
            path.parent.mkdir(parents=True, exist_ok=True)
            svs.save_cloud(path, cloud.transformed(T))


def ground_truth_errors(
    args: argparse.Namespace, T: np.ndarray, truth: np.ndarray | None, center: np.ndarray
) -> tuple[tuple[float, float] | None, bool]:
    """The errors of ``T`` against --ground-truth ``truth`` (degrees, mm at ``center``; None
    without one) and whether they are within the limits (True without a ground truth)."""
    if truth is None:
        return None, True
    errors = _errors(T, truth, center)
    return errors, _within(errors, (args.max_rotation_error, args.max_translation_error))


def print_transform(caption: str, T: np.ndarray) -> None:
    """``caption``, the 4 x 4 transform ``T`` and its rotation and translation in words."""
    with np.printoptions(precision=6, suppress=True):
        print(caption)
        print(T)
    print(describe_transform(T))


def error_report(errors: tuple[float, float] | None) -> dict[str, float]:
    """The --json fields of the errors against --ground-truth (none without one)."""
    if errors is None:
        return {}
    return {"rotation_error_deg": errors[0], "translation_error_mm": errors[1]}


def print_errors(args: argparse.Namespace, errors: tuple[float, float] | None, at: str) -> None:
    """The errors against --ground-truth (the translation's measured ``at`` a point) and
    whether they are within the limits, when a ground truth was given."""
    if errors is None:
        return
    limits = (args.max_rotation_error, args.max_translation_error)
    verdict = "ok" if _within(errors, limits) else "TOO LARGE"
    print(
        f"error against the ground truth: rotation {errors[0]:.2f} deg, translation "
        f"{errors[1]:.1f} mm at {at} ({verdict}; limits {limits[0]:g} deg, {limits[1]:g} mm)"
    )


def add_report_arguments(output: Any, json_contents: str) -> None:
    """--json (``json_contents``: what the report holds) and --quiet."""
    output.add_argument(
        "--json",
        action="store_true",
        help=f"print the result as JSON ({json_contents}) and no progress",
    )
    output.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def add_save_aligned(output: Any, moved: str) -> None:
    """--save-aligned: where to write ``moved`` (which cloud, moved by which transform)."""
    output.add_argument(
        "--save-aligned", type=Path, metavar="FILE", help=f"write {moved} (.pcd or .ply)"
    )
