"""Adversarial input to every public entry point, as one table (docs/reliability.md).

Each row of ``CASES`` is one call and its documented behaviour: an exception of a given
type whose message matches a fragment (naming the argument or the limit), or a normal
return that a check accepts (finite values, ``converged = False``, an exit code). To add
a case, add a row; ``files`` gives the row a folder of prepared inputs (valid, truncated
and corrupted point clouds, URDFs).

The C++ API has the same table in tests/cpp/adversarial_test.cpp, which also runs under
AddressSanitizer and UndefinedBehaviorSanitizer (``make test-sanitize``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import box_and_sphere
from test_properties import resident_megabytes

import spectral_vs as svs
from spectral_vs.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "tests" / "data" / "test_arm.urdf"
NAN, INF = math.nan, math.inf


# --- Inputs ---------------------------------------------------------------------------


def object_cloud() -> svs.PointCloud:
    """The asymmetric box-and-sphere object, 2000 points with normals."""
    points, normals = box_and_sphere(np.random.default_rng(5), samples=2000)
    return svs.PointCloud(points, normals)


OBJECT = object_cloud()
POINTS = np.asarray(OBJECT.points)
NORMALS = np.asarray(OBJECT.normals)

PCD_HEADER = (
    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
    "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n"
)


class Files:
    """A folder of prepared inputs: ``files.path(name)`` for each name written here."""

    def fifo(self) -> Path:
        """A named pipe (a reader of it would block until a writer comes)."""
        import os

        path = self.folder / "pipe.pcd"
        if not path.exists():
            os.mkfifo(path)
        return path

    def subfolder(self, name: str) -> Path:
        """A folder named like a file."""
        path = self.folder / name
        path.mkdir(exist_ok=True)
        return path

    def loop(self) -> Path:
        """A symbolic link to itself."""
        path = self.folder / "loop.pcd"
        if not path.is_symlink():
            path.symlink_to(path.name)
        return path

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        svs.save_cloud(folder / "model.pcd", OBJECT, "binary")
        svs.save_cloud(folder / "compressed.pcd", OBJECT, "binary_compressed")
        svs.save_cloud(folder / "model.ply", OBJECT)
        T = np.eye(4)
        T[:3, 3] = [0.02, -0.01, 0.03]
        svs.save_cloud(folder / "scene.pcd", OBJECT.transformed(T))
        binary = (folder / "model.pcd").read_bytes()
        compressed = (folder / "compressed.pcd").read_bytes()
        ply = (folder / "model.ply").read_bytes()
        self.write("truncated.pcd", binary[: len(binary) // 2])
        self.write("truncated_compressed.pcd", compressed[: len(compressed) // 2])
        self.write("truncated.ply", ply[: len(ply) // 2])
        inflated = compressed.replace(b"WIDTH 2000", b"WIDTH 2000000")
        self.write("inflated.pcd", inflated.replace(b"POINTS 2000", b"POINTS 2000000"))
        self.write("split_header.pcd", binary.replace(b"VERSION 0.7", b"VERSION 0\n7", 1))
        self.write("garbage_header.pcd", b"VERSION 0.7\n" + bytes(range(256)) * 4)
        self.write("words.pcd", (PCD_HEADER + "a b c\n1 2 3\n").encode())
        self.write("invalid_utf8.pcd", (PCD_HEADER + "1 2 ").encode() + b"\xff\xfe\n1 2 3\n")
        self.write("nan_only.pcd", (PCD_HEADER + "nan nan nan\ninf 0 0\n").encode())
        self.write("one_point.pcd", (PCD_HEADER.replace("2", "1") + "0.1 0.2 0.3\n").encode())
        self.write("not_a_cloud.pcd", b"hello, world\n")
        self.write("not_a_cloud.ply", b"solid cube\nfacet normal 0 0 1\n")
        self.write("empty.pcd", b"")
        self.write("cloud.xyz", b"0 0 0\n")
        urdf = URDF.read_text()
        self.write("missing_link.urdf", urdf.replace('<link name="link3"/>', "").encode())
        self.write(
            "deep.urdf", ("<robot>" + "<a>" * 100_000 + "</a>" * 100_000 + "</robot>").encode()
        )
        self.write("truncated.urdf", urdf[: len(urdf) // 2].encode())
        self.write(
            "zero_axis.urdf", urdf.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1).encode()
        )
        loop = urdf.replace(
            '<parent link="base_link"/>\n    <child link="link1"/>',
            '<parent link="link6"/>\n    <child link="link1"/>',
        )
        self.write("loop.urdf", loop.encode())

    def write(self, name: str, data: bytes) -> None:
        (self.folder / name).write_bytes(data)

    def path(self, name: str) -> str:
        return str(self.folder / name)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Files:
    return Files(tmp_path_factory.mktemp("adversarial"))


# --- Checks of a normal return --------------------------------------------------------


def finite(value: Any) -> None:
    if isinstance(value, svs.AlignResult):
        assert np.all(np.isfinite(np.asarray(value.T_scene_model)))
        assert 0.0 <= value.fitness <= 1.0
        assert math.isfinite(value.correlation)
    elif isinstance(value, svs.PointCloud):
        assert np.all(np.isfinite(value.points))
    else:
        assert np.all(np.isfinite(np.asarray(value, dtype=float)))


def unreliable(result: svs.AlignResult) -> None:
    finite(result)
    assert not result.reliable, result.status


def stopped_for(reason: str) -> Callable[[svs.AlignResult], None]:
    def check(result: svs.AlignResult) -> None:
        finite(result)
        assert not result.converged
        assert result.stop_reason == reason

    return check


def is_true(value: Any) -> None:
    assert value is True or value is np.True_


def has_length(n: int) -> Callable[[Any], None]:
    def check(value: Any) -> None:
        assert len(value) == n

    return check


def exits(code: int, fragment: str = "") -> Callable[[tuple[int, str]], None]:
    """A check of a CLI run: its exit code and a fragment of its standard error."""

    def check(result: tuple[int, str]) -> None:
        assert result[0] == code, result[1]
        assert fragment in result[1], result[1]

    return check


def cli(*argv: str) -> tuple[int, str]:
    """Runs the CLI in-process: (exit code, standard error)."""
    import contextlib
    import io

    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = cli_main(list(argv))
        except SystemExit as stop:  # argparse refused an argument
            code = int(stop.code or 0)
    return code, err.getvalue()


def cloud_with(points: Any, normals: Any = None) -> svs.PointCloud:
    return svs.PointCloud(points, normals)


def line(n: int = 100) -> np.ndarray:
    return np.c_[np.linspace(0, 0.2, n), np.zeros(n), np.zeros(n)]


def plane(n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    points = np.c_[rng.uniform(-0.1, 0.1, (n, 2)), np.zeros(n)]
    return points, np.tile([0.0, 0.0, 1.0], (n, 1))


def fast(**settings: Any) -> dict[str, Any]:
    """Alignment settings for degenerate input: a short search, no downsampling."""
    return {"hypotheses": 4, "refinements": 1, "downsample": False, **settings}


def grid_spec(n: int, resolution: float = 0.01) -> svs.GridSpec:
    return svs.GridSpec([-n * resolution / 2] * 3, resolution, [n, n, n])


def coefficients(bandwidth: int = 4) -> np.ndarray:
    return svs.egi_coefficients(OBJECT, bandwidth)


# --- The table ------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One call with bad input and what it must do."""

    name: str
    call: Callable[[Files], Any]
    raises: type[BaseException] | None = None  # expected exception type, or None
    match: str = ""  # a fragment of its message (regular expression)
    check: Callable[[Any], None] | None = None  # for a normal return: its check


