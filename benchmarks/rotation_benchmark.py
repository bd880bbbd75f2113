"""Rotation estimation (paper, section II-C): timings, EGI covariance error, basins.

Writes benchmarks/results/rotation.json and prints the markdown tables of
docs/rotation.md. Single-threaded. Three parts:

* timings: real Wigner matrices for all l < B, plus the correlation gradient (and
  Hessian), at B = 8, 16, 32, and the global search at B = 8, 16 (32 for reference).
  Timed inside C++ (``spectral_vs._core._rotation_timings``: median of many calls, no
  Python in the loop), and from Python for comparison.
* covariance: relative error |coefficients of R n - U(R) coefficients of n| / |U(R) F| of
  both EGI methods at B = 8, 16, 32, on object models.
* basin: success rate (rotation error < 5 degrees) of the local ascent from the identity
  (the paper's controller, with and without coarse-to-fine smoothing) and of the global
  search plus refinement, against the initial rotation angle.

The object models are the bunny and duck meshes of ``pybullet_data`` (when installed),
sampled twice independently (model and rotated target), with face normals; else the
PCL bunny scan in --data, with the same normals rotated.

Usage: python benchmarks/rotation_benchmark.py [--repeats 2000] [--trials 20] [--data DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import spectral_vs as svs
from spectral_vs import _core

ROOT = Path(__file__).resolve().parents[1]
ANGLES = [10, 20, 30, 45, 60, 75, 90, 120, 150, 180]
SMOOTHING = [0.5, 0.25, 0.0]  # coarse-to-fine heat-kernel widths, radians
SUCCESS_DEG = 5.0


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def hat(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def axis_angle(axis: np.ndarray, degrees: float) -> np.ndarray:
    k = hat(axis / np.linalg.norm(axis))
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0))))


def random_axis(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


# --- Object models ------------------------------------------------------------------


def load_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles (polygons fanned) of an OBJ file."""
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            vertices.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            faces += [[idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1)]
    return np.array(vertices), np.array(faces)


