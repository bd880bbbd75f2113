"""A whole-range harness of the public API (issue 34): every callable of
``spectral_vs.__all__`` called with values at, inside and beyond its documented ranges.

Each entry of the table (:func:`table`, one per public name) draws the arguments of one
callable, and of its main methods for a class, with hypothesis (``derandomize=True``, no
database, no deadline: the same calls on every run): integer settings over their whole type
range (the int32 and int64 edges, the documented bounds and one beyond each, random int64),
floats with NaN, +-inf, 0, -0, tiny, 1e300 and negative values, and arrays of the wrong
shape, dtype or layout. A call must return a finite answer (poses rigid, shares in [0, 1])
or raise a documented exception (ValueError, TypeError; OSError and its kinds for file
paths), within 10 s of wall time and 1 GB of resident memory over what the process held
before it. Anything else is a finding: a crash (signal), a hang, a memory jump, an
undocumented exception (RuntimeError, OverflowError, MemoryError, SystemError, ...) or a
non-finite result.

Run it as a script::

    python tests/python/api_harness.py --examples 15 --report report.jsonl

The script supervises a worker process (the same script with ``--worker``) that runs the
table. Before each call the worker writes the call (the callable and a short repr of its
arguments) to the last-call file, so that when it dies by a signal, or is killed for not
returning within ``--kill-after`` seconds, the supervisor names the culprit, records it and
starts a new worker after that entry. The worker caps its address space (``--address-space-mb``)
so that a runaway allocation fails (MemoryError, itself a finding) instead of starving the
machine. Findings go to the report, one JSON object a line, and to the summary printed at
the end; the exit status is 0 only without findings. ``--only NAME`` runs some entries.

``--examples`` is per callable, scaled by each entry's ``share`` (the alignments, the servo,
the global rotation search and the result types run a fraction of it): 20 take about 15 s,
1000 about 6 minutes on two cores (tests/python/test_api_harness.py: 20 by default, half of
SPECTRAL_VS_HARNESS_EXAMPLES when that is set, as ``make fuzz`` does).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
for _folder in (str(ROOT), str(HERE)):  # conftest.py, and the test modules reused here
    if _folder not in sys.path:
        sys.path.insert(0, _folder)

import numpy as np  # noqa: E402
from conftest import box_and_sphere  # noqa: E402
from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from test_properties import (  # noqa: E402
    DOCUMENTED,
    arrays,
    assert_finite,
    floats_any,
    int64,
    resident_megabytes,
    rotations,
    seeds,
)
from test_servo import FreeCamera, FreeCameraKinematics, camera_pose, table_top, view  # noqa: E402

import spectral_vs as svs  # noqa: E402
from spectral_vs.servo import fault_settings, stage_settings  # noqa: E402
from spectral_vs.servo import records as servo_records  # noqa: E402

#: What one call may take: seconds of wall time, megabytes of resident memory over what the
#: process held before it (as in test_properties.py's harness of cloud_from_depth).
LIMIT_SECONDS = 10.0
LIMIT_MEGABYTES = 1024.0
#: The default grid budget (GridLimits::max_voxels), and what a raised one may take a voxel:
#: the phase correlation's buffers, about 28 bytes, and the grids beside them.
DEFAULT_MAX_VOXELS = 2**24
BYTES_PER_VOXEL = 64


def raised_budget(max_voxels: Any) -> bool:
    """Whether a call was given a grid budget above the default."""
    return (
        isinstance(max_voxels, int)
        and not isinstance(max_voxels, bool)
        and DEFAULT_MAX_VOXELS < max_voxels <= 2**32
    )


#: The supervisor kills a worker whose call has not returned after this many seconds.
KILL_SECONDS = 20.0
#: The worker's address space (RLIMIT_AS), MB: 256 threads reserve 3.4 GB of it.
ADDRESS_SPACE_MB = 8192
#: The exceptions a file path may raise besides the documented ones.
FILE_ERRORS = (*DOCUMENTED, OSError)

INT_EDGES = (
    -(2**63),
    -(2**31) - 1,
    -(2**31),
    -1,
    0,
    1,
    2,
    3,
    2**16 + 1,
    2**30,
    2**31 - 1,
    2**31,
    2**32,
    2**63 - 1,
)
#: Values of the wrong type for any argument.
WRONG_TYPES = (
    None,
    "1",
    b"\x00",
    [1, 2],
    (),
    {"a": 1},
    1.5,
    math.nan,
    1j,
    True,
    np.float32(2.5),
    np.int64(3),
    np.array([1.0, 2.0]),
    np.zeros((2, 2, 2)),
    object(),
)


# --- Strategies -------------------------------------------------------------------------


def ints(*documented: int) -> st.SearchStrategy[int]:
    """Integers over the whole int64 range (and beyond it by one): the type edges, each
    documented bound and its neighbours, small values and random int64."""
    edges = sorted({*INT_EDGES, *(d + o for d in documented for o in (-1, 0, 1))})
    return st.one_of(st.sampled_from(edges), st.integers(-3, 40), int64)


def reals(*documented: float) -> st.SearchStrategy[float]:
    """Floats: NaN, +-inf, 0, -0, tiny, huge, random, and each documented bound with the
    floats just below and above it."""
    edges = [
        x
        for d in documented
        for x in (d, math.nextafter(d, -math.inf), math.nextafter(d, math.inf))
    ]
    return st.one_of(floats_any, st.sampled_from(edges)) if edges else floats_any


wrong = st.sampled_from(WRONG_TYPES)


def sometimes_wrong(strategy: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """``strategy``, or one time in five a value of the wrong type."""
    return st.integers(0, 4).flatmap(lambda i: wrong if i == 0 else strategy)


def rigid(R: np.ndarray, t: Any) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


@st.composite
def transforms(draw: st.DrawFn) -> Any:
    """4x4 transforms: rigid ones (any rotation, translations up to 1e300), and non-rigid,
    non-finite, wrongly shaped or typed ones."""
    R = draw(rotations())
    t = draw(
        st.sampled_from([(0.0, 0.0, 0.0), (0.01, -0.02, 0.03), (1e6, 0.0, 0.0), (1e300, 0, 0)])
    )
    T = rigid(R, t)
    kind = draw(st.integers(0, 14))
    if kind <= 6:
        return T
    if kind == 7:
        T[:3, :3] *= draw(st.sampled_from([1.0 + 1e-5, 2.0, 0.0, -1.0]))
    elif kind == 8:
        T.flat[draw(st.integers(0, 15))] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    elif kind == 9:
        T[3] = draw(st.sampled_from([(0, 0, 0, 0), (0, 0, 1, 1), (0, 0, 0, 2)]))
    elif kind == 10:
        return draw(st.sampled_from([T[:3, :3], T[:3], T.ravel(), T[None], T.T[:, :3]]))
    elif kind == 11:
        return T.tolist()
    elif kind == 12:
        return np.eye(4, dtype=draw(st.sampled_from([np.int64, np.float32, np.bool_, object])))
    elif kind == 13:
        return draw(arrays())
    else:
        return draw(wrong)
    return T


@st.composite
def rotation_matrices(draw: st.DrawFn) -> Any:
    """3x3 matrices: rotations (half turns included), near-rotations, reflections,
    non-finite, wrongly shaped or typed ones."""
    R = draw(rotations())
    kind = draw(st.integers(0, 10))
    if kind <= 5:
        return R
    if kind == 6:
        return R * draw(st.sampled_from([1.0 + 1e-7, 1.0 + 1e-5, -1.0, 0.0, 1e300]))
    if kind == 7:
        R = R.copy()
        R.flat[draw(st.integers(0, 8))] = draw(st.sampled_from([math.nan, math.inf]))
        return R
    if kind == 8:
        return draw(st.sampled_from([R.tolist(), R.astype(np.float32), np.eye(3, dtype=int)]))
    if kind == 9:
        return draw(arrays())
    return draw(wrong)


vectors = st.one_of(
    st.tuples(*[st.floats(-2.0, 2.0)] * 3).map(np.array),
    st.sampled_from(
        [
            np.zeros(3),
            np.array([0.0, 0.0, 1.0]),
            np.array([1e-300, 0.0, 0.0]),
            np.array([1e300, 1e300, 0.0]),
            np.array([math.nan, 0.0, 1.0]),
            np.array([math.inf, 0.0, 0.0]),
            np.array([1.0, 2.0]),
            np.ones(4),
            np.ones((3, 1)),
            np.array([1, 0, 0]),
            [0.0, 0.0, 1.0],
            "abc",
        ]
    ),
    st.tuples(*[reals()] * 3).map(np.array),
    arrays(),
    wrong,
)


def short(value: Any) -> str:
    """A short repr of an argument for the last-call file and the report."""
    if isinstance(value, np.ndarray):
        flags = []
        if value.dtype.kind in "fc" and value.size and not np.all(np.isfinite(value)):
            flags.append("non-finite")
        if value.size and value.dtype.kind in "fiu" and np.abs(value).max() > 1e6:
            flags.append(f"max {np.abs(value).max():.3g}")
        if value.size <= 4:
            flags.append(np.array2string(value.ravel(), precision=4, separator=","))
        return f"ndarray({value.dtype}, {value.shape}{', ' if flags else ''}{' '.join(flags)})"
    if isinstance(value, svs.PointCloud):
        label = FIXTURE_NAMES.get(id(value))
        return label or f"PointCloud({len(value)}{' with normals' if value.has_normals else ''})"
    if isinstance(value, (list, tuple)) and len(value) > 4:
        return f"{type(value).__name__}(len {len(value)}, first {short(value[0])})"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}={short(v)}" for k, v in value.items()) + "}"
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def call_text(label: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> str:
    parts = [short(a) for a in args] + [f"{k}={short(v)}" for k, v in kwargs.items()]
    return f"{label}({', '.join(parts)})"


# --- Checks of a result ------------------------------------------------------------------

#: Fields whose values may be NaN (documented: an invalid pixel, no registration yet).
NAN_ALLOWED = {
    ("OrganizedCloud", "points"),
    ("OrganizedCloud", "normals"),
    ("load_organized", ""),
    ("ServoRecord", "*"),
}
#: Fields whose values may be infinite (documented: a continuous joint has no limits).
INF_ALLOWED = {
    ("Kinematics", "lower_limits"),
    ("Kinematics", "upper_limits"),
    ("Kinematics", "velocity_limits"),
}
#: Fields documented in [0, 1].
UNIT_FIELDS = {
    "AlignResult": ("fitness", "confidence", "score", "inlier_fraction"),
    "AlignAlternative": ("confidence", "score"),
    "ViewAlignResult": ("confidence", "score", "inlier_fraction"),
    "ViewAlternative": ("confidence", "score"),
    "ViewSupport": ("fitness", "overlap", "score"),
    "TranslationEstimate": ("peak",),
    "DominantPlane": ("share",),
    "SingleViewEvidence": ("visible",),
    "PoseVerification": ("confidence", "inlier_fraction"),
    "VelocityCommand": ("velocity_scale",),
}
#: Settings: their constructors echo any value of the right type (checked where used).
SETTINGS_TYPES = (
    "AlignParams",
    "SceneParams",
    "LocalParams",
    "GlobalSearchParams",
    "RefinementParams",
    "VerificationParams",
    "ViewAlignParams",
    "DampingParams",
    "VelocityCommandParams",
    "ServoParams",
)


class BadResult(AssertionError):
    """A result that is not finite, not in its documented range, or not rigid."""


def check_number(value: float, owner: str, name: str) -> None:
    allowed_nan = (owner, name) in NAN_ALLOWED or (owner, "*") in NAN_ALLOWED
    allowed_inf = (owner, name) in INF_ALLOWED
    if math.isnan(value) and not allowed_nan:
        raise BadResult(f"{owner}.{name} is NaN")
    if math.isinf(value) and not allowed_inf:
        raise BadResult(f"{owner}.{name} is {value}")


def check_array(value: np.ndarray, owner: str, name: str) -> None:
    if value.dtype.kind not in "fc" or value.size == 0:
        return
    allowed_nan = (owner, name) in NAN_ALLOWED or (owner, "*") in NAN_ALLOWED
    allowed_inf = (owner, name) in INF_ALLOWED
    if not allowed_nan and np.isnan(value).any():
        raise BadResult(f"{owner}.{name} has NaN entries (shape {value.shape})")
    if not allowed_inf and np.isinf(value).any():
        raise BadResult(f"{owner}.{name} has infinite entries (shape {value.shape})")
    finite = np.isfinite(value).all()
    if finite and value.shape == (4, 4) and (name.startswith("T_") or name == "pose"):
        check_rigid(value, f"{owner}.{name}")
    if finite and value.shape == (3, 3) and name in ("R", "rotation"):
        check_rotation(value, f"{owner}.{name}")


def check_rotation(R: np.ndarray, what: str) -> None:
    error = max(np.abs(R.T @ R - np.eye(3)).max(), abs(np.linalg.det(R) - 1.0))
    if not error < 1e-6:
        raise BadResult(f"{what} is not a rotation: max |R^T R - I|, |det R - 1| = {error:.3g}")


def check_rigid(T: np.ndarray, what: str) -> None:
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise BadResult(f"{what} has the bottom row {T[3].tolist()}")
    check_rotation(T[:3, :3], what)


def check_value(value: Any, owner: str = "", name: str = "", depth: int = 0) -> None:
    """Raise BadResult unless ``value`` is finite where it is numeric (recursively through
    tuples, lists, dataclasses and the compiled module's result objects), its poses rigid
    and its documented shares in [0, 1]."""
    if depth > 5 or value is None or isinstance(value, (bool, str, bytes, int, np.bool_)):
        return
    if isinstance(value, (float, np.floating)):
        check_number(float(value), owner, name)
        return
    if isinstance(value, np.ndarray):
        check_array(value, owner, name)
        return
    if isinstance(value, (list, tuple)):
        for item in value:
            check_value(item, owner, name, depth + 1)
        return
    if isinstance(value, dict):
        for key, item in value.items():
            check_value(item, owner, str(key), depth + 1)
        return
    if isinstance(value, svs.PointCloud):
        try:
            assert_finite(value)
        except AssertionError as error:
            raise BadResult(f"PointCloud {name} with non-finite points or normals") from error
        return
    kind = type(value).__name__
    if kind in SETTINGS_TYPES:
        return
    if dataclasses.is_dataclass(value):
        for item in dataclasses.fields(value):
            check_value(getattr(value, item.name), kind, item.name, depth + 1)
        return
    if type(value).__module__ == "spectral_vs._core":
        for attribute, member in vars(type(value)).items():
            if attribute.startswith("_") or not isinstance(member, property):
                continue
            item = getattr(value, attribute)
            check_value(item, kind, attribute, depth + 1)
            if attribute in UNIT_FIELDS.get(kind, ()) and not 0.0 <= float(item) <= 1.0:
                raise BadResult(f"{kind}.{attribute} = {item} is outside [0, 1]")


def no_check(value: Any) -> None:
    """For calls that echo what they are given (settings, records)."""


# --- The probe: one call, bounded and classified -------------------------------------------


class Refused:
    """The result of a call that raised a documented exception."""

    def __repr__(self) -> str:
        return "REFUSED"


REFUSED: Any = Refused()


def reset_peak() -> None:
    """Start the peak resident memory (ru_maxrss, VmHWM) afresh, where the kernel allows."""
    with contextlib.suppress(OSError), open("/proc/self/clear_refs", "w") as clear:
        clear.write("5")


def peak_megabytes() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


@dataclass
class Stats:
    """What one entry's calls did."""

    examples: int = 0
    calls: int = 0
    returned: int = 0
    refused: dict[str, int] = field(default_factory=dict)
    slowest: float = 0.0
    slowest_call: str = ""
    most_megabytes: float = 0.0


class Probe:
    """Runs the calls of one worker: each call announced in the last-call file, timed,
    measured and classified; findings appended to the report."""

    def __init__(self, last_call: Path, report: Path) -> None:
        self.last_call = last_call
        self.report = report
        self.entry = ""
        self.raises: tuple[type[BaseException], ...] = DOCUMENTED
        self.stats: dict[str, Stats] = {}
        self.seen: dict[tuple[str, ...], dict[str, Any]] = {}
        #: The calls of the current example so far: the context of a finding (the
        #: constructor call before a method call).
        self.example: list[str] = []

    def announce(self, text: str) -> None:
        payload = json.dumps(
            {"entry": self.entry, "call": text, "after": self.example[-3:], "pid": os.getpid()}
        )
        with open(self.last_call, "w") as out:
            out.write(payload)

    def finding(self, kind: str, text: str, detail: str) -> None:
        key_detail = re.sub(r"0x[0-9a-f]+|[-+]?\d[\d.e+-]*", "#", detail)[:120]
        key = (self.entry, kind, key_detail)
        if key in self.seen:
            self.seen[key]["count"] += 1
            return
        record = {"finding": kind, "entry": self.entry, "call": text, "detail": detail, "count": 1}
        context = [call for call in self.example[-4:] if call != text][-3:]
        if context:
            record["after"] = context
        self.seen[key] = record
        with open(self.report, "a") as out:
            out.write(json.dumps(record) + "\n")
        print(f"FINDING [{kind}] {text}: {detail}", file=sys.stderr, flush=True)

    def __call__(
        self,
        label: str,
        function: Callable[..., Any],
        *args: Any,
        _raises: tuple[type[BaseException], ...] | None = None,
        _check: Callable[[Any], None] = check_value,
        _max_voxels: Any = None,
        **kwargs: Any,
    ) -> Any:
        """``function(*args, **kwargs)``, or REFUSED when it raised a documented exception.
        ``_max_voxels``: the grid budget the call was given, which grants it memory."""
        text = call_text(label, args, kwargs)
        stats = self.stats.setdefault(self.entry, Stats())
        stats.calls += 1
        self.announce(text)
        self.example.append(text)
        reset_peak()
        before = resident_megabytes()
        start = time.monotonic()
        value = REFUSED
        accepted = _raises or self.raises
        megabytes = LIMIT_MEGABYTES
        if raised_budget(_max_voxels):
            # The caller's decision (docs/reliability.md): memory in proportion, and
            # MemoryError where the machine cannot hold what the budget allows.
            accepted = (*accepted, MemoryError)
            megabytes = max(megabytes, _max_voxels * BYTES_PER_VOXEL / 2**20)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                value = function(*args, **kwargs)
        except accepted as error:
            name = type(error).__name__
            stats.refused[name] = stats.refused.get(name, 0) + 1
        except Exception as error:
            self.finding("exception", text, f"{type(error).__name__}: {error}"[:400])
        seconds = time.monotonic() - start
        grown = peak_megabytes() - before
        if seconds > stats.slowest:
            stats.slowest, stats.slowest_call = seconds, text
        stats.most_megabytes = max(stats.most_megabytes, grown)
        if seconds > LIMIT_SECONDS:
            self.finding("slow", text, f"took {seconds:.1f} s (limit {LIMIT_SECONDS:g} s)")
        if grown > megabytes:
            self.finding(
                "memory", text, f"resident memory grew by {grown:.0f} MB (limit {megabytes:g})"
            )
        if value is not REFUSED:
            stats.returned += 1
            try:
                _check(value)
            except BadResult as error:
                self.finding("bad result", text, str(error))
            except Exception as error:  # reading a property of the result raised
                self.finding("exception", f"reading the result of {text}", repr(error)[:400])
        return value


# --- Fixtures ----------------------------------------------------------------------------

FIXTURE_NAMES: dict[int, str] = {}


def named(label: str, cloud: svs.PointCloud) -> svs.PointCloud:
    FIXTURE_NAMES[id(cloud)] = label
    return cloud


class Fixtures:
    """The inputs every entry draws from: small clouds (and degenerate ones), grids,
    coefficients, the test arm's URDF and a folder of files."""

    def __init__(self) -> None:
        points, normals = box_and_sphere(np.random.default_rng(5), samples=400)
        self.T = rigid(svs.so3_exp([0.1, -0.2, 0.3]), (0.02, -0.01, 0.03))
        self.model = named("MODEL", svs.PointCloud(points, normals))
        self.scene = named("SCENE", self.model.transformed(self.T))
        self.points = named("MODEL_POINTS", svs.PointCloud(points))
        line = np.c_[np.linspace(0.0, 0.2, 50), np.zeros(50), np.zeros(50)] + (0, 0, 0.5)
        rng = np.random.default_rng(3)
        plane = np.c_[rng.uniform(-0.1, 0.1, (200, 2)), np.full(200, 0.6)]
        scene_points, scene_normals = table_top(spacing=0.015)
        self.reference = named("VIEW_REFERENCE", view((scene_points, scene_normals), camera_pose()))
        self.current = named(
            "VIEW_CURRENT",
            view((scene_points, scene_normals), camera_pose((0.01, -0.01, 0.0), (1.0, -1.0, 2.0))),
        )
        self.table = (scene_points, scene_normals)
        # The scene with two stray returns 2 m off: grids span them.
        stray = np.array([[1.9, 1.9, 1.9], [-0.1, -0.1, -0.1]])
        self.stray = named(
            "STRAY", svs.PointCloud(np.vstack([points + 0.02, stray]), np.r_[normals, normals[:2]])
        )
        self.clouds = [
            self.model,
            self.scene,
            self.points,
            self.reference,
            self.current,
            named("SPARSE", svs.PointCloud(points[:30], normals[:30])),
            named("ONE_POINT", svs.PointCloud(points[:1], normals[:1])),
            named("COINCIDENT", svs.PointCloud(np.tile(points[:1], (20, 1)))),
            named("LINE", svs.PointCloud(line)),
            named("PLANE", svs.PointCloud(plane, np.tile([0.0, 0.0, -1.0], (200, 1)))),
            named("FAR", svs.PointCloud(points + 1e6, normals)),
            named("HUGE", svs.PointCloud(points * 1e4, normals)),
            named("VAST", svs.PointCloud(points * 1e200, normals)),
            named("TINY", svs.PointCloud(points * 1e-7, normals)),
            named("EMPTY", svs.PointCloud(np.zeros((0, 3)))),
            self.stray,
        ]
        self.spec = svs.make_grid_spec(self.model, self.scene, 0.01)
        self.grid_a = svs.voxelize(self.model, self.spec)
        self.grid_b = svs.voxelize(self.scene, self.spec)
        self.urdf_path = ROOT / "tests" / "data" / "test_arm.urdf"
        self.urdf = self.urdf_path.read_text()
        self.links = ["world", "base_link", "link1", "link3", "link6", "tool", "sensor_mount"]
        self.kinematics = svs.Kinematics.from_urdf_string(self.urdf, "base_link", "tool")
        scratch = os.environ.get("SPECTRAL_VS_HARNESS_SCRATCH")  # the supervisor's, if any
        self.folder = Path(tempfile.mkdtemp(prefix="api_harness_", dir=scratch))
        self.paths = self._files()

    @cache  # noqa: B019 (one Fixtures per process)
    def coefficients(self, bandwidth: int) -> np.ndarray:
        return svs.egi_coefficients(self.model, bandwidth)

    @cache  # noqa: B019
    def scene_coefficients(self, bandwidth: int) -> np.ndarray:
        return svs.egi_coefficients(self.scene, bandwidth)

    def _files(self) -> list[Any]:
        """Paths to load: valid clouds, corrupted ones, the real scans, a folder, a missing
        file, a FIFO, a symbolic link loop, a device, a name too long, wrong types."""
        folder = self.folder
        svs.save_cloud(folder / "model.pcd", self.model, "binary")
        svs.save_cloud(folder / "compressed.pcd", self.model, "binary_compressed")
        svs.save_cloud(folder / "ascii.pcd", self.model, "ascii")
        svs.save_cloud(folder / "model.ply", self.model)
        binary = (folder / "model.pcd").read_bytes()
        compressed = (folder / "compressed.pcd").read_bytes()
        (folder / "truncated.pcd").write_bytes(binary[: len(binary) // 2])
        (folder / "truncated_compressed.pcd").write_bytes(compressed[: len(compressed) // 2])
        (folder / "inflated.pcd").write_bytes(
            compressed.replace(b"WIDTH 400", b"WIDTH 400000000").replace(
                b"POINTS 400", b"POINTS 400000000"
            )
        )
        (folder / "garbage.pcd").write_bytes(b"VERSION 0.7\n" + bytes(range(256)) * 4)
        (folder / "empty.pcd").write_bytes(b"")
        (folder / "not_a_cloud.ply").write_bytes(b"solid cube\nfacet normal 0 0 1\n")
        (folder / "cloud.xyz").write_bytes(b"0 0 0\n")
        (folder / "deep.urdf").write_text("<robot>" + "<a>" * 5000 + "</a>" * 5000 + "</robot>")
        (folder / "arm.urdf").write_text(self.urdf)
        (folder / "sub").mkdir()
        fifo = folder / "pipe.pcd"
        os.mkfifo(fifo)
        loop = folder / "loop.pcd"
        loop.symlink_to(loop.name)
        paths: list[Any] = [
            folder / name
            for name in (
                "model.pcd",
                "compressed.pcd",
                "ascii.pcd",
                "model.ply",
                "truncated.pcd",
                "truncated_compressed.pcd",
                "inflated.pcd",
                "garbage.pcd",
                "empty.pcd",
                "not_a_cloud.ply",
                "cloud.xyz",
                "deep.urdf",
                "arm.urdf",
                "sub",
                "missing.pcd",
                "pipe.pcd",
                "loop.pcd",
            )
        ]
        data = Path(os.environ.get("SPECTRAL_VS_DATA", ROOT.parent / "shared" / "data"))
        paths += [data / "milk.pcd", data / "bun0.pcd"]
        paths += [os.devnull, str(folder / ("a" * 5000 + ".pcd")), "", "a\0b.pcd"]
        paths += [str(folder / "model.pcd").encode(), 3, None]
        return paths

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


@cache
def fixtures() -> Fixtures:
    return Fixtures()


# --- Strategies over the fixtures ----------------------------------------------------------


def clouds() -> st.SearchStrategy[svs.PointCloud]:
    return st.sampled_from(fixtures().clouds)


def cloud_likes() -> st.SearchStrategy[Any]:
    """A fixture cloud, or an array of any shape and dtype, or a wrong type."""
    return st.one_of(clouds(), clouds(), arrays(), wrong)


BANDWIDTHS = (1, 2, 3, 4, 8, 16, 32)


def bandwidth_of(i: int) -> int:
    return 128 if i == 0 else BANDWIDTHS[i % len(BANDWIDTHS)]


def bandwidth_coefficients() -> st.SearchStrategy[tuple[int, np.ndarray]]:
    """(B, coefficients of the model at B): B in 1-32, or 128 (the largest) one time in 20."""
    return st.integers(0, 19).map(bandwidth_of).map(lambda B: (B, fixtures().coefficients(B)))


def coefficient_arrays(bandwidth: int) -> st.SearchStrategy[Any]:
    """The model's coefficients at ``bandwidth``, or broken ones."""
    good = fixtures().coefficients(bandwidth)
    broken = [good * 1e300, good[:-1], np.zeros_like(good), np.full_like(good, math.nan)]
    return st.one_of(
        st.just(good), st.just(fixtures().scene_coefficients(bandwidth)), st.sampled_from(broken)
    ) | st.one_of(arrays(), wrong)


def paths() -> st.SearchStrategy[Any]:
    return st.sampled_from(fixtures().paths)


#: Documented integer bounds of settings, by field name: drawn at, inside and one beyond.
INT_BOUNDS: dict[str, tuple[int, ...]] = {
    "bandwidth": (1, 2, 64, 128),
    "threads": (1, 256),
    "max_alternatives": (0, 64),
    "hypotheses": (1,),
    "refinements": (1,),
    "max_iterations": (0, 1),
    "refinement_iterations": (1,),
    "max_voxels": (1, 2**24, 2**32),
    "plane_turn_bandwidth": (2, 128),
}
#: Documented float bounds, by field name.
FLOAT_BOUNDS: dict[str, tuple[float, ...]] = {
    "translation_gain": (0.0, 1.0),
    "rotation_gain": (0.0, 1.0),
    "reselect_margin": (0.0, 1.0),
    "guess_angle_deg": (0.0, 180.0),
    "window_search_below": (0.0, 1.0),
    "voxels_across": (4.0,),
    "plane_cone": (0.0, math.pi / 2),
    "limit_avoidance_exponent": (1.0,),
}
#: The choices of string settings.
CHOICES: dict[str, tuple[str, ...]] = {
    "occupancy": ("binary", "count", "trilinear"),
    "egi_method": ("projection", "histogram"),
    "scene_view": ("auto", "single_view", "all_sides"),
    "rotation_step": ("newton", "gradient"),
    "mode": ("iteration", "pose"),
}


def setting_values(name: str, default: Any) -> st.SearchStrategy[Any]:
    """Values of a setting from its name and the type of its default."""
    if isinstance(default, bool):
        return st.one_of(st.booleans(), wrong)
    if isinstance(default, int):
        return sometimes_wrong(ints(*INT_BOUNDS.get(name, ())))
    if isinstance(default, float):
        return sometimes_wrong(reals(*FLOAT_BOUNDS.get(name, ())))
    if isinstance(default, str):
        choices = CHOICES.get(name, (default,))
        return st.one_of(
            st.sampled_from(choices), st.sampled_from(["", "NEWTON", "x" * 300]), wrong
        )
    if isinstance(default, np.ndarray) and default.shape == (4, 4):
        return transforms()
    if isinstance(default, np.ndarray):
        return st.one_of(vectors, st.none())
    if isinstance(default, dict):
        return st.sampled_from([{}, {"threads": 2}, {"threads": 10**6}, {"nope": 1}, {"_x": 1}])
    return wrong


def settings_fields(kind: type) -> dict[str, Any]:
    """The settable fields of a bound settings type and their defaults (groups left out)."""
    instance = kind()
    groups = set(getattr(kind, "_groups", ()))
    out = {}
    for name, member in vars(kind).items():
        if name.startswith("_") or name in groups or not isinstance(member, property):
            continue
        if member.fset is None:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[name] = getattr(instance, name)
    return out


@st.composite
def overrides(draw: st.DrawFn, fields: dict[str, Any], at_most: int = 2) -> dict[str, Any]:
    """Up to ``at_most`` fields set to drawn values, the rest left at their defaults: one
    or two settings out of range at a time reach the checks of the others."""
    names = draw(st.lists(st.sampled_from(sorted(fields)), max_size=at_most, unique=True))
    return {name: draw(setting_values(name, fields[name])) for name in names}


def servo_fields() -> dict[str, Any]:
    out: dict[str, Any] = {}
    for kind in (
        stage_settings.RegistrationParams,
        stage_settings.LawParams,
        stage_settings.StopParams,
        stage_settings.WatchdogParams,
        fault_settings.FaultParams,
        fault_settings.RelocalizationParams,
        fault_settings.RecoveryParams,
        stage_settings.PlaneTurnParams,
    ):
        instance = kind()
        for item in dataclasses.fields(kind):
            out[item.name] = getattr(instance, item.name)
    return out


#: A table drawn from: every integer setting of the servo, by name, with its documented
#: lower bound (the checks of spectral_vs.servo.setting_checks).
INT_BOUNDS.update(
    {
        "min_points": (1,),
        "reengage_steps": (1,),
        "relocalize_interval": (1,),
        "relocalize_retry": (1,),
        "relocalize_backoff": (1,),
        "refute_steps": (1,),
        "recover_after": (0,),
        "recover_steps": (1,),
        "recover_retry": (1,),
        "recover_widen": (0,),
        "plane_turn_stride": (1,),
    }
)


@st.composite
def depth_images(draw: st.DrawFn) -> Any:
    """Depth images: uint16 millimetres, float metres (with NaN, inf, 0 and negative
    returns), of 1 x 1 to 40 x 48 pixels; or wrong dtypes and shapes."""
    h, w = draw(st.integers(1, 40)), draw(st.integers(1, 48))
    kind = draw(st.sampled_from(["uint16", "float32", "float64", "float64", "bad"]))
    rng = np.random.default_rng(draw(seeds))
    metres = rng.uniform(0.3, 2.0, (h, w))
    if kind == "uint16":
        image: Any = (metres * 1000).astype(np.uint16)
        image[rng.random((h, w)) < 0.1] = draw(st.sampled_from([0, 65535]))
        return image
    if kind == "bad":
        return draw(
            st.sampled_from(
                [
                    metres.astype(np.int32),
                    metres.astype(np.float16),
                    metres.astype(bool),
                    metres[None],
                    metres.ravel(),
                    np.zeros((0, 5)),
                    metres.astype(object),
                    metres.tolist(),
                ]
            )
        )
    image = metres.astype(kind)
    special = draw(st.sampled_from([None, math.nan, math.inf, -1.0, 0.0, 1e300, 1e-300]))
    if special is not None:
        image[rng.random((h, w)) < 0.2] = special
    return image


def camera_matrices(height: int = 40, width: int = 48) -> st.SearchStrategy[Any]:
    K = np.array([[50.0, 0.0, width / 2], [0.0, 50.0, height / 2], [0.0, 0.0, 1.0]])
    broken = []
    for index, value in [(0, 0.0), (0, -50.0), (4, math.nan), (1, 1.0), (8, 2.0), (2, math.inf)]:
        B = K.copy()
        B.flat[index] = value
        broken.append(B)
    broken += [K * 1e300, K[:2], K.ravel(), K.astype(int), np.eye(3) * 1e-300]
    return st.one_of(st.just(K), st.sampled_from(broken), arrays(), wrong)


# --- The table ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Entry:
    """One public name: ``run(probe, data)`` draws its arguments (``data.draw``) and makes
    its calls through ``probe``. ``share`` scales the examples (slow calls run fewer);
    ``raises``, the exceptions documented for it."""

    name: str
    run: Callable[[Probe, Any], None]
    share: float = 1.0
    raises: tuple[type[BaseException], ...] = DOCUMENTED


TABLE: dict[str, Entry] = {}
#: Public callables the harness does not call, with the reason.
EXCLUDED: dict[str, str] = {}


def entry(
    name: str, share: float = 1.0, raises: tuple[type[BaseException], ...] = DOCUMENTED
) -> Callable[[Callable[[Probe, Any], None]], Callable[[Probe, Any], None]]:
    def register(run: Callable[[Probe, Any], None]) -> Callable[[Probe, Any], None]:
        if name in TABLE:
            raise ValueError(f"{name} has two entries")
        TABLE[name] = Entry(name, run, share, raises)
        return run

    return register


def ok(value: Any) -> bool:
    return value is not REFUSED


# Representation ------------------------------------------------------------------------


@entry("PointCloud")
def _point_cloud(probe: Probe, data: Any) -> None:
    F = fixtures()
    points = data.draw(st.one_of(arrays(), st.just(np.asarray(F.model.points)), wrong))
    normals = data.draw(st.one_of(st.none(), arrays(), st.just(np.asarray(F.model.normals))))
    drop = data.draw(st.one_of(st.booleans(), wrong))
    cloud = probe("PointCloud", svs.PointCloud, points, normals, drop_non_finite=drop)
    if not ok(cloud):
        return
    probe("len(PointCloud)", len, cloud)
    probe("PointCloud.centroid", cloud.centroid)
    keep = data.draw(
        st.one_of(
            st.just(np.ones(len(cloud), bool)),
            st.just(np.arange(len(cloud)) % 2 == 0),
            st.just(np.ones(len(cloud) + 1, bool)),
            st.just(np.ones(len(cloud), np.int64)),
            arrays(),
            wrong,
        )
    )
    probe("PointCloud.select", cloud.select, keep)
    probe("PointCloud.transformed", cloud.transformed, data.draw(transforms()))


@entry("load_cloud", raises=FILE_ERRORS)
def _load_cloud(probe: Probe, data: Any) -> None:
    probe("load_cloud", svs.load_cloud, data.draw(paths()))


@entry("load_cloud_with_info", raises=FILE_ERRORS)
def _load_cloud_with_info(probe: Probe, data: Any) -> None:
    probe("load_cloud_with_info", svs.load_cloud_with_info, data.draw(paths()))


@entry("load_organized", raises=FILE_ERRORS)
def _load_organized(probe: Probe, data: Any) -> None:
    probe(
        "load_organized",
        svs.load_organized,
        data.draw(paths()),
        _check=lambda value: check_value(value, "load_organized", ""),  # NaN: no return
    )


@entry("save_cloud", raises=FILE_ERRORS)
def _save_cloud(probe: Probe, data: Any) -> None:
    folder = fixtures().folder
    name = data.draw(
        st.sampled_from(
            [
                "out.pcd",
                "out.ply",
                "out.PCD",
                "out.xyz",
                "sub",
                "missing/out.pcd",
                "pipe.pcd",
                "pipe.ply",
                "a" * 300 + ".pcd",
                "",
            ]
        )
    )
    if name in ("pipe.ply",) and not (folder / name).exists():
        os.mkfifo(folder / name)
    path = data.draw(st.one_of(st.just(str(folder / name)), st.just(folder / name), wrong))
    encoding = data.draw(
        st.one_of(
            st.sampled_from(["binary", "ascii", "binary_compressed", "BINARY", "", "x" * 100]),
            wrong,
        )
    )
    cloud = data.draw(cloud_likes())
    probe("save_cloud", svs.save_cloud, path, cloud, encoding)


@entry("dominant_direction")
def _dominant_direction(probe: Probe, data: Any) -> None:
    normals = data.draw(st.one_of(st.just(np.asarray(fixtures().model.normals)), arrays(), wrong))
    probe(
        "dominant_direction",
        svs.dominant_direction,
        normals,
        data.draw(sometimes_wrong(reals(0.0, math.pi / 2))),
        data.draw(sometimes_wrong(reals(0.0, math.pi / 2))),
    )


@entry("dominant_plane")
def _dominant_plane(probe: Probe, data: Any) -> None:
    kwargs = {
        name: data.draw(sometimes_wrong(reals(*bounds)))
        for name, bounds in [
            ("direction_cone", (0.0, math.pi / 2)),
            ("member_cone", (0.0, math.pi / 2)),
            ("offset_bin", (0.0,)),
            ("band", (0.0,)),
            ("min_share", (0.0, 1.0)),
        ]
        if data.draw(st.booleans())
    }
    probe("dominant_plane", svs.dominant_plane, data.draw(cloud_likes()), **kwargs)


@entry("voxel_downsample")
def _voxel_downsample(probe: Probe, data: Any) -> None:
    probe(
        "voxel_downsample",
        svs.voxel_downsample,
        data.draw(cloud_likes()),
        data.draw(sometimes_wrong(reals(0.0, 1e-3, 1e6))),
    )


@entry("estimate_normals", share=0.5)
def _estimate_normals(probe: Probe, data: Any) -> None:
    kwargs: dict[str, Any] = {}
    if data.draw(st.booleans()):
        kwargs["radius"] = data.draw(sometimes_wrong(reals(0.0, 0.015)))
    if data.draw(st.booleans()):
        kwargs["k_neighbors"] = data.draw(sometimes_wrong(ints(0)))
    if data.draw(st.booleans()):
        kwargs["viewpoint"] = data.draw(vectors)
    if data.draw(st.booleans()):
        kwargs["orientation"] = data.draw(
            st.one_of(st.sampled_from(["toward_viewpoint", "outward", "inward"]), wrong)
        )
    if data.draw(st.booleans()):
        kwargs["threads"] = data.draw(sometimes_wrong(ints(1, 256)))
    probe("estimate_normals", svs.estimate_normals, data.draw(cloud_likes()), **kwargs)


@entry("prepare_cloud", share=0.5)
def _prepare_cloud(probe: Probe, data: Any) -> None:
    kwargs: dict[str, Any] = {}
    if data.draw(st.booleans()):
        kwargs["downsample"] = data.draw(st.one_of(st.booleans(), wrong))
    if data.draw(st.booleans()):
        kwargs["viewpoint"] = data.draw(vectors)
    if data.draw(st.booleans()):
        kwargs["argument"] = data.draw(st.one_of(st.sampled_from(["model", "scene"]), wrong))
    probe(
        "prepare_cloud",
        svs.prepare_cloud,
        data.draw(cloud_likes()),
        data.draw(sometimes_wrong(reals(0.0, 1e-3, 1e6))),
        **kwargs,
    )


@entry("GridSpec")
def _grid_spec(probe: Probe, data: Any) -> None:
    dims = data.draw(
        st.one_of(
            st.tuples(ints(1, 2**30), ints(1, 2**30), ints(1, 2**30)).map(list),
            st.sampled_from([[8, 8, 8], [1, 1, 1], [40, 30, 20]]),
            arrays(),
            wrong,
        )
    )
    origin = data.draw(st.one_of(st.just(np.zeros(3)), vectors))
    resolution = data.draw(sometimes_wrong(reals(0.0, 0.01)))
    spec = probe("GridSpec", svs.GridSpec, origin, resolution, dims)
    if not ok(spec):
        return
    count = probe("GridSpec.voxel_count", lambda: spec.voxel_count)
    if ok(count) and count != math.prod(int(n) for n in spec.dims):
        probe.finding(
            "bad result", f"GridSpec.voxel_count of dims {spec.dims.tolist()}", f"{count}"
        )
    probe("GridSpec.index_of", spec.index_of, data.draw(vectors))
    cloud = data.draw(clouds())
    occupancy = data.draw(st.sampled_from(["binary", "count", "trilinear"]))
    grid = probe("voxelize", svs.voxelize, cloud, spec, occupancy)
    pc = probe("PhaseCorrelation", svs.PhaseCorrelation, spec)
    if ok(grid) and ok(pc):
        if ok(probe("PhaseCorrelation.set_target", pc.set_target, grid)):
            probe("PhaseCorrelation.estimate", pc.estimate, grid)


@entry("fft_friendly_size")
def _fft_friendly_size(probe: Probe, data: Any) -> None:
    n = data.draw(sometimes_wrong(ints(0, 2, 1024, 2**30)))
    value = probe("fft_friendly_size", svs.fft_friendly_size, n)
    if ok(value) and isinstance(n, int) and not (value >= n and value >= 2):
        probe.finding("bad result", f"fft_friendly_size({n})", f"returned {value} < n")


@entry("make_grid_spec")
def _make_grid_spec(probe: Probe, data: Any) -> None:
    spec = probe(
        "make_grid_spec",
        svs.make_grid_spec,
        data.draw(cloud_likes()),
        data.draw(cloud_likes()),
        data.draw(sometimes_wrong(reals(0.0, 0.01))),
        data.draw(sometimes_wrong(ints(1, 2**24, 2**32))),
    )
    if ok(spec):
        probe("GridSpec.voxel_count", lambda: spec.voxel_count)


@entry("voxelize")
def _voxelize(probe: Probe, data: Any) -> None:
    F = fixtures()
    spec = data.draw(
        st.one_of(
            st.just(F.spec),
            st.sampled_from(
                [
                    svs.GridSpec(np.zeros(3), 0.01, [2**10, 2**10, 2**10]),
                    svs.GridSpec(np.zeros(3), 1e-300, [4, 4, 4]),
                    svs.GridSpec(np.full(3, -1e300), 1e300, [4, 4, 4]),
                    svs.GridSpec(np.zeros(3), 0.01, [1, 1, 2**30]),
                ]
            ),
            wrong,
        )
    )
    occupancy = data.draw(
        st.one_of(st.sampled_from(["binary", "count", "trilinear", "Binary", ""]), wrong)
    )
    max_voxels = data.draw(sometimes_wrong(ints(1, 2**24, 2**32)))
    grid = probe(
        "voxelize",
        svs.voxelize,
        data.draw(cloud_likes()),
        spec,
        occupancy,
        max_voxels,
        _max_voxels=max_voxels,
    )
    if ok(grid):
        probe("VoxelGrid.values", lambda: np.asarray(grid.values).sum())


def grids() -> st.SearchStrategy[Any]:
    """VoxelGrids on the fixtures' spec, or 3-D arrays (unit voxels) of any size up to
    24 per axis, with NaN, inf or huge values, or wrong shapes and types."""
    F = fixtures()

    @st.composite
    def volumes(draw: st.DrawFn) -> np.ndarray:
        shape = tuple(draw(st.integers(0, 24)) for _ in range(3))
        rng = np.random.default_rng(draw(seeds))
        values = (rng.random(shape) < 0.3).astype(draw(st.sampled_from([np.float32, np.float64])))
        special = draw(st.sampled_from([None, None, math.nan, math.inf, 1e300, -1.0]))
        if special is not None and values.size:
            values.flat[rng.integers(values.size)] = special
        return values

    return st.one_of(st.sampled_from([F.grid_a, F.grid_b]), volumes(), arrays(), wrong)


@entry("phase_correlation")
def _phase_correlation(probe: Probe, data: Any) -> None:
    a = data.draw(grids())
    b = data.draw(st.one_of(st.just(a), grids()))
    kwargs: dict[str, Any] = {}
    if data.draw(st.booleans()):
        kwargs["subvoxel"] = data.draw(st.one_of(st.booleans(), wrong))
    if data.draw(st.booleans()):
        kwargs["subvoxel_band"] = data.draw(sometimes_wrong(reals(0.0, 0.5)))
    if data.draw(st.booleans()):
        kwargs["max_voxels"] = data.draw(sometimes_wrong(ints(1, 2**24, 2**32)))
    probe(
        "phase_correlation",
        svs.phase_correlation,
        a,
        b,
        _max_voxels=kwargs.get("max_voxels"),
        **kwargs,
    )


shifts = st.one_of(
    st.tuples(ints(), ints(), ints()).map(list),
    st.sampled_from([[0, 0, 0], [1, -1, 2], [5, 5, 5]]),
    vectors,
)


@entry("translation_cost")
def _translation_cost(probe: Probe, data: Any) -> None:
    a = data.draw(grids())
    b = data.draw(st.one_of(st.just(a), grids()))
    probe("translation_cost", svs.translation_cost, a, b, data.draw(shifts))


@entry("PhaseCorrelation")
def _phase_correlation_class(probe: Probe, data: Any) -> None:
    F = fixtures()
    spec = data.draw(
        st.one_of(
            st.just(F.spec),
            st.sampled_from([svs.GridSpec(np.zeros(3), 0.01, [2**30, 2**30, 2**30])]),
            wrong,
        )
    )
    kwargs: dict[str, Any] = {}
    for name, strategy in [
        ("subvoxel", st.one_of(st.booleans(), wrong)),
        ("subvoxel_band", sometimes_wrong(reals(0.0, 0.5))),
        ("threads", sometimes_wrong(ints(1, 256))),
        ("max_voxels", sometimes_wrong(ints(1, 2**24, 2**32))),
    ]:
        if data.draw(st.booleans()):
            kwargs[name] = data.draw(strategy)
    pc = probe(
        "PhaseCorrelation",
        svs.PhaseCorrelation,
        spec,
        _max_voxels=kwargs.get("max_voxels"),
        **kwargs,
    )
    if not ok(pc):
        return
    probe("PhaseCorrelation.has_target", lambda: pc.has_target)
    if data.draw(st.booleans()):  # before a target: documented ValueError
        probe("PhaseCorrelation.estimate", pc.estimate, F.grid_b)
    if not ok(probe("PhaseCorrelation.set_target", pc.set_target, data.draw(grids()))):
        return
    max_shift = data.draw(st.one_of(st.none(), shifts))
    if data.draw(st.booleans()):
        probe("PhaseCorrelation.estimate", pc.estimate, data.draw(grids()), max_shift)
    else:
        probe("PhaseCorrelation.estimate", pc.estimate, F.grid_b, max_shift_voxels=max_shift)


@entry("egi")
def _egi(probe: Probe, data: Any) -> None:
    weights = data.draw(st.one_of(st.none(), arrays(), st.just(np.ones(400)), wrong))
    probe(
        "egi",
        svs.egi,
        data.draw(cloud_likes()),
        data.draw(sometimes_wrong(ints(1, 128))),
        weights,
    )


@entry("egi_cell")
def _egi_cell(probe: Probe, data: Any) -> None:
    probe("egi_cell", svs.egi_cell, data.draw(vectors), data.draw(sometimes_wrong(ints(1, 128))))


@entry("sphere_grid")
def _sphere_grid(probe: Probe, data: Any) -> None:
    probe("sphere_grid", svs.sphere_grid, data.draw(sometimes_wrong(ints(1, 128))))


@entry("egi_coefficients")
def _egi_coefficients(probe: Probe, data: Any) -> None:
    method = data.draw(st.one_of(st.sampled_from(["projection", "histogram", "fft"]), wrong))
    weights = data.draw(st.one_of(st.none(), arrays(), st.just(np.ones(400)), wrong))
    probe(
        "egi_coefficients",
        svs.egi_coefficients,
        data.draw(cloud_likes()),
        data.draw(sometimes_wrong(ints(1, 128))),
        method,
        weights,
    )


# Rotation -------------------------------------------------------------------------------


@entry("sh_index")
def _sh_index(probe: Probe, data: Any) -> None:
    degree = data.draw(sometimes_wrong(ints(0, 127)))
    order = data.draw(sometimes_wrong(ints(0)))
    value = probe("sh_index", svs.sh_index, degree, order)
    if ok(value) and isinstance(degree, int) and isinstance(order, int):
        if value != degree * degree + degree + order:
            probe.finding("bad result", f"sh_index({degree}, {order})", f"returned {value}")


@entry("real_spherical_harmonics")
def _real_spherical_harmonics(probe: Probe, data: Any) -> None:
    probe(
        "real_spherical_harmonics",
        svs.real_spherical_harmonics,
        data.draw(vectors),
        data.draw(sometimes_wrong(ints(0, 127))),
    )


@entry("sh_coefficients")
def _sh_coefficients(probe: Probe, data: Any) -> None:
    bandwidth = data.draw(sometimes_wrong(ints(1, 128)))
    B = data.draw(st.sampled_from([1, 2, 4, 8, 16]))
    grid = data.draw(
        st.one_of(
            st.just(svs.egi(fixtures().model, B)),
            st.just(np.full((2 * B, 2 * B), 1e300)),
            st.just(np.full((2 * B, 2 * B), math.nan)),
            arrays(),
            wrong,
        )
    )
    probe("sh_coefficients", svs.sh_coefficients, grid, bandwidth)


@entry("sh_synthesis")
def _sh_synthesis(probe: Probe, data: Any) -> None:
    B, _ = data.draw(bandwidth_coefficients())
    bandwidth = data.draw(st.one_of(st.just(B), sometimes_wrong(ints(1, 128))))
    probe("sh_synthesis", svs.sh_synthesis, data.draw(coefficient_arrays(B)), bandwidth)


@entry("smooth_coefficients")
def _smooth_coefficients(probe: Probe, data: Any) -> None:
    B, _ = data.draw(bandwidth_coefficients())
    bandwidth = data.draw(st.one_of(st.just(B), sometimes_wrong(ints(1, 128))))
    probe(
        "smooth_coefficients",
        svs.smooth_coefficients,
        data.draw(coefficient_arrays(B)),
        bandwidth,
        data.draw(sometimes_wrong(reals(0.0))),
    )


@entry("wigner_real")
def _wigner_real(probe: Probe, data: Any) -> None:
    probe(
        "wigner_real",
        svs.wigner_real,
        data.draw(rotation_matrices()),
        data.draw(sometimes_wrong(ints(0, 127))),
    )


@entry("wigner_generators")
def _wigner_generators(probe: Probe, data: Any) -> None:
    probe("wigner_generators", svs.wigner_generators, data.draw(sometimes_wrong(ints(0, 127))))


def coefficient_pairs(data: Any) -> tuple[int, Any, Any]:
    B, _ = data.draw(bandwidth_coefficients())
    return B, data.draw(coefficient_arrays(B)), data.draw(coefficient_arrays(B))


@entry("So3Correlation")
def _so3_correlation_class(probe: Probe, data: Any) -> None:
    _, target, model = coefficient_pairs(data)
    normalised = data.draw(st.one_of(st.booleans(), wrong))
    correlation = probe("So3Correlation", svs.So3Correlation, target, model, normalised)
    if not ok(correlation):
        return
    probe("So3Correlation.bandwidth", lambda: correlation.bandwidth)
    for _ in range(data.draw(st.integers(1, 3))):
        hessian = data.draw(st.one_of(st.booleans(), wrong))
        probe(
            "So3Correlation.evaluate", correlation.evaluate, data.draw(rotation_matrices()), hessian
        )


@entry("so3_correlation")
def _so3_correlation(probe: Probe, data: Any) -> None:
    _, target, model = coefficient_pairs(data)
    probe(
        "so3_correlation",
        svs.so3_correlation,
        target,
        model,
        data.draw(rotation_matrices()),
        data.draw(st.one_of(st.booleans(), wrong)),
        data.draw(st.one_of(st.booleans(), wrong)),
    )


@entry("rotation_cost")
def _rotation_cost(probe: Probe, data: Any) -> None:
    _, target, model = coefficient_pairs(data)
    probe(
        "rotation_cost",
        svs.rotation_cost,
        target,
        model,
        data.draw(rotation_matrices()),
        data.draw(st.one_of(st.booleans(), wrong)),
    )


@entry("so3_search", share=0.5)
def _so3_search(probe: Probe, data: Any) -> None:
    B, target, model = coefficient_pairs(data)
    bandwidth = data.draw(st.one_of(st.just(B), sometimes_wrong(ints(1, 128))))
    kwargs: dict[str, Any] = {}
    if data.draw(st.booleans()):
        kwargs["k"] = data.draw(sometimes_wrong(ints(1)))
    if data.draw(st.booleans()):
        kwargs["threads"] = data.draw(sometimes_wrong(ints(1, 256)))
    if data.draw(st.booleans()):
        kwargs["normalised"] = data.draw(st.one_of(st.booleans(), wrong))
    probe("so3_search", svs.so3_search, target, model, bandwidth, **kwargs)


@entry("refine_rotation")
def _refine_rotation(probe: Probe, data: Any) -> None:
    _, target, model = coefficient_pairs(data)
    kwargs: dict[str, Any] = {}
    for name, strategy in [
        ("gain", reals(0.0)),
        ("max_iterations", ints(0)),
        ("gradient_tolerance", reals(0.0)),
        ("newton", st.booleans()),
        ("max_step", reals(0.0)),
        ("normalised", st.booleans()),
    ]:
        if data.draw(st.booleans()):
            kwargs[name] = data.draw(sometimes_wrong(strategy))
    probe(
        "refine_rotation",
        svs.refine_rotation,
        target,
        model,
        data.draw(rotation_matrices()),
        **kwargs,
    )


@entry("so3_exp")
def _so3_exp(probe: Probe, data: Any) -> None:
    probe(
        "so3_exp", svs.so3_exp, data.draw(vectors), _check=lambda R: check_value(R, "so3_exp", "R")
    )


@entry("so3_log")
def _so3_log(probe: Probe, data: Any) -> None:
    probe("so3_log", svs.so3_log, data.draw(rotation_matrices()))


@entry("rotation_angle")
def _rotation_angle(probe: Probe, data: Any) -> None:
    angle = probe("rotation_angle", svs.rotation_angle, data.draw(rotation_matrices()))
    if ok(angle) and not 0.0 <= angle <= math.pi:
        probe.finding("bad result", "rotation_angle", f"returned {angle}, outside [0, pi]")


@entry("rotation_step_about")
def _rotation_step_about(probe: Probe, data: Any) -> None:
    F = fixtures()
    correlation = data.draw(
        st.one_of(
            st.just(svs.So3Correlation(F.scene_coefficients(8), F.coefficients(8))),
            st.just(svs.So3Correlation(F.coefficients(2), F.coefficients(2))),
            wrong,
        )
    )
    params = data.draw(
        st.one_of(
            overrides(
                {"rotation_step": "newton", "rotation_gain": 1.0, "max_rotation_step": 0.1}
            ).map(lambda kw: ("AlignParams", kw)),
            wrong,
        )
    )
    if isinstance(params, tuple) and params[:1] == ("AlignParams",):
        params = probe("AlignParams", svs.AlignParams, _check=no_check, **params[1])
        if not ok(params):
            return
    probe(
        "rotation_step_about",
        svs.rotation_step_about,
        correlation,
        data.draw(rotation_matrices()),
        data.draw(vectors),
        params,
    )


# Depth images ---------------------------------------------------------------------------


@entry("check_depth_scale")
def _check_depth_scale(probe: Probe, data: Any) -> None:
    kwargs = {}
    if data.draw(st.booleans()):
        kwargs["depth_scale"] = data.draw(st.one_of(st.none(), sometimes_wrong(reals(0.0))))
    probe("check_depth_scale", svs.check_depth_scale, data.draw(depth_images()), **kwargs)


@entry("cloud_from_depth")
def _cloud_from_depth(probe: Probe, data: Any) -> None:
    depth = data.draw(depth_images())
    shape = np.shape(depth)
    K = data.draw(camera_matrices(*(shape if len(shape) == 2 else (40, 48))))
    fields = {
        "depth_scale": 1.0,
        "min_depth": 0.0,
        "max_depth": math.inf,
        "stride": 1,
        "organized": False,
        "normals": True,
        "normal_step": 2,
        "window": 5,
        "max_depth_jump": 0.05,
    }
    kwargs = data.draw(overrides(fields, at_most=3))
    value = probe("cloud_from_depth", svs.cloud_from_depth, depth, K, **kwargs)
    if ok(value) and isinstance(value, svs.OrganizedCloud):
        probe("OrganizedCloud.valid_cloud", value.valid_cloud)


# Alignment ------------------------------------------------------------------------------


@entry("alignment_voxel_size")
def _alignment_voxel_size(probe: Probe, data: Any) -> None:
    value = probe(
        "alignment_voxel_size",
        svs.alignment_voxel_size,
        data.draw(cloud_likes()),
        data.draw(cloud_likes()),
    )
    if ok(value) and not value > 0:
        probe.finding("bad result", "alignment_voxel_size", f"returned {value}, not > 0")


@entry("view_scale")
def _view_scale(probe: Probe, data: Any) -> None:
    args = [data.draw(cloud_likes()), data.draw(cloud_likes())]
    if data.draw(st.booleans()):
        args.append(data.draw(sometimes_wrong(reals(4.0))))
    probe("view_scale", svs.view_scale, *args)


@entry("detect_single_view")
def _detect_single_view(probe: Probe, data: Any) -> None:
    probe(
        "detect_single_view",
        svs.detect_single_view,
        data.draw(cloud_likes()),
        data.draw(vectors),
        data.draw(sometimes_wrong(reals(0.0, 0.01))),
    )


@entry("covariance_inflation")
def _covariance_inflation(probe: Probe, data: Any) -> None:
    kind = data.draw(st.one_of(st.sampled_from(["align", "views", "Align", "", "x" * 1000]), wrong))
    probe("covariance_inflation", svs.covariance_inflation, kind)


@entry("calibrated_confidence")
def _calibrated_confidence(probe: Probe, data: Any) -> None:
    kind = data.draw(
        st.one_of(
            st.sampled_from(["align", "views", "servo", "servo_carried", "", "x" * 1000]), wrong
        )
    )
    score = data.draw(st.one_of(st.floats(allow_nan=True, allow_infinity=True), wrong))
    probe("calibrated_confidence", svs.calibrated_confidence, score, kind)


@entry("step_score")
def _step_score(probe: Probe, data: Any) -> None:
    F = fixtures()
    points = st.one_of(
        st.just(np.asarray(F.model.points)), st.just(np.asarray(F.scene.points)), arrays(), wrong
    )
    probe(
        "step_score",
        svs.step_score,
        data.draw(st.one_of(st.floats(allow_nan=True, allow_infinity=True), wrong)),
        data.draw(st.one_of(st.booleans(), wrong)),
        data.draw(points),
        data.draw(st.one_of(st.just(F.T), transforms())),
        data.draw(points),
        data.draw(sometimes_wrong(reals(0.8, 0.0, 1.0))),
        min_field_share=data.draw(sometimes_wrong(reals(0.3, 0.0, 1.0))),
        max_depth=data.draw(sometimes_wrong(reals(3.0, 0.0, float("inf")))),
    )


@entry("pose_covariance")
def _pose_covariance(probe: Probe, data: Any) -> None:
    F = fixtures()
    probe(
        "pose_covariance",
        svs.pose_covariance,
        data.draw(cloud_likes()),
        data.draw(cloud_likes()),
        data.draw(st.one_of(st.just(F.T), transforms())),
        data.draw(sometimes_wrong(reals(0.0, 0.01))),
    )


ALIGN_FIELDS: dict[str, Any] = {}


def align_fields() -> dict[str, Any]:
    if not ALIGN_FIELDS:
        ALIGN_FIELDS.update(settings_fields(svs.AlignParams))
    return ALIGN_FIELDS


def align_overrides() -> st.SearchStrategy[dict[str, Any]]:
    return overrides(align_fields())


@entry("align", share=0.1)
def _align(probe: Probe, data: Any) -> None:
    F = fixtures()
    model = data.draw(st.one_of(st.just(F.model), st.just(F.points), cloud_likes()))
    scene = data.draw(st.one_of(st.just(F.scene), st.just(F.stray), cloud_likes()))
    kwargs = data.draw(align_overrides())
    if data.draw(st.integers(0, 4)) == 0:  # fine voxels: grids near the default max_voxels
        kwargs["voxel_size"] = data.draw(st.sampled_from([0.0053, 0.003]))
        kwargs["global_search"] = data.draw(st.booleans())
    if data.draw(st.booleans()):
        kwargs["downsample"] = data.draw(st.one_of(st.booleans(), wrong))
    params = data.draw(st.one_of(st.none(), st.just(svs.AlignParams(hypotheses=8)), wrong))
    if data.draw(st.integers(0, 9)) == 0:
        kwargs[data.draw(st.sampled_from(["viewpoint", "scene_viewpoint", "nope"]))] = data.draw(
            vectors
        )
    probe("align", svs.align, model, scene, params, _max_voxels=kwargs.get("max_voxels"), **kwargs)


def align_with(probe: Probe, params: Any) -> None:
    """``params`` used: align of the fixtures' model onto their scene."""
    F = fixtures()
    budget = params.max_voxels if isinstance(params, svs.AlignParams) else None
    probe("align", svs.align, F.model, F.scene, params, _max_voxels=budget)


@entry("AlignParams", share=0.1)
def _align_params(probe: Probe, data: Any) -> None:
    kwargs = data.draw(align_overrides())
    params = probe("AlignParams", svs.AlignParams, _check=no_check, **kwargs)
    if ok(params):
        probe("repr(AlignParams)", repr, params)
        probe("copy(AlignParams)", params.__copy__)
        align_with(probe, params)
    # The same values through the setters of a default instance.
    target = svs.AlignParams()
    for name, value in kwargs.items():
        if not ok(probe(f"AlignParams.{name} =", setattr, target, name, value)):
            return
    align_with(probe, target)


def group_entry(name: str, kind: type, group: str) -> None:
    @entry(name, share=0.1)
    def _group(probe: Probe, data: Any) -> None:
        kwargs = data.draw(overrides(settings_fields(kind)))
        value = probe(name, kind, _check=no_check, **kwargs)
        if not ok(value):
            return
        params = svs.AlignParams()
        if ok(probe(f"AlignParams.{group} =", setattr, params, group, value)):
            align_with(probe, params)
        params = probe("AlignParams", svs.AlignParams, _check=no_check, **{group: value})
        if ok(params):
            probe("repr", repr, params)


group_entry("SceneParams", svs.SceneParams, "scene")
group_entry("LocalParams", svs.LocalParams, "local")
group_entry("GlobalSearchParams", svs.GlobalSearchParams, "search")
group_entry("RefinementParams", svs.RefinementParams, "refinement")
group_entry("VerificationParams", svs.VerificationParams, "verification")


@entry("verify_pose", share=0.3)
def _verify_pose(probe: Probe, data: Any) -> None:
    F = fixtures()
    kwargs: dict[str, Any] = {}
    if data.draw(st.booleans()):
        kwargs["sensor_origin"] = data.draw(vectors)
    if data.draw(st.booleans()):
        kwargs["scene_view"] = data.draw(
            st.one_of(st.sampled_from(["auto", "single_view", "all_sides", "none"]), wrong)
        )
    if data.draw(st.booleans()):
        kwargs["downsample"] = data.draw(st.one_of(st.booleans(), wrong))
    probe(
        "verify_pose",
        svs.verify_pose,
        data.draw(st.one_of(st.just(F.model), cloud_likes())),
        data.draw(st.one_of(st.just(F.scene), cloud_likes())),
        data.draw(st.one_of(st.just(F.T), transforms())),
        data.draw(sometimes_wrong(reals(0.0, 0.01))),
        **kwargs,
    )


VIEW_FIELDS: dict[str, Any] = {}


def view_overrides() -> st.SearchStrategy[dict[str, Any]]:
    if not VIEW_FIELDS:
        VIEW_FIELDS.update(settings_fields(svs.ViewAlignParams))
    return overrides(VIEW_FIELDS)


def view_pair(data: Any) -> tuple[Any, Any]:
    F = fixtures()
    reference = data.draw(st.one_of(st.just(F.reference), st.just(F.model), cloud_likes()))
    current = data.draw(st.one_of(st.just(F.current), st.just(F.scene), cloud_likes()))
    return reference, current


@entry("align_views", share=0.1)
def _align_views(probe: Probe, data: Any) -> None:
    reference, current = view_pair(data)
    kwargs = data.draw(view_overrides())
    if data.draw(st.booleans()):
        kwargs["reference_sensor_origin"] = data.draw(vectors)
    if data.draw(st.booleans()):
        kwargs["prior"] = data.draw(st.one_of(st.none(), transforms()))
    params = data.draw(st.one_of(st.none(), st.just(svs.ViewAlignParams(hypotheses=4)), wrong))
    result = probe(
        "align_views",
        svs.align_views,
        reference,
        current,
        params,
        _max_voxels=kwargs.get("max_voxels"),
        **kwargs,
    )
    if ok(result):
        probe("ViewAlignResult.hypotheses", lambda: result.hypotheses)


@entry("ViewAlignParams", share=0.1)
def _view_align_params(probe: Probe, data: Any) -> None:
    F = fixtures()
    kwargs = data.draw(view_overrides())
    params = probe("ViewAlignParams", svs.ViewAlignParams, _check=no_check, **kwargs)
    if not ok(params):
        return
    probe("repr(ViewAlignParams)", repr, params)
    probe("align_views", svs.align_views, F.reference, F.current, params)
    probe("view_support", svs.view_support, F.reference, F.current, np.eye(4), params)


@entry("view_support", share=0.5)
def _view_support(probe: Probe, data: Any) -> None:
    reference, current = view_pair(data)
    args = [reference, current, data.draw(st.one_of(st.just(np.eye(4)), transforms()))]
    if data.draw(st.booleans()):
        kwargs = data.draw(view_overrides())
        params = probe("ViewAlignParams", svs.ViewAlignParams, _check=no_check, **kwargs)
        if not ok(params):
            return
        args.append(params)
    probe("view_support", svs.view_support, *args)


@entry("pose_error")
def _pose_error(probe: Probe, data: Any) -> None:
    args = [data.draw(transforms())]
    if data.draw(st.booleans()):
        args.append(data.draw(st.one_of(st.none(), transforms())))
    kwargs = (
        {"center": data.draw(st.one_of(st.none(), vectors))} if data.draw(st.booleans()) else {}
    )
    error = probe("pose_error", svs.pose_error, *args, **kwargs)
    if ok(error):
        probe("PoseError.translation_mm", lambda: error.translation_mm)
        if not 0.0 <= error.rotation_rad <= math.pi:
            probe.finding(
                "bad result", "pose_error", f"rotation {error.rotation_rad} not in [0, pi]"
            )


@entry("PoseError")
def _pose_error_type(probe: Probe, data: Any) -> None:
    t = data.draw(st.one_of(reals(), wrong))
    r = data.draw(st.one_of(reals(), wrong))
    value = probe("PoseError", svs.PoseError, t, r, _check=no_check)
    if ok(value):
        probe("PoseError.rotation_deg", lambda: value.rotation_deg, _check=no_check)
        probe("PoseError unpacking", tuple, value, _check=no_check)


# Interop --------------------------------------------------------------------------------


def open3d_clouds(data: Any) -> Any:
    try:
        import open3d
    except ImportError:
        return data.draw(wrong)
    points = data.draw(st.one_of(arrays(), st.just(np.asarray(fixtures().model.points))))
    cloud = open3d.geometry.PointCloud()
    try:
        cloud.points = open3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64))
        if data.draw(st.booleans()):
            normals = np.asarray(data.draw(arrays()), dtype=np.float64)
            cloud.normals = open3d.utility.Vector3dVector(normals)
    except (TypeError, ValueError, RuntimeError):
        pass  # Open3D refused the array: the cloud keeps what it took
    return cloud


@entry("from_open3d")
def _from_open3d(probe: Probe, data: Any) -> None:
    cloud = data.draw(wrong) if data.draw(st.integers(0, 3)) == 0 else open3d_clouds(data)
    kwargs = {}
    if data.draw(st.booleans()):
        kwargs["drop_non_finite"] = data.draw(st.one_of(st.booleans(), wrong))
    probe("from_open3d", svs.from_open3d, cloud, **kwargs)


@entry("to_open3d", raises=(*DOCUMENTED, ImportError))
def _to_open3d(probe: Probe, data: Any) -> None:
    cloud = data.draw(cloud_likes())
    colors = data.draw(
        st.one_of(
            st.none(), arrays(), st.just(np.full((400, 3), 0.5)), st.just(np.ones((400, 3)) * 2)
        )
    )
    probe(
        "to_open3d",
        svs.to_open3d,
        cloud,
        colors,
        _check=lambda value: check_value(np.asarray(value.points), "to_open3d", "points"),
    )


@entry("InputWarning")
def _input_warning(probe: Probe, data: Any) -> None:
    args = data.draw(st.lists(st.one_of(wrong, st.text(max_size=5)), max_size=2))
    warning = probe("InputWarning", svs.InputWarning, *args, _check=no_check)
    if ok(warning):
        probe("str(InputWarning)", str, warning, _check=no_check)
        if not isinstance(warning, UserWarning):
            probe.finding("bad result", "InputWarning", "is not a UserWarning")


# Kinematics -----------------------------------------------------------------------------


@st.composite
def urdf_texts(draw: st.DrawFn) -> Any:
    """The test arm's URDF, cut, with a number replaced by NaN, inf, 1e308 or garbage,
    nested deeply, or not text at all."""
    text = fixtures().urdf
    kind = draw(st.integers(0, 6))
    if kind <= 1:
        return text
    if kind == 2:
        return text[: draw(st.integers(0, len(text)))]
    if kind == 3:
        numbers = list(re.finditer(r"-?\d+(\.\d+)?", text))
        match = numbers[draw(st.integers(0, len(numbers) - 1))]
        value = draw(st.sampled_from(["nan", "inf", "-inf", "1e308", "1e-320", "x", "", "0"]))
        return text[: match.start()] + value + text[match.end() :]
    if kind == 4:
        depth = draw(st.sampled_from([10, 300, 5000]))
        return "<robot>" + "<a>" * depth + "</a>" * depth + "</robot>"
    if kind == 5:
        return draw(st.sampled_from(["", "<robot/>", "<robot name='x'>", "\x00" * 10]))
    return draw(wrong)


joint_vectors = st.one_of(
    st.tuples(*[st.floats(-3.0, 3.0)] * 6).map(np.array),
    st.sampled_from(
        [
            np.zeros(6),
            np.full(6, 1e300),
            np.full(6, math.nan),
            np.full(6, math.inf),
            np.zeros(5),
            np.zeros(7),
            np.zeros((6, 1)),
        ]
    ),
    st.tuples(*[reals()] * 6).map(np.array),
    arrays(),
    wrong,
)
twists = st.one_of(
    st.tuples(*[st.floats(-1.0, 1.0)] * 6).map(np.array),
    st.tuples(*[reals()] * 6).map(np.array),
    st.sampled_from([np.zeros(6), np.full(6, 1e300), np.zeros(3)]),
    wrong,
)


@entry("Kinematics", raises=FILE_ERRORS)
def _kinematics(probe: Probe, data: Any) -> None:
    F = fixtures()
    links = st.one_of(st.sampled_from(F.links), st.sampled_from(["", "nope", "tool\x00"]), wrong)
    T = data.draw(st.one_of(st.none(), transforms()))
    if data.draw(st.booleans()):
        path = data.draw(st.one_of(st.just(F.urdf_path), st.just(str(F.urdf_path)), paths()))
        kinematics = probe(
            "Kinematics", svs.Kinematics, path, data.draw(links), data.draw(links), T
        )
    else:
        kinematics = probe(
            "Kinematics.from_urdf_string",
            svs.Kinematics.from_urdf_string,
            data.draw(urdf_texts()),
            data.draw(links),
            data.draw(links),
            T,
        )
    if not ok(kinematics):
        kinematics = F.kinematics
    q = data.draw(joint_vectors)
    probe("Kinematics.tip_pose", kinematics.tip_pose, q)
    probe("Kinematics.forward", kinematics.forward, q)
    probe("Kinematics.jacobian", kinematics.jacobian, q)
    args = [q, data.draw(twists)]
    if data.draw(st.booleans()):
        args.append(data.draw(st.one_of(st.just(svs.VelocityCommandParams()), wrong)))
    probe("Kinematics.joint_velocities", kinematics.joint_velocities, *args)


@entry("damped_least_squares")
def _damped_least_squares(probe: Probe, data: Any) -> None:
    jacobian = fixtures().kinematics.jacobian(np.zeros(6))
    J = data.draw(
        st.one_of(
            st.sampled_from([jacobian, np.zeros((6, 6)), jacobian * 1e300, jacobian[:, :1]]),
            arrays(),
            wrong,
        )
    )
    b = data.draw(st.one_of(st.just(np.ones(6)), twists, arrays()))
    args = [J, b]
    if data.draw(st.booleans()):
        kwargs = data.draw(overrides(settings_fields(svs.DampingParams)))
        params = probe("DampingParams", svs.DampingParams, _check=no_check, **kwargs)
        if not ok(params):
            return
        args.append(params)
    probe("damped_least_squares", svs.damped_least_squares, *args)


@entry("DampingParams")
def _damping_params(probe: Probe, data: Any) -> None:
    kwargs = data.draw(overrides(settings_fields(svs.DampingParams)))
    params = probe("DampingParams", svs.DampingParams, _check=no_check, **kwargs)
    if ok(params):
        probe("repr(DampingParams)", repr, params)
        J = fixtures().kinematics.jacobian(np.zeros(6))
        probe("damped_least_squares", svs.damped_least_squares, J, np.ones(6), params)


@entry("VelocityCommandParams")
def _velocity_command_params(probe: Probe, data: Any) -> None:
    fields = settings_fields(svs.VelocityCommandParams)
    fields.pop("damping")
    kwargs = data.draw(overrides(fields))
    if data.draw(st.integers(0, 3)) == 0:
        kwargs["damping"] = data.draw(
            st.one_of(st.just(svs.DampingParams(max_damping=-1.0)), wrong)
        )
    params = probe("VelocityCommandParams", svs.VelocityCommandParams, _check=no_check, **kwargs)
    if ok(params):
        kinematics = fixtures().kinematics
        q = data.draw(st.one_of(st.just(np.zeros(6)), joint_vectors))
        probe("Kinematics.joint_velocities", kinematics.joint_velocities, q, np.ones(6), params)


# The servo ------------------------------------------------------------------------------

SERVO_FIELDS: dict[str, Any] = {}


def servo_overrides(at_most: int = 2) -> st.SearchStrategy[dict[str, Any]]:
    if not SERVO_FIELDS:
        SERVO_FIELDS.update(servo_fields())
    return overrides(SERVO_FIELDS, at_most)


@entry("ServoParams", share=0.2)
def _servo_params(probe: Probe, data: Any) -> None:
    F = fixtures()
    kwargs = data.draw(servo_overrides())
    params = probe("ServoParams", svs.ServoParams, _check=no_check, **kwargs)
    if not ok(params):
        return
    probe("ServoParams.uses_tracking", params.uses_tracking, _check=no_check)
    resolved = probe(
        "ServoParams.resolved", params.resolved, data.draw(cloud_likes()), _check=no_check
    )
    if ok(resolved):
        probe("ServoParams.align_params", resolved.align_params, _check=no_check)
    servo = probe("SpectralServo", svs.SpectralServo, F.reference, params, _check=no_check)
    if ok(servo):
        probe("SpectralServo.step", servo.step, F.current)


@entry("ServoStatus")
def _servo_status(probe: Probe, data: Any) -> None:
    args = data.draw(
        st.lists(st.one_of(st.sampled_from(["running", "stopped", ""]), wrong), max_size=3)
    )
    probe("ServoStatus", svs.ServoStatus, *args, _check=no_check)


@entry("ServoRecord")
def _servo_record(probe: Probe, data: Any) -> None:
    record = servo_records._empty_record(0, 0)
    fields = {item.name: getattr(record, item.name) for item in dataclasses.fields(record)}
    for name in data.draw(st.lists(st.sampled_from(sorted(fields)), max_size=3, unique=True)):
        fields[name] = data.draw(st.one_of(reals(), ints(), wrong))
    if data.draw(st.booleans()):
        fields.pop(data.draw(st.sampled_from(sorted(fields))))  # a field missing: TypeError
    probe("ServoRecord", svs.ServoRecord, _check=no_check, **fields)


@entry("ServoLog")
def _servo_log(probe: Probe, data: Any) -> None:
    """A record type: it holds what it is given (wrong types too, unchecked); its methods
    are called on well-typed logs."""
    probe("ServoLog", svs.ServoLog, *data.draw(st.lists(wrong, max_size=3)), _check=no_check)
    records = [servo_records._empty_record(i, 10) for i in range(data.draw(st.integers(0, 3)))]
    state = data.draw(st.sampled_from(["running", "converged", "stopped", "", "x"]))
    status = svs.ServoStatus(state, data.draw(st.sampled_from(["", "jump", "x" * 100])))
    log = probe("ServoLog", svs.ServoLog, records, status, data.draw(reals()), _check=no_check)
    if not ok(log):
        return
    probe("ServoLog.reason", lambda: log.reason, _check=no_check)
    probe("ServoLog.converged", lambda: log.converged, _check=no_check)
    name = data.draw(
        st.one_of(
            st.sampled_from(["twist", "fitness", "step", "nope", "", "_x", "__class__"]), wrong
        )
    )
    probe("ServoLog.array", log.array, name, _check=no_check)


def current_clouds(data: Any) -> Any:
    F = fixtures()
    return data.draw(st.one_of(st.just(F.current), st.just(F.reference), cloud_likes()))


@entry("SpectralServo", share=0.1)
def _spectral_servo(probe: Probe, data: Any) -> None:
    F = fixtures()
    reference = data.draw(st.one_of(st.just(F.reference), cloud_likes()))
    args: list[Any] = [reference]
    if data.draw(st.booleans()):
        kwargs = data.draw(servo_overrides(1))
        params = probe("ServoParams", svs.ServoParams, _check=no_check, **kwargs)
        if not ok(params):
            return
        args.append(params)
    servo = probe("SpectralServo", svs.SpectralServo, *args, _check=no_check)
    if not ok(servo):
        return
    for step in range(data.draw(st.integers(1, 3))):
        kwargs = {}
        if data.draw(st.booleans()):  # the robot clock, or any value
            kwargs["now"] = data.draw(st.one_of(st.just(0.1 * step), reals(), wrong))
        if data.draw(st.booleans()):
            kwargs["stamp"] = data.draw(st.one_of(reals(), wrong))
        motion = data.draw(st.one_of(st.none(), st.just(np.eye(4)), transforms()))
        probe("SpectralServo.step", servo.step, current_clouds(data), motion, **kwargs)
    guess = data.draw(st.one_of(st.none(), transforms()))
    probe("SpectralServo.estimate", servo.estimate, current_clouds(data), guess)
    probe("SpectralServo.twist", servo.twist, data.draw(transforms()))
    probe("SpectralServo.previous_estimate", lambda: servo.previous_estimate)
    probe("SpectralServo.reset", servo.reset)


@entry("run_servo", share=0.1)
def _run_servo(probe: Probe, data: Any) -> None:
    """A free-flying fake camera (tests/python/test_servo.py) over the table top, its
    kinematics fake or the test arm's (joint counts then agree: 6)."""
    F = fixtures()
    start = camera_pose(
        data.draw(st.sampled_from([(0.0, 0.0, 0.0), (0.02, 0.01, -0.01), (0.3, 0.0, 0.0)])),
        data.draw(st.sampled_from([(0.0, 0.0, 0.0), (-2.0, 3.0, -4.0)])),
    )
    robot = FreeCamera(F.table, start, empty_at=data.draw(st.sampled_from([None, None, 0, 2])))
    kinematics = data.draw(st.sampled_from([FreeCameraKinematics(), F.kinematics]))
    servo = probe("SpectralServo", svs.SpectralServo, F.reference, _check=no_check)
    if not ok(servo):
        return
    kwargs: dict[str, Any] = {}
    for name, strategy in [
        ("dt", reals(0.0, 0.1)),
        ("max_steps", st.one_of(ints(1), st.integers(1, 30))),
        ("max_time", reals(0.0, 2.0)),
        ("velocity_params", st.just(svs.VelocityCommandParams(max_joint_speed=0.5))),
        ("stop_at_joint_limit", st.booleans()),
        ("callback", st.just(lambda record: None)),
    ]:
        if data.draw(st.booleans()):
            kwargs[name] = data.draw(sometimes_wrong(strategy))
    kwargs.setdefault("max_steps", 30)
    log = probe("run_servo", svs.run_servo, robot, kinematics, servo, **kwargs)
    if ok(log) and robot.stops != 1:
        probe.finding("bad result", "run_servo", f"the robot was stopped {robot.stops} times")


@entry("RobotInterface")
def _robot_interface(probe: Probe, data: Any) -> None:
    probe("RobotInterface", svs.RobotInterface, *data.draw(st.lists(wrong, max_size=2)))
    robot = FreeCamera(fixtures().table, camera_pose())
    value = probe("isinstance(RobotInterface)", isinstance, robot, svs.RobotInterface)
    if value is not True:
        probe.finding("bad result", "isinstance(FreeCamera, RobotInterface)", f"{value}")
    probe("isinstance(RobotInterface)", isinstance, data.draw(wrong), svs.RobotInterface)


# Result types: no constructor; their properties read on a result ------------------------


#: The instance of each result type whose properties were read (one per worker).
PRODUCED: dict[str, Any] = {}


def result_type(name: str, produce: Callable[[], Any]) -> None:
    """A result type: calling it must raise TypeError (no constructor); every property of
    an instance (produced once by ``produce``) must read finite."""

    @entry(name, share=0.1)
    def _result(probe: Probe, data: Any) -> None:
        kind = getattr(svs, name)
        args = data.draw(st.lists(wrong, max_size=2))
        value = probe(name, kind, *args)
        if ok(value):
            probe.finding("bad result", f"{name}(...)", "a result type was constructed")
        if name not in PRODUCED:
            PRODUCED[name] = instance = probe(f"a {name}", produce)
            if ok(instance) and not isinstance(instance, kind):
                probe.finding("bad result", f"a {name}", f"produced a {type(instance).__name__}")


def _first(items: list[Any], what: str) -> Any:
    if not items:
        raise ValueError(f"no {what} to read")  # a documented refusal: nothing to check
    return items[0]


def _produce_organized() -> Any:
    depth = np.full((12, 16), 1.0)
    K = np.array([[20.0, 0.0, 8.0], [0.0, 20.0, 6.0], [0.0, 0.0, 1.0]])
    organized = svs.cloud_from_depth(depth, K, organized=True)
    organized.valid_cloud()
    return organized


def _produce_translation() -> Any:
    F = fixtures()
    return svs.phase_correlation(F.grid_a, F.grid_b)


def _register_result_types() -> None:
    F = fixtures
    result_type("AlignResult", lambda: svs.align(F().model, F().scene, hypotheses=8))
    result_type("AlignIteration", lambda: _first(svs.align(F().model, F().scene).history, "step"))
    result_type("AlignTimings", lambda: svs.align(F().model, F().scene).timings)
    result_type("ViewAlignTimings", lambda: svs.align_views(F().reference, F().current).timings)
    result_type(
        "AlignAlternative",
        lambda: _first(svs.align(F().reference, F().current).alternatives, "alternative"),
    )
    result_type(
        "AxisRotationStep",
        lambda: svs.rotation_step_about(
            svs.So3Correlation(F().coefficients(8), F().coefficients(8)),
            np.eye(3),
            [0.0, 0.0, 1.0],
            svs.AlignParams(),
        ),
    )
    result_type("CloudFileInfo", lambda: svs.load_cloud_with_info(F().folder / "model.pcd")[1])
    result_type(
        "DampedSolution",
        lambda: svs.damped_least_squares(F().kinematics.jacobian(np.zeros(6)), np.ones(6)),
    )
    result_type("DepthScaleCheck", lambda: svs.check_depth_scale(np.full((4, 4), 1.0)))
    result_type("DominantPlane", lambda: svs.dominant_plane(F().clouds[9]))
    result_type("OrganizedCloud", _produce_organized)
    result_type("PoseVerification", lambda: svs.verify_pose(F().model, F().scene, F().T))
    result_type(
        "RotationRefineResult",
        lambda: svs.refine_rotation(F().scene_coefficients(8), F().coefficients(8), np.eye(3)),
    )
    result_type(
        "SingleViewEvidence", lambda: svs.detect_single_view(F().current, np.zeros(3), 0.01)
    )
    result_type("TranslationEstimate", _produce_translation)
    result_type("VelocityCommand", lambda: F().kinematics.joint_velocities(np.zeros(6), np.ones(6)))
    result_type("ViewAlignResult", lambda: svs.align_views(F().reference, F().current))
    result_type(
        "ViewAlternative",
        lambda: _first(svs.align_views(F().reference, F().current).alternatives, "alternative"),
    )
    result_type("ViewScale", lambda: svs.view_scale(F().reference, F().current))
    result_type("ViewSupport", lambda: svs.view_support(F().reference, F().current, np.eye(4)))
    result_type("VoxelGrid", lambda: svs.voxelize(F().model, F().spec))


_register_result_types()


def table() -> dict[str, Entry]:
    return TABLE


# --- Coverage ----------------------------------------------------------------------------


def public_callables() -> list[str]:
    return sorted(name for name in svs.__all__ if callable(getattr(svs, name)))


def check_coverage() -> None:
    """Every public callable has an entry or an exclusion with a reason, and nothing else."""
    public = set(public_callables())
    missing = sorted(public - set(TABLE) - set(EXCLUDED))
    stale = sorted((set(TABLE) | set(EXCLUDED)) - public)
    unexplained = sorted(name for name, reason in EXCLUDED.items() if not reason.strip())
    problems = []
    if missing:
        problems.append(f"public callables without an entry or exclusion: {missing}")
    if stale:
        problems.append(f"entries or exclusions of names not in spectral_vs.__all__: {stale}")
    if unexplained:
        problems.append(f"exclusions without a reason: {unexplained}")
    for name in ("CONFIDENCE_THRESHOLD", "RELIABLE_CONFIDENCE", "SINGLE_VIEW_THRESHOLD"):
        value = getattr(svs, name)
        if not (isinstance(value, float) and 0.0 <= value <= 1.0):
            problems.append(f"{name} = {value!r} is not a share in [0, 1]")
    if problems:
        raise SystemExit("api_harness: " + "; ".join(problems))


# --- The worker --------------------------------------------------------------------------


def examples_of(entry_: Entry, examples: int) -> int:
    return max(2, round(examples * entry_.share))


def run_entry(probe: Probe, entry_: Entry, examples: int) -> None:
    probe.entry, probe.raises = entry_.name, entry_.raises
    stats = probe.stats.setdefault(entry_.name, Stats())

    @settings(
        derandomize=True,
        database=None,
        deadline=None,
        max_examples=examples_of(entry_, examples),
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(data=st.data())
    def run(data: Any) -> None:
        stats.examples += 1
        probe.example = []
        entry_.run(probe, data)

    try:
        run()
    except Exception as error:  # an error of the harness itself (a strategy, a check)
        probe.finding("harness error", entry_.name, f"{type(error).__name__}: {error}"[:400])


def limit_address_space(megabytes: int) -> None:
    if megabytes <= 0:
        return
    wanted = megabytes * 2**20
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        wanted = min(wanted, hard)
    resource.setrlimit(resource.RLIMIT_AS, (wanted, hard))


def selected(only: list[str] | None, start_after: str | None) -> list[Entry]:
    entries = [TABLE[name] for name in sorted(TABLE)]
    if only:
        unknown = sorted(set(only) - set(TABLE))
        if unknown:
            raise SystemExit(f"api_harness: no entry named {unknown}")
        entries = [e for e in entries if e.name in only]
    if start_after:
        names = [e.name for e in entries]
        entries = entries[names.index(start_after) + 1 :] if start_after in names else []
    return entries


def worker(args: argparse.Namespace) -> int:
    check_coverage()
    limit_address_space(args.address_space_mb)
    report, last_call = Path(args.report), Path(args.last_call)
    probe = Probe(last_call, report)
    probe.entry = "(fixtures)"
    probe.announce("building the fixtures")
    F = fixtures()
    try:
        for entry_ in selected(args.only, args.start_after):
            started = time.monotonic()
            run_entry(probe, entry_, args.examples)
            stats = probe.stats[entry_.name]
            with open(report, "a") as out:
                summary = dataclasses.asdict(stats)
                summary.update(entry=entry_.name, seconds=round(time.monotonic() - started, 3))
                out.write(json.dumps({"stats": summary}) + "\n")
            if args.verbose:
                print(
                    f"{entry_.name}: {stats.examples} examples, {stats.calls} calls, "
                    f"{time.monotonic() - started:.1f} s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        F.close()
    probe.announce("(finished)")
    return 1 if probe.seen else 0


# --- The supervisor ----------------------------------------------------------------------


def read_last_call(path: Path) -> dict[str, Any]:
    try:
        return dict(json.loads(path.read_text()))
    except (OSError, ValueError):
        return {"entry": "?", "call": "(no last call recorded)"}


def describe(returncode: int) -> str:
    if returncode < 0:
        with contextlib.suppress(ValueError):
            return f"died by signal {signal.Signals(-returncode).name}"
    return f"exited with status {returncode}"


def supervise(args: argparse.Namespace) -> int:
    """Runs workers until every entry ran: a worker that dies by a signal, or whose call
    does not return within ``--kill-after`` seconds, is a finding naming that call, and the
    next worker starts after its entry."""
    check_coverage()
    report = Path(args.report)
    last_call = Path(args.last_call or report.with_suffix(".last_call.json"))
    report.write_text("")
    start_after: str | None = None
    started = time.monotonic()
    findings = 0
    # The workers' files (a FIFO among them) in one folder, removed even after a kill.
    scratch = tempfile.TemporaryDirectory(prefix="api_harness_")
    environment = dict(os.environ, SPECTRAL_VS_HARNESS_SCRATCH=scratch.name)
    while True:
        command = [sys.executable, str(Path(__file__).resolve()), "--worker"]
        command += ["--examples", str(args.examples), "--report", str(report)]
        command += ["--last-call", str(last_call), "--address-space-mb", str(args.address_space_mb)]
        command += ["--start-after", start_after] if start_after else []
        command += [item for name in args.only or [] for item in ("--only", name)]
        command += ["--verbose"] if args.verbose else []
        last_call.write_text("")
        process = subprocess.Popen(command, env=environment)
        hung = False
        while process.poll() is None:
            time.sleep(0.2)
            with contextlib.suppress(OSError):
                if time.time() - last_call.stat().st_mtime > args.kill_after:
                    hung = True
                    process.kill()
                    process.wait()
        code = process.returncode
        if not hung and code in (0, 1):
            break
        culprit = read_last_call(last_call)
        kind = "hang" if hung else "crash"
        detail = f"no return within {args.kill_after:g} s: killed" if hung else describe(code)
        record = {"finding": kind, "entry": culprit.get("entry", "?"), "call": culprit.get("call")}
        record.update(detail=detail, count=1)
        if culprit.get("after"):
            record["after"] = culprit["after"]
        with open(report, "a") as out:
            out.write(json.dumps(record) + "\n")
        print(f"FINDING [{kind}] {record['call']}: {detail}", file=sys.stderr, flush=True)
        findings += 1
        if code not in (0, 1) and not hung and record["entry"] in ("?", "(fixtures)"):
            break  # the worker itself fails: restarting would fail again
        start_after = str(record["entry"])
    scratch.cleanup()
    lines = [json.loads(line) for line in report.read_text().splitlines() if line.strip()]
    found = [line for line in lines if "finding" in line]
    stats = [line["stats"] for line in lines if "stats" in line]
    print(summary_text(found, stats, time.monotonic() - started))
    return 1 if found else 0


def summary_text(found: list[dict[str, Any]], stats: list[dict[str, Any]], seconds: float) -> str:
    examples = sum(s["examples"] for s in stats)
    calls = sum(s["calls"] for s in stats)
    out = [
        f"api_harness: {len(stats)} entries, {examples} examples, {calls} calls in "
        f"{seconds:.0f} s; {len(found)} findings"
    ]
    slow = sorted(stats, key=lambda s: -s["seconds"])[:5]
    out.append("slowest entries: " + ", ".join(f"{s['entry']} {s['seconds']:.1f} s" for s in slow))
    for item in found:
        times = f" (x{item['count']})" if item.get("count", 1) > 1 else ""
        out.append(f"  [{item['finding']}] {item['call']}: {item['detail']}{times}")
        if item.get("after"):
            out.append(f"      after: {'; '.join(item['after'])}")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=15, help="per callable (scaled by share)")
    parser.add_argument("--report", default="api_harness_report.jsonl")
    parser.add_argument("--last-call", default=None)
    parser.add_argument("--kill-after", type=float, default=KILL_SECONDS)
    parser.add_argument("--address-space-mb", type=int, default=ADDRESS_SPACE_MB)
    parser.add_argument("--only", action="append", help="run only this entry (repeatable)")
    parser.add_argument("--start-after", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--verbose", action="store_true")
    args = parser.parse_args(argv)
    if args.worker:
        if not args.last_call:
            parser.error("--worker needs --last-call")
        return worker(args)
    return supervise(args)


if __name__ == "__main__":
    sys.exit(main())