CASES = [
    # PointCloud construction: finite float (N, 3) arrays of any layout, else ValueError.
    Case("cloud/empty", lambda f: cloud_with(np.zeros((0, 3))), check=has_length(0)),
    Case(
        "cloud/int dtype", lambda f: cloud_with(np.zeros((3, 3), int)), ValueError, "floating dtype"
    ),
    Case("cloud/bool dtype", lambda f: cloud_with(np.zeros((3, 3), bool)), ValueError, "floating"),
    Case(
        "cloud/complex dtype", lambda f: cloud_with(np.zeros((3, 3), complex)), ValueError, "float"
    ),
    Case(
        "cloud/object dtype", lambda f: cloud_with(np.zeros((3, 3), object)), ValueError, "floating"
    ),
    Case("cloud/string", lambda f: cloud_with("points"), ValueError, "floating dtype"),
    Case("cloud/None", lambda f: cloud_with(None), ValueError, "floating dtype"),
    Case("cloud/int list", lambda f: cloud_with([[0, 0, 0]]), ValueError, "floating dtype .*int64"),
    Case("cloud/float32", lambda f: cloud_with(POINTS.astype(np.float32)), check=has_length(2000)),
    Case("cloud/float16", lambda f: cloud_with(POINTS.astype(np.float16)), check=has_length(2000)),
    Case(
        "cloud/fortran order",
        lambda f: np.array_equal(cloud_with(np.asfortranarray(POINTS)).points, POINTS),
        check=is_true,
    ),
    Case(
        "cloud/non-contiguous",
        lambda f: np.array_equal(cloud_with(POINTS[::3]).points, POINTS[::3]),
        check=is_true,
    ),
    Case(
        "cloud/transposed",
        lambda f: cloud_with(POINTS.T),
        ValueError,
        r"shape \(N, 3\), got \(3, 2000\)",
    ),
    Case("cloud/1-D", lambda f: cloud_with(np.zeros(3)), ValueError, r"shape \(N, 3\)"),
    Case("cloud/3-D", lambda f: cloud_with(np.zeros((1, 2, 3))), ValueError, r"shape \(N, 3\)"),
    Case(
        "cloud/NaN point",
        lambda f: cloud_with([[0.0, 0, 0], [NAN, 0, 0]]),
        ValueError,
        "row 1 is not finite",
    ),
    Case(
        "cloud/inf point", lambda f: cloud_with([[INF, 0.0, 0]]), ValueError, "row 0 is not finite"
    ),
    Case(
        "cloud/NaN normal",
        lambda f: cloud_with(POINTS[:2], [[0, 0, 1.0], [NAN, 0, 1]]),
        ValueError,
        "normals: row 1 is not finite or has zero length",
    ),
    Case(
        "cloud/zero normal",
        lambda f: cloud_with(POINTS[:2], [[0, 0, 1.0], [0, 0, 0]]),
        ValueError,
        "normals: row 1 is not finite or has zero length",
    ),
    Case(
        "cloud/int normals",
        lambda f: cloud_with(POINTS[:2], np.ones((2, 3), int)),
        ValueError,
        "normals",
    ),
    Case(
        "cloud/normal rows",
        lambda f: cloud_with(POINTS[:3], NORMALS[:2]),
        ValueError,
        "expected 3 rows",
    ),
    Case(
        "cloud/drop non-finite",
        lambda f: svs.PointCloud(
            [[NAN, 0, 0], [1.0, 1, 1], [2.0, 2, 2]],
            [[0, 0, 1.0], [0, 0, 1], [0, 0, 0]],
            drop_non_finite=True,
        ),
        check=has_length(1),
    ),
    Case(
        "cloud/transformed NaN",
        lambda f: OBJECT.transformed(np.full((4, 4), NAN)),
        ValueError,
        "non-finite",
    ),
    Case("cloud/transformed 3x3", lambda f: OBJECT.transformed(np.eye(3)), ValueError, r"\(4, 4\)"),
    Case(
        "cloud/transformed reflection",
        lambda f: OBJECT.transformed(np.diag([1.0, 1, -1, 1])),
        ValueError,
        "not a rigid transform",
    ),
    # Files.
    Case(
        "load/missing",
        lambda f: svs.load_cloud(f.path("missing.pcd")),
        FileNotFoundError,
        "no such file",
    ),
    Case(
        "load/folder",
        lambda f: svs.load_cloud(f.folder),
        IsADirectoryError,
        "path: is a folder, not a file",
    ),
    Case(
        "load/extension",
        lambda f: svs.load_cloud(f.path("cloud.xyz")),
        ValueError,
        "unsupported extension",
    ),
    Case(
        "load/empty file",
        lambda f: svs.load_cloud(f.path("empty.pcd")),
        ValueError,
        "is not a PCD file",
    ),
    Case(
        "load/text as pcd",
        lambda f: svs.load_cloud(f.path("not_a_cloud.pcd")),
        ValueError,
        "not a PCD",
    ),
    Case(
        "load/stl as ply",
        lambda f: svs.load_cloud(f.path("not_a_cloud.ply")),
        ValueError,
        "not a PLY",
    ),
    Case(
        "load/truncated pcd",
        lambda f: svs.load_cloud(f.path("truncated.pcd")),
        ValueError,
        "is truncated",
    ),
    Case(
        "load/truncated compressed",
        lambda f: svs.load_cloud(f.path("truncated_compressed.pcd")),
        ValueError,
        "is truncated",
    ),
    Case(
        "load/truncated ply",
        lambda f: svs.load_cloud(f.path("truncated.ply")),
        ValueError,
        "is truncated",
    ),
    Case(
        "load/inflated point count",  # crashed PCL's reader before the header check
        lambda f: svs.load_cloud(f.path("inflated.pcd")),
        ValueError,
        "the compressed block holds",
    ),
    Case(
        "load/split header line",  # crashed PCL's reader before the header check
        lambda f: svs.load_cloud(f.path("split_header.pcd")),
        ValueError,
        "unknown header line '7'",
    ),
    Case(
        "load/garbage header",
        lambda f: svs.load_cloud(f.path("garbage_header.pcd")),
        ValueError,
        "not a valid PCD file",
    ),
    Case(
        "load/words for numbers",  # PCL read them as zeros
        lambda f: svs.load_cloud(f.path("words.pcd")),
        ValueError,
        "'a' is not a decimal number",
    ),
    Case(
        "load/invalid UTF-8",  # the message was not decodable: UnicodeDecodeError
        lambda f: svs.load_cloud(f.path("invalid_utf8.pcd")),
        ValueError,
        r"'\?\?' is not a decimal number",
    ),
    Case(
        "load/only NaN",
        lambda f: svs.load_cloud(f.path("nan_only.pcd")),
        ValueError,
        "no finite point",
    ),
    Case("load/one point", lambda f: svs.load_cloud(f.path("one_point.pcd")), check=has_length(1)),
    Case(
        "save/empty cloud",
        lambda f: svs.save_cloud(f.path("out.pcd"), svs.PointCloud(np.zeros((0, 3)))),
        ValueError,
        "empty",
    ),
    Case(
        "save/extension",
        lambda f: svs.save_cloud(f.path("out.txt"), OBJECT),
        ValueError,
        "unsupported extension",
    ),
    Case(
        "save/no folder",
        lambda f: svs.save_cloud(f.path("none/out.pcd"), OBJECT),
        ValueError,
        "cannot write",
    ),
    Case(
        "save/encoding",
        lambda f: svs.save_cloud(f.path("o.pcd"), OBJECT, "zip"),
        ValueError,
        "encoding must be",
    ),
    Case(
        "save/to a FIFO",  # blocked until a reader came (a hang)
        lambda f: svs.save_cloud(str(f.fifo()), OBJECT),
        ValueError,
        "is not a regular file, not a file to write a cloud to",
    ),
    Case(
        "save/to a folder",
        lambda f: svs.save_cloud(str(f.subfolder("a_folder.pcd")), OBJECT),
        ValueError,
        "is a folder",
    ),
    # Preprocessing.
    Case(
        "downsample/zero",
        lambda f: svs.voxel_downsample(OBJECT, 0.0),
        ValueError,
        "voxel_size must be finite and > 0",
    ),
    Case(
        "downsample/NaN",
        lambda f: svs.voxel_downsample(OBJECT, NAN),
        ValueError,
        "voxel_size must be finite",
    ),
    Case(
        "downsample/tiny", lambda f: svs.voxel_downsample(OBJECT, 1e-300), ValueError, "too small"
    ),
    Case(
        "downsample/huge",
        lambda f: svs.voxel_downsample(OBJECT, 1e7),
        ValueError,
        "must be <= 1e\\+06",
    ),
    Case(
        "downsample/identical points",
        lambda f: svs.voxel_downsample(cloud_with(np.tile([1.0, 2, 3], (50, 1))), 0.01),
        check=has_length(1),
    ),
    Case(
        "downsample/1e6 m away keeps precision",  # PCL's floats: 6 cm steps at 1e6 m
        lambda f: (
            np.ptp(svs.voxel_downsample(cloud_with(POINTS + 1e6), 0.004).points, axis=0)
            - np.ptp(svs.voxel_downsample(OBJECT, 0.004).points, axis=0)
        ),
        check=lambda d: np.testing.assert_allclose(d, 0, atol=1e-4),
    ),
    Case(
        "normals/one point",
        lambda f: svs.estimate_normals(cloud_with([[0.0, 0, 0]])),
        ValueError,
        "no point has enough neighbours",
    ),
    Case(
        "normals/identical points",
        lambda f: svs.estimate_normals(cloud_with(np.tile([1.0, 2, 3], (50, 1)))),
        ValueError,
        "coincident or collinear",
    ),
    Case(
        "normals/collinear",
        lambda f: svs.estimate_normals(cloud_with(line())),
        ValueError,
        "no point has enough neighbours",
    ),
    Case(
        "normals/coplanar",
        lambda f: np.asarray(
            svs.estimate_normals(cloud_with(plane()[0]), viewpoint=(0, 0, 1)).normals
        )[:, 2].min(),
        check=lambda z: np.testing.assert_array_less(0.999, z),
    ),
    Case(
        "normals/radius NaN",
        lambda f: svs.estimate_normals(OBJECT, radius=NAN),
        ValueError,
        "radius",
    ),
    Case(
        "normals/k negative",
        lambda f: svs.estimate_normals(OBJECT, k_neighbors=-1),
        ValueError,
        "k_neighbors",
    ),
    Case(
        "normals/k 2**30",  # 4 GB reserved, then std::bad_alloc
        lambda f: svs.estimate_normals(OBJECT, k_neighbors=2**30),
        ValueError,
        r"k_neighbors must be in \[0, 1024\]",
    ),
    Case(
        "normals/100000 threads",  # crashed the process (PCL's OpenMP)
        lambda f: svs.estimate_normals(OBJECT, threads=100000),
        ValueError,
        r"threads must be in \[1, 256\]",
    ),
    Case(
        "normals/viewpoint shape",
        lambda f: svs.estimate_normals(OBJECT, viewpoint=[1, 2]),
        TypeError,
    ),
    Case(
        "normals/viewpoint NaN",
        lambda f: svs.estimate_normals(OBJECT, viewpoint=[NAN, 0, 0]),
        ValueError,
        "viewpoint",
    ),
    Case(
        "normals/orientation",
        lambda f: svs.estimate_normals(OBJECT, orientation="up"),
        ValueError,
        "orientation must be",
    ),
    # Voxel grids.
    Case(
        "grid/resolution zero",
        lambda f: svs.make_grid_spec(OBJECT, OBJECT, 0.0),
        ValueError,
        "resolution",
    ),
    Case(
        "grid/tiny resolution",
        lambda f: svs.make_grid_spec(OBJECT, OBJECT, 1e-6),
        ValueError,
        "max_voxels",
    ),
    Case(
        "grid/empty cloud",
        lambda f: svs.make_grid_spec(cloud_with(np.zeros((0, 3))), OBJECT, 0.01),
        ValueError,
        "empty",
    ),
    Case(
        "gridspec/dims past int",
        lambda f: svs.GridSpec([0, 0, 0], 0.01, [2**31, 1, 1]),
        ValueError,
        "dims must be in",
    ),
    Case(
        "gridspec/zero dims",
        lambda f: svs.GridSpec([0, 0, 0], 0.01, [0, 4, 4]),
        ValueError,
        "dims must be in",
    ),
    Case(
        "gridspec/NaN origin",
        lambda f: svs.GridSpec([NAN, 0, 0], 0.01, [4, 4, 4]),
        ValueError,
        "origin",
    ),
    Case(
        "gridspec/negative resolution",
        lambda f: svs.GridSpec([0, 0, 0], -1.0, [4, 4, 4]),
        ValueError,
        "resolution",
    ),
    Case(
        "gridspec/index of NaN and 1e300 is clamped",
        lambda f: grid_spec(4, 1e-9).index_of([NAN, 1e300, -1e300]),
        check=lambda i: np.testing.assert_array_equal(i, [-(2**30), 2**30, -(2**30)]),
    ),
    Case(
        "voxelize/over limit",
        lambda f: svs.voxelize(OBJECT, grid_spec(1024)),
        ValueError,
        "max_voxels",
    ),
    Case(
        "voxelize/occupancy",
        lambda f: svs.voxelize(OBJECT, grid_spec(8), "soft"),
        ValueError,
        "occupancy must be",
    ),
    Case(
        "voxelize/points 1e6 m away are outside",
        lambda f: svs.voxelize(cloud_with(POINTS * 1e6), grid_spec(64)).points_outside,
        check=lambda n: np.testing.assert_array_less(1990, n),
    ),
    Case(
        "fft size/past 2^30", lambda f: svs.fft_friendly_size(2**31 - 1), ValueError, "n must be <="
    ),
    # EGI and spherical harmonics.
    Case(
        "egi/bandwidth 0",
        lambda f: svs.egi(OBJECT, 0),
        ValueError,
        r"bandwidth must be in \[1, 128\]",
    ),
    Case("egi/no normals", lambda f: svs.egi(cloud_with(POINTS), 4), ValueError, "has no normals"),
    Case(
        "egi/int normals", lambda f: svs.egi(np.ones((3, 3), int), 4), ValueError, "floating dtype"
    ),
    Case("egi/zero normal", lambda f: svs.egi(np.zeros((1, 3)), 4), ValueError, "zero length"),
    Case(
        "egi/weights length",
        lambda f: svs.egi(OBJECT, 4, np.ones(3)),
        ValueError,
        "weights: expected 2000",
    ),
    Case(
        "egi cell/bandwidth 0", lambda f: svs.egi_cell([0, 0, 1.0], 0), ValueError, "bandwidth"
    ),  # was SIGFPE
    Case(
        "egi cell/NaN", lambda f: svs.egi_cell([NAN, 0, 1.0], 8), ValueError, "finite and non-zero"
    ),
    Case("egi cell/2 entries", lambda f: svs.egi_cell([0, 1.0], 8), TypeError),
    Case(
        "egi coefficients/method",
        lambda f: svs.egi_coefficients(OBJECT, 4, "fft"),
        ValueError,
        "method must be",
    ),
    Case(
        "egi coefficients/NaN",
        lambda f: svs.egi_coefficients(np.array([[NAN, 0, 1]]), 4),
        ValueError,
        "normals: row 0",
    ),
    Case("sh index/out of range", lambda f: svs.sh_index(100000, 0), ValueError, "0 <= l < 128"),
    Case(
        "sh synthesis/length", lambda f: svs.sh_synthesis(np.ones(15), 0), ValueError, "not B\\^2"
    ),
    Case(
        "smooth/negative sigma",
        lambda f: svs.smooth_coefficients(coefficients(), 4, -1.0),
        ValueError,
        "sigma",
    ),
    Case(
        "harmonics/zero direction",
        lambda f: svs.real_spherical_harmonics([0, 0, 0.0], 3),
        ValueError,
        "direction",
    ),
    # Rotation.
    Case("wigner/reflection", lambda f: svs.wigner_real(-np.eye(3), 2), ValueError, "R"),
    Case(
        "wigner/int matrix",
        lambda f: svs.wigner_real(np.eye(3, dtype=int), 2),
        ValueError,
        "floating dtype",
    ),
    Case("wigner/lmax 128", lambda f: svs.wigner_real(np.eye(3), 128), ValueError, "lmax"),
    Case(
        "correlation/uniform EGI",
        lambda f: svs.so3_correlation(np.r_[1.0, np.zeros(15)], coefficients(), np.eye(3)),
        ValueError,
        "uniform EGI",
    ),
    Case(
        "correlation/NaN",
        lambda f: svs.so3_correlation(np.full(16, NAN), coefficients(), np.eye(3)),
        ValueError,
        "non-finite",
    ),
    Case(
        "search/k 0",
        lambda f: svs.so3_search(coefficients(), coefficients(), 4, k=0),
        ValueError,
        "candidates",
    ),
    Case(
        "search/k 10^9 is bounded by the maxima",
        lambda f: len(svs.so3_search(coefficients(8), coefficients(8), 8, k=10**9)),
        check=lambda n: np.testing.assert_array_less(n, 8**3),
    ),
    # Translation.
    Case(
        "phase/empty grids",
        lambda f: svs.phase_correlation(np.zeros((4, 4, 4)), np.zeros((4, 4, 4))),
        ValueError,
        "is empty",
    ),
    Case(
        "phase/NaN grid",
        lambda f: svs.phase_correlation(np.full((4, 4, 4), NAN), np.ones((4, 4, 4))),
        ValueError,
        "non-finite",
    ),
    Case(
        "phase/shapes",
        lambda f: svs.phase_correlation(np.ones((4, 4, 4)), np.ones((4, 4, 5))),
        ValueError,
        "expected",
    ),
    Case(
        "phase/2-D",
        lambda f: svs.phase_correlation(np.ones((4, 4)), np.ones((4, 4))),
        ValueError,
        "3-D array",
    ),
    Case(
        "phase/strings",
        lambda f: svs.phase_correlation(np.full((1, 1, 1), "a"), np.ones((1, 1, 1))),
        ValueError,
        "numbers",
    ),
    Case(
        "phase/one voxel",
        lambda f: svs.phase_correlation(np.ones((1, 1, 1)), np.ones((1, 1, 1))),
        check=lambda r: np.testing.assert_array_equal(r.shift_voxels, 0),
    ),
    Case(
        "phase/over limit before allocating",  # 2048^3 voxels: 170 GB of FFT buffers
        lambda f: svs.PhaseCorrelation(svs.GridSpec([0, 0, 0], 0.01, [2048] * 3)),
        ValueError,
        r"about 171\.\d+ GB\) exceeds the limit of 16777216 voxels \(GridLimits::max_voxels\)",
    ),
    Case(
        "phase/threads",
        lambda f: svs.PhaseCorrelation(grid_spec(8), threads=0),
        ValueError,
        "threads",
    ),
    Case(
        "phase/band",
        lambda f: svs.PhaseCorrelation(grid_spec(8), subvoxel_band=0.7),
        ValueError,
        "subvoxel_band",
    ),
    Case(
        "phase/no target",
        lambda f: svs.PhaseCorrelation(grid_spec(64)).estimate(svs.voxelize(OBJECT, grid_spec(64))),
        ValueError,
        "set_target",
    ),
    Case(
        "translation cost/shift of 2",
        lambda f: svs.translation_cost(np.ones((2, 2, 2)), np.ones((2, 2, 2)), (1, 2)),
        TypeError,
    ),
    # Alignment: errors name the argument or the limit.
    Case(
        "align/empty model",
        lambda f: svs.align(np.zeros((0, 3)), OBJECT),
        ValueError,
        "model is empty",
    ),
    Case(
        "align/int array",
        lambda f: svs.align(np.zeros((10, 3), int), OBJECT),
        ValueError,
        "floating dtype",
    ),
    Case(
        "align/(N, 5) array",
        lambda f: svs.align(np.zeros((10, 5)), OBJECT),
        ValueError,
        r"\(N, 3\) / \(N, 6\)",
    ),
    Case(
        "align/a path",
        lambda f: svs.align(f.path("model.pcd"), OBJECT),
        ValueError,
        "model must be",
    ),
    Case(
        "align/NaN coordinates",
        lambda f: svs.align(np.array([[NAN, 0, 0]]), OBJECT),
        ValueError,
        "not finite",
    ),
    Case(
        "align/params of another type",
        lambda f: svs.align(OBJECT, OBJECT, params=5),
        TypeError,
        "AlignParams",
    ),
    Case(
        "align/setting of another type",
        lambda f: svs.align(OBJECT, OBJECT, voxel_size="8 mm"),
        TypeError,
        "'voxel_size'",
    ),
    Case(
        "align/unknown setting",
        lambda f: svs.align(OBJECT, OBJECT, voxel=0.01),
        TypeError,
        "unknown alignment setting 'voxel'",
    ),
    Case(
        "align/voxel NaN",
        lambda f: svs.align(OBJECT, OBJECT, voxel_size=NAN),
        ValueError,
        "voxel_size must be finite",
    ),
    Case(
        "align/voxel negative",
        lambda f: svs.align(OBJECT, OBJECT, voxel_size=-0.01),
        ValueError,
        "voxel_size",
    ),
    Case(
        "align/voxel too fine",  # downsampled to 0.5 nm (every point its own voxel): the grid
        lambda f: svs.align(OBJECT, OBJECT, voxel_size=1e-9),
        ValueError,
        "voxels of 1e-09 m along an axis, over the limit .* voxels \\(max_voxels\\)",
    ),
    Case(
        "align/tiny voxel",
        lambda f: svs.align(OBJECT, OBJECT, voxel_size=1e-5, downsample=False),
        ValueError,
        "max_voxels",
    ),
    Case(
        "align/bandwidth",
        lambda f: svs.align(OBJECT, OBJECT, bandwidth=200),
        ValueError,
        r"bandwidth must be in \[2, 64\]",
    ),
    Case(
        "align/threads",
        lambda f: svs.align(OBJECT, OBJECT, threads=1000),
        ValueError,
        r"threads must be in \[1, 256\]",
    ),
    Case(
        "align/max_seconds negative",
        lambda f: svs.align(OBJECT, OBJECT, max_seconds=-1.0),
        ValueError,
        "max_seconds",
    ),
    Case(
        "align/max_voxels negative",
        lambda f: svs.align(OBJECT, OBJECT, max_voxels=-1),
        ValueError,
        "max_voxels must be >= 1",
    ),
    Case(
        "align/max_voxels 1000",
        lambda f: svs.align(OBJECT, OBJECT, max_voxels=1000),
        ValueError,
        "max_voxels",
    ),
    Case(
        "align/max_voxels 2**40",  # a budget no machine holds: std::bad_alloc
        lambda f: svs.align(OBJECT, OBJECT, max_voxels=2**40),
        ValueError,
        r"max_voxels must be <= 2\^32",
    ),
    Case(
        "align/max_iterations 10**6",  # ran past any wait (2**31 - 1: a hang)
        lambda f: svs.align(OBJECT, OBJECT, max_iterations=10**6),
        ValueError,
        r"max_iterations must be in \[1, 10000\]",
    ),
    Case(
        "align/refinement_iterations 2**31 - 1",
        lambda f: svs.align(OBJECT, OBJECT, refinement_iterations=2**31 - 1),
        ValueError,
        r"refinement_iterations must be in \[1, 10000\]",
    ),
    Case(
        "align/guess not rigid",
        lambda f: svs.align(OBJECT, OBJECT, initial_guess=np.ones((4, 4))),
        ValueError,
        "initial_guess",
    ),
    Case(
        "align/viewpoint shape",
        lambda f: svs.align(POINTS, POINTS, sensor_origin=(1, 2)),
        TypeError,
        "sensor_origin",
    ),
    Case(
        "align/rotation step",
        lambda f: svs.align(OBJECT, OBJECT, rotation_step="big"),
        ValueError,
        "rotation_step must be",
    ),
    Case(
        "align/scene spanning 2e6 m at 0.1 mm",  # voxel counts past the range of int
        lambda f: svs.align(
            OBJECT,
            cloud_with([[-1e6, 0, 0], [1e6, 0, 0]], [[0, 0, 1.0], [0, 1, 0]]),
            **fast(voxel_size=1e-4),
        ),
        ValueError,
        "max_voxels",
    ),
    Case(
        "align/one point without normal",
        lambda f: svs.align(POINTS[:1], OBJECT),
        ValueError,
        "no point has enough neighbours",
    ),
    Case(
        "align/collinear without normals",
        lambda f: svs.align(line(), OBJECT),
        ValueError,
        "no point has enough neighbours",
    ),
    # Alignment: degenerate clouds give a finite pose whose verdict says not to act on it.
    Case(
        "align/one point",
        lambda f: svs.align(cloud_with(POINTS[:1], NORMALS[:1]), OBJECT, **fast()),
        check=unreliable,
    ),
    Case(
        "align/identical points",
        lambda f: svs.align(
            cloud_with(np.tile(POINTS[0], (100, 1)), np.tile(NORMALS[0], (100, 1))),
            OBJECT,
            **fast(),
        ),
        check=unreliable,
    ),
    Case(
        "align/one point scene",
        lambda f: svs.align(OBJECT, cloud_with(POINTS[:1], NORMALS[:1]), **fast()),
        check=unreliable,
    ),
    Case(
        "align/coplanar onto itself",  # rotation about the normal is unobservable: any is right
        lambda f: svs.align(cloud_with(*plane()), cloud_with(*plane()), **fast()),
        check=lambda r: (
            finite(r),
            np.testing.assert_allclose(abs(np.asarray(r.T_scene_model)[2, 2]), 1, atol=1e-3),
        ),
    ),
    Case(
        "align/1e6 m from the origin",
        lambda f: svs.align(
            cloud_with(POINTS + 1e6, NORMALS),
            cloud_with(POINTS + 1e6 + [0.02, 0, 0], NORMALS),
            downsample=False,
        ),
        check=lambda r: np.testing.assert_allclose(
            np.asarray(r.T_scene_model)[:3, 3], [0.02, 0, 0], atol=1e-3
        ),
    ),
    Case(
        "align/max_seconds",
        lambda f: svs.align(OBJECT, OBJECT, max_seconds=1e-9, **fast()),
        check=stopped_for("max_seconds"),
    ),
    Case(
        "align/max_iterations",
        lambda f: svs.align(
            OBJECT,
            OBJECT.transformed(np.eye(4) + np.eye(4, k=3) * 0.03),
            max_iterations=1,
            global_search=False,
            downsample=False,
        ),
        check=stopped_for("max_iterations"),
    ),
    # Kinematics.
    Case(
        "urdf/missing file",
        lambda f: svs.Kinematics(f.path("none.urdf"), "base_link", "tool"),
        FileNotFoundError,
    ),
    Case(
        "urdf/missing link",
        lambda f: svs.Kinematics(f.path("missing_link.urdf"), "base_link", "tool"),
        ValueError,
        "not a valid URDF",
    ),
    Case(
        "urdf/truncated",
        lambda f: svs.Kinematics(f.path("truncated.urdf"), "base_link", "tool"),
        ValueError,
        "not a valid URDF",
    ),
    Case(
        "urdf/a point cloud",
        lambda f: svs.Kinematics(f.path("model.pcd"), "base_link", "tool"),
        ValueError,
        "not a valid URDF",
    ),
    Case(
        "urdf/unknown tip",
        lambda f: svs.Kinematics(str(URDF), "base_link", "gripper"),
        ValueError,
        "tip_link: no link named 'gripper'",
    ),
    Case(
        "urdf/unknown base",
        lambda f: svs.Kinematics(str(URDF), "floor", "tool"),
        ValueError,
        "base_link: no link named 'floor'",
    ),
    Case(
        "urdf/tip above base",
        lambda f: svs.Kinematics(str(URDF), "link4", "link1"),
        ValueError,
        "is not below",
    ),
    Case(
        "urdf/zero axis",  # poses and Jacobians were NaN
        lambda f: svs.Kinematics(f.path("zero_axis.urdf"), "base_link", "tool"),
        ValueError,
        "zero or non-finite axis",
    ),
    Case(
        "urdf/loop of links",  # an endless walk up the loop, then MemoryError
        lambda f: svs.Kinematics(f.path("loop.urdf"), "base_link", "link6"),
        ValueError,
        "form a loop",
    ),
    Case(
        "urdf/string",
        lambda f: svs.Kinematics.from_urdf_string("<robot/>", "a", "b"),
        ValueError,
        "URDF",
    ),
    Case(
        "kinematics/q length",
        lambda f: svs.Kinematics(str(URDF), "base_link", "tool").forward(np.zeros(2)),
        ValueError,
        "expected 6",
    ),
    Case(
        "kinematics/q NaN",
        lambda f: svs.Kinematics(str(URDF), "base_link", "tool").jacobian(np.full(6, NAN)),
        ValueError,
        "non-finite",
    ),
    Case(
        "kinematics/q text",
        lambda f: svs.Kinematics(str(URDF), "base_link", "tool").forward("000000"),
        ValueError,
        "array of numbers",
    ),
    Case(
        "kinematics/twist 1e300 stays within limits",
        lambda f: (
            svs.Kinematics(str(URDF), "base_link", "tool")
            .joint_velocities(np.zeros(6), np.full(6, 1e300))
            .q_dot
        ),
        check=finite,
    ),
    Case(
        "lstsq/empty",
        lambda f: svs.damped_least_squares(np.zeros((0, 0)), np.zeros(0)),
        ValueError,
        "J is empty",
    ),
    Case(
        "lstsq/b length",
        lambda f: svs.damped_least_squares(np.ones((6, 3)), np.zeros(5)),
        ValueError,
        "b: expected 6",
    ),
    # The align command: exit 2 with the problem named, 1 for a result that did not converge.
    Case(
        "cli/missing model",
        lambda f: cli("align", f.path("none.pcd"), f.path("scene.pcd")),
        check=exits(2, "MODEL: no such file"),
    ),
    Case(
        "cli/truncated scene",
        lambda f: cli("align", f.path("model.pcd"), f.path("truncated.pcd")),
        check=exits(2, "SCENE:"),
    ),
    Case(
        "cli/not a cloud",
        lambda f: cli("align", f.path("not_a_cloud.pcd"), f.path("scene.pcd")),
        check=exits(2, "not a PCD file"),
    ),
    Case(
        "cli/inflated count",
        lambda f: cli("align", f.path("inflated.pcd"), f.path("scene.pcd")),
        check=exits(2, "compressed block"),
    ),
    Case(
        "cli/only NaN",
        lambda f: cli("align", f.path("nan_only.pcd"), f.path("scene.pcd")),
        check=exits(2, "no finite point"),
    ),
    Case(
        "cli/one point",
        lambda f: cli("align", f.path("one_point.pcd"), f.path("scene.pcd")),
        check=exits(2, "no point has enough neighbours"),
    ),
    Case(
        "cli/tiny voxel",
        lambda f: cli("align", f.path("model.pcd"), f.path("scene.pcd"), "--voxel-size", "1e-9"),
        check=exits(2, "voxel_size"),
    ),
    # Issue 34's findings on the Python side: each a row.
    Case(
        "servo params/nan backoff",
        lambda f: svs.ServoParams(relocalize_backoff=NAN),
        TypeError,
        "relocalize_backoff must be an integer",
    ),
    Case(
        "servo params/fractional steps",
        lambda f: svs.ServoParams(refute_steps=2.5),
        TypeError,
        "refute_steps must be an integer",
    ),
    Case(
        "servo params/gain as text",
        lambda f: svs.ServoParams(lambda_t="2"),
        TypeError,
        r"lambda_t must be a number, got '2' \(str\)",
    ),
    Case(
        "servo params/share as text",
        lambda f: svs.ServoParams(min_fitness="high"),
        TypeError,
        "min_fitness must be a number",
    ),
    Case(
        "pose_error/bottom row",
        lambda f: svs.pose_error(
            np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 2, 3, 4]])
        ),
        ValueError,
        r"T must have the bottom row \[0, 0, 0, 1\]",
    ),
    Case(
        "pose_error/nan center",
        lambda f: svs.pose_error(np.eye(4), np.eye(4), center=[NAN, 0, 0]),
        ValueError,
        "center must be 3 finite numbers",
    ),
    Case(
        "pose_error/nan transform",
        lambda f: svs.pose_error(np.full((4, 4), NAN)),
        ValueError,
        "T must be finite",
    ),
    Case(
        "servo step/nan motion",
        lambda f: svs.SpectralServo(OBJECT).step(OBJECT, np.full((4, 4), NAN), now=0.0),
        ValueError,
        "T_previous_current must be a finite 4x4 transform",
    ),
    Case(
        "servo step/motion not rigid",
        lambda f: svs.SpectralServo(OBJECT).step(OBJECT, 2 * np.eye(4), now=0.0),
        ValueError,
        "T_previous_current must be a rigid transform",
    ),
    Case(
        "cli/nan error limit",
        lambda f: cli(
            "align", f.path("model.pcd"), f.path("scene.pcd"), "--max-rotation-error", "nan"
        ),
        check=exits(2, "--max-rotation-error: must be a finite number > 0"),
    ),
    Case(
        "cli/negative seed",
        lambda f: cli("servo-sim", "--seed", "-1", "--no-figures"),
        check=exits(2, "--seed: must be an integer in [0, 2**32)"),
    ),
    # Issue 34's findings on the C++ side.
    Case(
        "fft_friendly_size/zero",
        lambda f: svs.fft_friendly_size(0),
        ValueError,
        "n must be >= 1, got 0",
    ),
    Case(
        "fft_friendly_size/negative",
        lambda f: svs.fft_friendly_size(-5),
        ValueError,
        "n must be >= 1, got -5",
    ),
    Case(
        "so3_exp/huge vector",
        lambda f: svs.so3_exp([1e200, 0.0, 0.0]),
        check=lambda R: np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9),
    ),
    Case(
        "so3_search/257 threads",
        lambda f: svs.so3_search(np.ones(64), np.ones(64), 8, threads=257),
        ValueError,
        r"threads must be in \[1, 256\]",
    ),
    Case(
        "egi/negative weight",
        lambda f: svs.egi(NORMALS[:10], 4, -np.ones(10)),
        ValueError,
        "weights: entry 0 must be finite and >= 0",
    ),
    Case(
        "dominant_direction/zero normals",
        lambda f: svs.dominant_direction(np.zeros((5, 3))),
        ValueError,
        "normals: row 0 is not a unit vector",
    ),
    Case(
        "dominant_direction/nan normals",
        lambda f: svs.dominant_direction(np.full((5, 3), NAN)),
        ValueError,
        "normals: row 0 is not a unit vector",
    ),
    Case(
        "save_cloud/beyond float32",
        lambda f: svs.save_cloud(
            f.folder / "huge.pcd", svs.PointCloud(np.array([[1e39, 0.0, 0.0]]))
        ),
        ValueError,
        "point 0 has a coordinate beyond the float32 range",
    ),
    Case(
        "align params/negative max_voxels",
        lambda f: svs.AlignParams(max_voxels=-1),
        ValueError,
        "max_voxels must be >= 1",
    ),
    Case(
        "voxelize/negative max_voxels",
        lambda f: svs.make_grid_spec(OBJECT, OBJECT, 0.01, -1),
        ValueError,
        "max_voxels must be >= 1",
    ),
    Case(
        "load_cloud/fifo",
        lambda f: svs.load_cloud(str(f.fifo())),
        ValueError,
        r"path: is not a regular file \(a FIFO",
    ),
    Case(
        "load_cloud/symlink loop",
        lambda f: svs.load_cloud(str(f.loop())),
        OSError,
        "too many levels of symbolic links",
    ),
    Case(
        "urdf/zero velocity limit",
        lambda f: svs.Kinematics.from_urdf_string(
            URDF.read_text().replace('velocity="2.0"', 'velocity="0"', 1),
            "base_link",
            "tool",
        ),
        ValueError,
        "velocity limit 0: it must be > 0",
    ),
    Case(
        "cloud_from_depth/huge normal_step",  # was SIGSEGV: 2 * normal_step overflowed
        lambda f: svs.cloud_from_depth(
            np.ones((48, 64), np.float32), np.diag([500.0, 500.0, 1.0]), normal_step=2**31 - 1
        ),
        ValueError,
        "normal_step must be <= the image's larger side, 64 pixels",
    ),
    Case(
        "cloud_from_depth/huge window",  # was 33 s, or 3.1 GB with normals=False
        lambda f: svs.cloud_from_depth(
            np.ones((48, 64), np.float32),
            np.diag([500.0, 500.0, 1.0]),
            normals=False,
            window=2**27 + 1,
        ),
        ValueError,
        "window must be <= twice the image's larger side plus one, 129 pixels",
    ),
    Case(
        "urdf/nested 100000 levels",  # was SIGSEGV after about 7 s (the parser recursed)
        lambda f: svs.Kinematics.from_urdf_string(
            "<robot name='r'>" + "<a>" * 100_000 + "</a>" * 100_000 + "</robot>", "a", "b"
        ),
        ValueError,
        "nested deeper than 256 levels",
    ),
    Case(
        "urdf/nested 100000 levels, a file",
        lambda f: svs.Kinematics(f.path("deep.urdf"), "a", "b"),
        ValueError,
        "nested deeper than 256 levels",
    ),
    Case(
        "cli/not converged exits 1",
        lambda f: cli(
            "align", f.path("model.pcd"), f.path("scene.pcd"), "--paper", "--max-iterations", "1"
        ),
        check=exits(1),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_documented_behaviour(case: Case, files: Files) -> None:
    if case.raises is not None:
        with pytest.raises(case.raises, match=case.match or None):
            case.call(files)
        return
    result = case.call(files)
    if case.check is not None:
        case.check(result)


def test_case_names_are_unique() -> None:
    names = [case.name for case in CASES]
    assert len(names) == len(set(names))
    assert all(re.fullmatch(r"[a-z][^\[\]]*", name) for name in names)


def test_a_pcd_whose_first_line_is_a_vertical_tab_is_refused(tmp_path):
    """PCL splits header lines on spaces, tabs and carriage returns only: to it a line of a
    vertical tab is an unknown header line that ends the header, and its binary reader
    then crashed (found by fuzz/pcd_fuzzer). The header check splits the same way."""
    body = (
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
        b"HEIGHT 1\nPOINTS 1\nDATA binary\n" + np.zeros(3, dtype=np.float32).tobytes()
    )
    path = tmp_path / "vertical_tab.pcd"
    path.write_bytes(b"\x0b\n" + body)
    with pytest.raises(ValueError, match="not a PCD file"):
        svs.load_cloud(str(path))
    path.write_bytes(body)  # the same file without that line loads
    assert len(svs.load_cloud(str(path))) == 1


@pytest.mark.parametrize("blank", [b"\r", b" ", b"\t"])
def test_a_pcd_with_a_header_line_of_white_space_is_refused(tmp_path, blank):
    """PCL's reader skips an empty header line but ends the header at a line of spaces,
    tabs or a carriage return (a blank line of a CRLF file); its reader then crashed on
    the header it had (found by fuzz/pcd_fuzzer)."""
    body = (
        b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
        b"HEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n"
    )
    path = tmp_path / "blank_line.pcd"
    path.write_bytes(b"VERSION 0.7\n" + blank + b"\n" + body)
    with pytest.raises(ValueError, match="white space only"):
        svs.load_cloud(str(path))
    path.write_bytes(b"VERSION 0.7\n\n" + body)  # an empty line is skipped, as PCL does
    assert len(svs.load_cloud(str(path))) == 1


def test_a_ply_with_an_indented_header_line_is_refused(tmp_path):
    """PCL's PLY reader asserted (aborting the process) on an indented obj_info line
    (found by fuzz/ply_fuzzer)."""
    body = (
        b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        b"end_header\n1 2 3\n"
    )
    path = tmp_path / "indented.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\n obj_info num_rows 1\n" + body)
    with pytest.raises(ValueError, match="begins with white space"):
        svs.load_cloud(str(path))
    path.write_bytes(b"ply\nformat ascii 1.0\nobj_info num_rows 1\n" + body)
    assert len(svs.load_cloud(str(path))) == 1