def mesh_normal_sampler(vertices: np.ndarray, faces: np.ndarray):
    """A function drawing face normals of area-uniform surface samples."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    keep = area > 0
    normals, p = cross[keep] / area[keep, None], area[keep] / area[keep].sum()

    def sample(rng: np.random.Generator, count: int) -> np.ndarray:
        return normals[rng.choice(len(normals), size=count, p=p)]

    return sample


def objects(data: Path):
    """name -> sampler(rng, count) of normals; independent draws for model and target."""
    found = {}
    try:
        import pybullet_data

        folder = Path(pybullet_data.getDataPath())
        for name in ("bunny", "duck"):
            found[name] = mesh_normal_sampler(*load_obj(folder / f"{name}.obj"))
    except ImportError:
        pass
    if not found:
        scan = svs.load_cloud(data / "bun0.pcd").normals
        found["bun0 scan"] = lambda rng, count: scan
    return found


# --- Timings ------------------------------------------------------------------------


def median_python(call, repeats: int) -> float:
    call()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def timings(repeats: int) -> list[dict]:
    return [timing_row(bandwidth, repeats) for bandwidth in (8, 16, 32)]


def timing_row(bandwidth: int, repeats: int) -> dict:
    cpp = _core._rotation_timings(bandwidth, repeats)
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(500, 3))
    model = svs.egi_coefficients(normals, bandwidth)
    R = axis_angle(random_axis(rng), 70.0)
    target = svs.egi_coefficients(normals @ R.T, bandwidth)
    correlation = svs.So3Correlation(target, model)
    return {
        "bandwidth": bandwidth,
        "cpp_wigner_ms": 1e3 * cpp["wigner"],
        "cpp_wigner_gradient_ms": 1e3 * cpp["wigner_and_gradient"],
        "cpp_wigner_gradient_hessian_ms": 1e3 * cpp["wigner_gradient_hessian"],
        "cpp_search_ms": 1e3 * cpp["search"],
        "python_wigner_ms": 1e3 * median_python(lambda: svs.wigner_real(R, bandwidth - 1), repeats),
        "python_evaluate_ms": 1e3 * median_python(lambda: correlation.evaluate(R), repeats),
        "python_search_ms": 1e3
        * median_python(lambda: svs.so3_search(target, model, bandwidth), max(5, repeats // 20)),
    }


# --- Covariance error of the EGI methods --------------------------------------------


def covariance(samplers, trials: int) -> list[dict]:
    rows = []
    for name, sample in samplers.items():
        rng = np.random.default_rng(2)
        normals = sample(rng, 4000)
        for bandwidth in (8, 16, 32):
            for method in ("projection", "histogram"):
                errors = []
                for _ in range(trials):
                    R = axis_angle(random_axis(rng), rng.uniform(10, 180))
                    F = svs.egi_coefficients(normals, bandwidth, method=method)
                    G = svs.egi_coefficients(normals @ R.T, bandwidth, method=method)
                    U = svs.wigner_real(R, bandwidth - 1)
                    expected = np.concatenate(
                        [U[ell] @ F[ell * ell : (ell + 1) ** 2] for ell in range(bandwidth)]
                    )
                    errors.append(np.linalg.norm(G - expected) / np.linalg.norm(expected))
                rows.append(
                    {
                        "object": name,
                        "bandwidth": bandwidth,
                        "method": method,
                        "mean_error": float(np.mean(errors)),
                        "max_error": float(np.max(errors)),
                    }
                )
    return rows


# --- Basins -------------------------------------------------------------------------


def ascent(target, model, bandwidth, newton: bool, smoothing: bool) -> np.ndarray:
    R = np.eye(3)
    for sigma in SMOOTHING if smoothing else [0.0]:
        t = svs.smooth_coefficients(target, bandwidth, sigma)
        m = svs.smooth_coefficients(model, bandwidth, sigma)
        R = svs.refine_rotation(t, m, R, newton=newton, max_iterations=300).R
    return R


def search(target, model, bandwidth) -> np.ndarray:
    refined = [
        svs.refine_rotation(target, model, R0)
        for R0, _ in svs.so3_search(target, model, bandwidth, k=8)
    ]
    return max(refined, key=lambda r: r.correlation).R


METHODS = {
    "ascent": lambda t, m, b: ascent(t, m, b, newton=False, smoothing=False),
    "ascent + smoothing": lambda t, m, b: ascent(t, m, b, newton=False, smoothing=True),
    "Newton": lambda t, m, b: ascent(t, m, b, newton=True, smoothing=False),
    "Newton + smoothing": lambda t, m, b: ascent(t, m, b, newton=True, smoothing=True),
    "search + refine": search,
}


def basins(samplers, trials: int) -> list[dict]:
    rows = []
    for name, sample in samplers.items():
        for bandwidth in (8, 16):
            rng = np.random.default_rng(3)
            for degrees in ANGLES:
                errors = {method: [] for method in METHODS}
                for _ in range(trials):
                    R = axis_angle(random_axis(rng), degrees)
                    model = svs.egi_coefficients(sample(rng, 4000), bandwidth)
                    target = svs.egi_coefficients(sample(rng, 4000) @ R.T, bandwidth)
                    for method, run in METHODS.items():
                        errors[method].append(angle_deg(run(target, model, bandwidth), R))
                for method, e in errors.items():
                    e = np.array(e)
                    ok = e < SUCCESS_DEG
                    rows.append(
                        {
                            "object": name,
                            "bandwidth": bandwidth,
                            "angle_deg": degrees,
                            "method": method,
                            "success": float(ok.mean()),
                            "median_error_deg_of_successes": float(np.median(e[ok]))
                            if ok.any()
                            else None,
                        }
                    )
    return rows


# --- Report -------------------------------------------------------------------------


def print_tables(result: dict) -> None:
    print("\n### Timings (ms, median, one thread)\n")
    print(
        "| B | U^l, l < B (C++) | U^l + gradient (C++) | + Hessian (C++) | FFTSO3 U^l | "
        "so3_search (C++) | wigner_real (Python) | evaluate (Python) | so3_search (Python) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    reference = {16: 0.17, 32: 1.3}
    for r in result["timings"]:
        ref = f"{reference[r['bandwidth']]:.2f}" if r["bandwidth"] in reference else "-"
        search_cpp, search_py = f"{r['cpp_search_ms']:.3f}", f"{r['python_search_ms']:.3f}"
        print(
            f"| {r['bandwidth']} | {r['cpp_wigner_ms']:.4f} | {r['cpp_wigner_gradient_ms']:.4f} | "
            f"{r['cpp_wigner_gradient_hessian_ms']:.4f} | {ref} | {search_cpp} | "
            f"{r['python_wigner_ms']:.4f} | {r['python_evaluate_ms']:.4f} | {search_py} |"
        )
    print("\n### EGI covariance error (relative, mean / max over random rotations)\n")
    print("| object | B | projection | histogram (paper) |")
    print("|---|---|---|---|")
    cov = result["covariance"]
    for obj in dict.fromkeys(r["object"] for r in cov):
        for b in (8, 16, 32):
            cell = {
                r["method"]: f"{r['mean_error']:.2g} / {r['max_error']:.2g}"
                for r in cov
                if r["object"] == obj and r["bandwidth"] == b
            }
            print(f"| {obj} | {b} | {cell['projection']} | {cell['histogram']} |")
    basin = result["basin"]
    for obj in dict.fromkeys(r["object"] for r in basin):
        for b in (8, 16):
            rows = [r for r in basin if r["object"] == obj and r["bandwidth"] == b]
            print(f"\n### Success rate (< {SUCCESS_DEG:g} deg), {obj}, B = {b}\n")
            print("| method | " + " | ".join(f"{a} deg" for a in ANGLES) + " |")
            print("|---|" + "---|" * len(ANGLES))
            for method in METHODS:
                cells = [
                    f"{100 * r['success']:.0f} %"
                    for a in ANGLES
                    for r in rows
                    if r["angle_deg"] == a and r["method"] == method
                ]
                print(f"| {method} | " + " | ".join(cells) + " |")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=2000, help="timed calls per figure")
    parser.add_argument("--trials", type=int, default=20, help="random axes per angle")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    parser.add_argument(
        "--output", type=Path, default=ROOT / "benchmarks" / "results" / "rotation.json"
    )
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    samplers = objects(args.data)
    started = time.time()
    result = {
        "command": "python benchmarks/rotation_benchmark.py " + " ".join(sys.argv[1:]),
        "machine": {
            "cpu": cpu_name(),
            "cores": os.cpu_count(),
            "system": platform.platform(),
            "python": platform.python_version(),
            "spectral_vs": svs.__version__,
        },
        "success_threshold_deg": SUCCESS_DEG,
        "smoothing_schedule_rad": SMOOTHING,
        "timings": timings(args.repeats),
        "covariance": covariance(samplers, trials=10),
        "basin": basins(samplers, args.trials),
    }
    result["seconds"] = time.time() - started
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2) + "\n")
    print_tables(result)
    print(f"\nwrote {args.output} in {result['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