@pytest.mark.parametrize("index, refused", [("-1", True), ("3", True), ("1.5", True), ("2", False)])
def test_a_ply_range_grid_naming_no_vertex_is_refused(tmp_path, index, refused):
    """PCL's PLY reader copies each cell of an organized cloud from the vertex its
    range_grid list names, unchecked: -1 read before its buffer and killed the process
    (SIGSEGV, found by fuzz/ply_fuzzer)."""
    path = tmp_path / "organized.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\nelement vertex 3\n"
        "property float x\nproperty float y\nproperty float z\nelement range_grid 4\n"
        "property list uchar int vertex_indices\nend_header\n0 0 1\n0.1 0 1\n0 0.1 1\n"
        f"1 0\n1 1\n0\n1 {index}\n"
    )
    if refused:
        with pytest.raises(ValueError, match=f"range_grid cell 3 names vertex '{index}'"):
            svs.load_cloud(path)
    else:
        np.testing.assert_allclose(
            np.asarray(svs.load_cloud(path).points),
            [[0, 0, 1], [0.1, 0, 1], [0, 0.1, 1]],
            atol=1e-7,
        )


def test_a_large_depth_frame_leaves_no_large_scratch_behind():
    """One 3000 x 3000 frame kept about 700 MB of per-thread scratch resident after the call;
    buffers over 64 MB are now released: the resident memory grows by less than 150 MB
    (the cloud itself, 9 M points with normals, is 430 MB and is freed with it)."""
    depth = np.full((3000, 3000), 1.0, np.float32)
    K = np.array([[1500.0, 0.0, 1500.0], [0.0, 1500.0, 1500.0], [0.0, 0.0, 1.0]])
    before = resident_megabytes()
    cloud = svs.cloud_from_depth(depth, K)
    assert len(cloud) > 8_000_000
    del cloud
    assert resident_megabytes() - before < 150.0


def test_every_bandwidth_once_leaves_a_bounded_cache():
    """Before: the spherical harmonic transforms of every bandwidth, cached for the process,
    kept 549 MB resident once each had been used, and the Wigner generators of every lmax
    2.1 GB. Now the transforms' cache keeps 64 MB of the recently used ones and the
    generators are built at each call: the resident memory grows by less than 500 MB (freed
    heap that the allocator keeps included; 200-330 MB measured here)."""
    before = resident_megabytes()
    for bandwidth in range(1, 129):
        grid = np.ones((2 * bandwidth, 2 * bandwidth))
        coefficients = svs.sh_coefficients(grid, bandwidth)
        assert coefficients[0] == pytest.approx(math.sqrt(4 * math.pi), rel=1e-9)
        generators = svs.wigner_generators(bandwidth - 1)
        assert len(generators[0]) == bandwidth
    del generators
    assert resident_megabytes() - before < 500.0


def test_so3_search_with_256_threads_gives_the_grid_of_one():
    """Each worker holds every degree's Wigner matrices: 256 workers took 5.6 GB at B = 128
    and, when the system refused a thread, the process aborted. The workers now share
    256 MB and a refused thread's rows run on the caller: the same maxima either way."""
    rng = np.random.default_rng(7)
    bandwidth = 24
    target = rng.normal(size=bandwidth**2)
    model = rng.normal(size=bandwidth**2)
    one = svs.so3_search(target, model, bandwidth, k=4, threads=1)
    many = svs.so3_search(target, model, bandwidth, k=4, threads=256)
    assert len(one) == len(many) == 4
    for (R1, c1), (R2, c2) in zip(one, many, strict=True):
        np.testing.assert_array_equal(R1, R2)
        assert c1 == c2


# Found by tests/python/api_harness.py (issue 34); each returned inf or NaN, or hung.
def test_pose_covariance_refuses_voxels_that_hung_or_gave_nan():
    cloud = svs.PointCloud(POINTS[:30], NORMALS[:30])
    for voxel in (1.8e15, math.inf):  # NaN before
        with pytest.raises(ValueError, match="voxel_size"):
            svs.pose_covariance(cloud, cloud, np.eye(4), voxel)
    # 5e-324 never returned: 1.25 times the smallest denormal is itself.
    covariance = svs.pose_covariance(cloud, cloud, np.eye(4), 5e-324)
    assert np.asarray(covariance).shape == (6, 6) and np.isfinite(covariance).all()


def test_scales_of_coordinates_past_1e154_are_finite():
    cloud = svs.PointCloud(POINTS * 1e200, NORMALS)
    size = svs.alignment_voxel_size(cloud, cloud)
    typical = 2 * np.median(np.linalg.norm(POINTS - np.median(POINTS, axis=0), axis=1))
    assert math.isfinite(size) and size == pytest.approx(1e200 * typical / 12, rel=0.5)
    assert math.isfinite(svs.view_scale(cloud, cloud).voxel_size)


def test_rotation_angle_stays_within_pi():
    axis = np.array([0.18881711923692265, -0.19839032737660414, 0.9617636786063786])
    R = svs.so3_exp(axis * np.pi)
    assert 0.0 <= svs.rotation_angle(R) <= math.pi  # was pi + 1 ulp


def test_so3_exp_of_an_overflowing_norm_is_refused():
    with pytest.raises(ValueError, match="norm exceeds the largest double"):
        svs.so3_exp([0.0, 1.7976931348623157e308, 1.7976931348623157e308])


def test_raw_correlations_of_huge_coefficients_are_refused():
    c = svs.egi_coefficients(OBJECT, 8) * 1e302
    with pytest.raises(ValueError, match="raw correlation"):
        svs.so3_correlation(c, c, np.eye(3), normalised=False)
    with pytest.raises(ValueError, match="raw correlation"):
        svs.rotation_cost(c, c, np.eye(3), normalised=False)


def test_raw_refinement_stops_at_a_relative_gradient():
    """Raw sums never met the absolute tolerance of 1e-6 and ran every iteration (24 s at
    B = 128); the tolerance is now relative to |C|'s bound, so a start 0.3 rad off converges
    near the right rotation in a few iterations."""
    bandwidth = 16
    R_true = svs.so3_exp([0.2, -0.1, 0.15])
    T_true = np.eye(4)
    T_true[:3, :3] = R_true
    target = svs.egi_coefficients(OBJECT.transformed(T_true), bandwidth)
    model = svs.egi_coefficients(OBJECT, bandwidth)
    result = svs.refine_rotation(target, model, np.eye(3), normalised=False)
    assert result.converged and result.iterations < 100
    assert math.degrees(svs.rotation_angle(R_true.T @ result.R)) < 3.0


def test_a_jacobian_that_overflows_is_refused():
    arm = svs.Kinematics(str(URDF), "base_link", "tool")
    q = np.zeros(arm.joint_count)
    q[2] = 1.7976931348623157e308  # the test arm's prismatic joint
    with pytest.raises(ValueError, match="overflows"):
        arm.jacobian(q)


def test_grid_spec_voxel_count_saturates():
    spec = svs.GridSpec(np.zeros(3), 0.01, [2**30] * 3)
    assert spec.voxel_count == 2**64 - 1  # wrapped to 0 before
