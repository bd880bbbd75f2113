"""How the CPU time of one object registration grows (issue 36, point 5): with the number
of points, with the scene's extent at a fixed density (a table to a room), and with the
model's size; ours and each peer on the same inputs, one thread, CPU time of the whole
call (conversion, downsampling, normals, features and refinement included).

The scenes are synthetic and seeded: meshes of ``benchmarks/cases.py`` sampled
area-uniformly with their outward face normals (seen from all sides), the model the duck
(0.15 m) and the scene a square table top with the duck at a random pose among other
objects (mug, bunny, a random blob) at random places and yaws:

* ``points``: model and scene of N points each, N = 10^3 ... 10^7, on a 0.7 m table with
  three other objects;
* ``extent``: tables of 0.7, 1.4, 2.8 and 5.6 m with the same density of objects (three
  others per 0.49 m^2) and of points (20 000 per m^2 of surface, the model too): the scene
  grows with the area, from 15 k to 0.9 M points;
* ``model_size``: the duck scaled to 0.05, 0.1, 0.2 and 0.4 m on the 0.7 m table, 20 000
  points per m^2: the model grows with its area.

Every method gets the same voxel v, ours' rule for the model
(``spectral_vs.alignment_voxel_size``), and the clouds as generated, which ours
downsamples to v / 2 and the peers' calls are preceded by Open3D's downsampling to v / 2
(timed with them); the peers of
``benchmarks/peers.py`` (``register``: Open3D FPFH + RANSAC + ICP, FPFH + FGR + ICP,
point-to-plane ICP and GICP, small_gicp GICP; ``register_kiss_matcher``: KISS-Matcher +
ICP) with their settings there; ours also with every part of the scene searched
(``max_parts``, 8 by default). The local methods (Open3D ICP and GICP, small_gicp GICP,
ours in the paper's mode) start from the truth turned 10 degrees about a random axis and
moved 20 mm: their time, not their basin, is measured here. Success: within 5 degrees and
10 mm of the truth at the model's centroid.

Usage (about 20 minutes on one core)::

    OMP_NUM_THREADS=1 python benchmarks/cost_growth.py            # writes the results,
                                                                 # the table and the figure
    python benchmarks/cost_growth.py --report-only               # from the results file
    python benchmarks/cost_growth.py --sweeps points --methods ours o3d_ransac --seeds 1
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from pathlib import Path
from typing import Any

import cases as case_lib
import numpy as np
import peers
import report as report_lib

import spectral_vs as svs

RESULTS = report_lib.RESULTS / "cost_growth.json"
FIGURE = report_lib.ROOT / "docs" / "figures" / "cost_growth.png"
DOC_BLOCK = "cost-growth"

#: The sweeps and their values.
SWEEPS: dict[str, tuple[float, ...]] = {
    "points": (1e3, 1e4, 1e5, 1e6, 1e7),
    "extent": (0.7, 1.4, 2.8, 5.6),
    "model_size": (0.05, 0.1, 0.2, 0.4),
}
UNITS = {"points": "points per cloud", "extent": "table side (m)", "model_size": "model size (m)"}
#: Every method, ours first; ``ours_all_parts`` is ours searching every part of the scene
#: (``max_parts``), ``kiss`` KISS-Matcher + ICP.
METHODS = (
    "ours", "ours_all_parts", "paper", "o3d_ransac", "o3d_fgr", "kiss", "o3d_icp", "o3d_gicp",
    "sg_gicp",
)  # fmt: skip
LOCAL = ("paper", "o3d_icp", "o3d_gicp", "sg_gicp")
ALL_PARTS = 1_000_000
TITLES = {
    **peers.TITLES,
    "ours_all_parts": f"ours, every part (max_parts {ALL_PARTS:.0e})",
    "kiss": "KISS-Matcher + ICP",
}

TARGET = "duck"
CLUTTER = ("mug", "bunny", "blob004")
TABLE = 0.7  # side of the table of the points and model-size sweeps, m
DENSITY = 20_000.0  # points per m^2 of surface (extent and model-size sweeps)
OBJECTS_PER_AREA = 3 / 0.49  # other objects per m^2 of table
START_ANGLE_DEG, START_OFFSET = 10.0, 0.02  # the local methods' start off the truth


@functools.cache
def _mesh(name: str, size: float | None = None) -> case_lib.Mesh:
    """The mesh of an object of benchmarks/cases.py, scaled to ``size`` (read once)."""
    mesh = case_lib.load_mesh(name)
    if size is None:
        return mesh
    scale = size / case_lib.object_spec(name).size
    return case_lib._with_geometry(mesh.vertices * scale, mesh.faces, mesh.parts)


def _sample(mesh: case_lib.Mesh, count: int, rng: np.random.Generator) -> tuple:
    return case_lib.sample_surface(mesh, max(int(count), 10), rng)


def _standing(mesh: case_lib.Mesh, yaw: float, xy: np.ndarray) -> np.ndarray:
    """T_table_object: the object upright on the table (z = 0) at ``xy``, turned by ``yaw``."""
    T = case_lib.pose(case_lib.axis_angle(np.array([0.0, 0.0, 1.0]), yaw), np.zeros(3))
    T[:2, 3] = xy
    T[2, 3] = -mesh.vertices[:, 2].min()
    return T


def _places(count: int, side: float, radius: float, rng: np.random.Generator) -> np.ndarray:
    """``count`` places on a table of ``side`` m at least 2 ``radius`` apart (seeded tries)."""
    places: list[np.ndarray] = []
    half = side / 2 - radius
    for _ in range(200 * count):
        if len(places) == count:
            break
        p = rng.uniform(-half, half, size=2)
        if all(np.linalg.norm(p - q) >= 2 * radius for q in places):
            places.append(p)
    return np.array(places)


def make_scene(sweep: str, value: float, seed: int) -> dict[str, Any]:
    """The model, the scene, the truth and the voxel of one case."""
    rng = np.random.default_rng([seed, sum(map(ord, sweep)), int(value * 1000)])
    side = value if sweep == "extent" else TABLE
    target = _mesh(TARGET, value if sweep == "model_size" else None)
    clutter = [_mesh(name) for name in CLUTTER]
    others = max(3, round(OBJECTS_PER_AREA * side * side))
    meshes = [target] + [clutter[i % len(clutter)] for i in range(others)]
    radius = 0.5 * max(float(np.ptp(m.vertices[:, :2], axis=0).max()) for m in meshes)
    places = _places(len(meshes), side, radius, rng)
    meshes = meshes[: len(places)]
    areas = np.array([side * side] + [float(m.areas.sum()) for m in meshes])
    if sweep == "points":
        counts = np.maximum(10, np.round(value * areas / areas.sum())).astype(int)
        model_count = int(value)
    else:
        counts = np.maximum(10, np.round(DENSITY * areas)).astype(int)
        model_count = round(DENSITY * areas[1])
    points = [np.column_stack([rng.uniform(-side / 2, side / 2, (counts[0], 2)),
                               np.zeros(counts[0])])]  # fmt: skip
    normals = [np.tile([0.0, 0.0, 1.0], (counts[0], 1))]
    T_scene_model = np.eye(4)
    for i, (mesh, xy) in enumerate(zip(meshes, places, strict=True)):
        T = _standing(mesh, rng.uniform(0, 2 * math.pi), xy)
        if i == 0:
            T_scene_model = T
        p, n = _sample(mesh, counts[i + 1], rng)
        moved = case_lib.apply(T, p)
        above = moved[:, 2] > 1e-4  # not the face it stands on
        points.append(moved[above])
        normals.append((n @ T[:3, :3].T)[above])
    model_points, model_normals = _sample(target, model_count, rng)
    scene_points, scene_normals = np.vstack(points), np.vstack(normals)
    voxel = float(
        svs.alignment_voxel_size(
            svs.PointCloud(model_points, model_normals), svs.PointCloud(scene_points, scene_normals)
        )
    )
    return {
        "model": (model_points, model_normals),
        "scene": (scene_points, scene_normals),
        "T_true": T_scene_model,
        "center": model_points.mean(axis=0),
        "voxel": voxel,
        "start": _start(T_scene_model, rng),
    }


def _start(T_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    turn = case_lib.axis_angle(case_lib.random_unit(rng), math.radians(START_ANGLE_DEG))
    T = T_true.copy()
    T[:3, :3] = turn @ T[:3, :3]
    T[:3, 3] += START_OFFSET * case_lib.random_unit(rng)
    return T


def _downsampled(cloud: tuple[np.ndarray, np.ndarray], voxel: float) -> tuple:
    """Open3D's voxel downsampling (points and normals averaged per voxel)."""
    o3d = peers._open3d()
    pcd = peers._o3d_cloud(o3d, *cloud)
    down = pcd.voxel_down_sample(voxel)
    return np.asarray(down.points), np.asarray(down.normals)


def run_method(method: str, case: dict[str, Any]) -> tuple[np.ndarray, float, float, Any]:
    """(T_scene_model, CPU seconds, wall seconds, ours' verdict or None) of one method on
    one case. Every method
    gets the clouds as generated and works at the voxel v: ours downsamples them to v / 2
    itself, the peers' calls are preceded by Open3D's downsampling to v / 2, timed with
    them (their refinement runs on the clouds they are given, which at 10^7 points made
    RANSAC's final ICP alone take minutes)."""
    voxel = case["voxel"]
    cpu, wall = time.process_time(), time.perf_counter()
    model, scene = case["model"], case["scene"]
    if method not in ("ours", "ours_all_parts", "paper"):
        model, scene = _downsampled(model, voxel / 2), _downsampled(scene, voxel / 2)
    verdict = None
    if method.startswith("ours"):  # as peers.register("ours") runs it, keeping the verdict
        parts = {"max_parts": ALL_PARTS} if method == "ours_all_parts" else {}
        result = svs.align(
            svs.PointCloud(*model), svs.PointCloud(*scene), voxel_size=voxel, **parts
        )
        T, verdict = np.asarray(result.T_scene_model), (result.reliable, result.status)
    elif method == "kiss":
        T = np.asarray(peers.register_kiss_matcher(*model, *scene, voxel)[0].T_scene_model)
    else:
        T_init = case["start"] if method in LOCAL else None
        T = np.asarray(peers.register(method, *model, *scene, voxel=voxel, T_init=T_init)[0])
    return T, time.process_time() - cpu, time.perf_counter() - wall, verdict


def errors(case: dict[str, Any], T: np.ndarray) -> tuple[float, float]:
    center = np.append(case["center"], 1.0)
    moved = float(np.linalg.norm((T @ center - case["T_true"] @ center)[:3]))
    return case_lib.rotation_angle_deg(T[:3, :3].T @ case["T_true"][:3, :3]), moved


def run(args: argparse.Namespace) -> dict[str, Any]:
    peers.configure_threads(1)
    versions = peers.import_peers()
    records = []
    for sweep in args.sweeps:
        for value in SWEEPS[sweep]:
            for seed in range(args.seeds):
                case = make_scene(sweep, value, seed)
                for method in args.methods:  # interleaved: every method on the case in turn
                    T, cpu, wall, verdict = run_method(method, case)
                    rotation, translation = errors(case, T)
                    records.append({
                        "sweep": sweep, "value": value, "seed": seed, "method": method,
                        "model_points": len(case["model"][0]),
                        "scene_points": len(case["scene"][0]), "voxel_m": case["voxel"],
                        "cpu_s": cpu, "wall_s": wall, "rotation_deg": rotation,
                        "translation_m": translation,
                        "success": case_lib.succeeded(rotation, translation),
                        "reliable": None if verdict is None else bool(verdict[0]),
                        "status": None if verdict is None else str(verdict[1]),
                    })  # fmt: skip
                    print(json.dumps(report_lib.rounded(records[-1])), flush=True)
    return {
        "command": "OMP_NUM_THREADS=1 python benchmarks/cost_growth.py",
        "commit": report_lib.commit(),
        "build": report_lib.core_sha256(),
        "machine": report_lib.machine(),
        "date": time.strftime("%Y-%m-%d"),
        "versions": versions,
        "records": records,
    }


def cells(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Per sweep, value and method: the median CPU time, the points and the successes."""
    out = []
    keys = sorted({(r["sweep"], r["value"], r["method"]) for r in results["records"]},
                  key=lambda k: (list(SWEEPS).index(k[0]), k[1], METHODS.index(k[2])))  # fmt: skip
    for sweep, value, method in keys:
        chosen = [r for r in results["records"]
                  if (r["sweep"], r["value"], r["method"]) == (sweep, value, method)]  # fmt: skip
        out.append({
            "sweep": sweep, "value": value, "method": method,
            "cpu_s": float(np.median([r["cpu_s"] for r in chosen])),
            "scene_points": int(np.median([r["scene_points"] for r in chosen])),
            "model_points": int(np.median([r["model_points"] for r in chosen])),
            "voxel_m": float(np.median([r["voxel_m"] for r in chosen])),
            "successes": sum(r["success"] for r in chosen), "cases": len(chosen),
        })  # fmt: skip
    return out


def growth(cells_of: list[dict[str, Any]], sweep: str, method: str) -> float | None:
    """The slope of log CPU time against log of the sweep's value (1: linear), from its
    first to its last value."""
    chosen = [c for c in cells_of if c["sweep"] == sweep and c["method"] == method]
    if len(chosen) < 2:
        return None
    first, last = chosen[0], chosen[-1]
    return math.log(last["cpu_s"] / first["cpu_s"]) / math.log(last["value"] / first["value"])


def table(results: dict[str, Any]) -> str:
    all_cells = cells(results)
    methods = [m for m in METHODS if any(c["method"] == m for c in all_cells)]
    parts = [
        f"Commit `{results['commit']}` (build {results['build']}), {results['machine']}, "
        f"{results['date']}; one thread, CPU time of the whole call, the median of "
        f"{max(c['cases'] for c in all_cells)} seeded cases per cell (successes in "
        f"parentheses); `{results['command']}`."
    ]
    for sweep in SWEEPS:
        values = sorted({c["value"] for c in all_cells if c["sweep"] == sweep})
        if not values:
            continue
        header = [UNITS[sweep]] + [_value(sweep, v) for v in values] + ["growth exponent"]
        rows = []
        points = [next(c for c in all_cells if c["sweep"] == sweep and c["value"] == v)
                  for v in values]  # fmt: skip
        rows.append(["scene / model points (k)"]
                    + [f"{c['scene_points'] / 1e3:.0f} / {c['model_points'] / 1e3:.1f}"
                       for c in points] + [""])  # fmt: skip
        rows.append(["voxel (mm)"] + [f"{1e3 * c['voxel_m']:.1f}" for c in points] + [""])
        for method in methods:
            row = [TITLES[method]]
            for v in values:
                c = _cell(all_cells, sweep, v, method)
                row.append(
                    "-" if c is None else f"{c['cpu_s']:.3f} s ({c['successes']}/{c['cases']})"
                )
            slope = growth(all_cells, sweep, method)
            row.append("-" if slope is None else f"{slope:.2f}")
            rows.append(row)
        parts.append(f"**{sweep}**\n\n" + report_lib.markdown(header, rows))
    return "\n\n".join(parts)


def _cell(cells_of: list[dict[str, Any]], sweep: str, value: float, method: str) -> Any:
    return next(
        (c for c in cells_of if (c["sweep"], c["value"], c["method"]) == (sweep, value, method)),
        None,
    )


def _value(sweep: str, value: float) -> str:
    return f"10^{round(math.log10(value))}" if sweep == "points" else f"{value:g}"


def figure(results: dict[str, Any]) -> Path:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    all_cells = cells(results)
    fig, axes = plt.subplots(1, len(SWEEPS), figsize=(13.5, 4.2))
    for ax, sweep in zip(axes, SWEEPS, strict=True):
        for method in METHODS:
            chosen = [c for c in all_cells if c["sweep"] == sweep and c["method"] == method]
            if not chosen:
                continue
            style = {"lw": 2.5, "color": "k"} if method == "ours" else {"lw": 1.2}
            ax.loglog([c["value"] for c in chosen], [c["cpu_s"] for c in chosen], "o-",
                      label=TITLES[method], ms=3, **style)  # fmt: skip
        if sweep != "points":  # a few plain values, not powers of ten
            values = sorted({c["value"] for c in all_cells if c["sweep"] == sweep})
            ax.set_xticks(values, [f"{v:g}" for v in values])
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel(UNITS[sweep])
        ax.grid(alpha=0.3, which="both")
        ax.set_title(sweep.replace("_", " "))
    axes[0].set_ylabel("CPU time per call (s)")
    axes[-1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return report_lib.save_figure(fig, FIGURE)


def write_report(results: dict[str, Any]) -> None:
    figure(results)
    report_lib.publish(DOC_BLOCK, table(results))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sweeps", nargs="+", choices=list(SWEEPS), default=list(SWEEPS))
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument("--seeds", type=int, default=2, help="cases per cell")
    parser.add_argument("--output", type=Path, default=RESULTS)
    parser.add_argument("--report-only", action="store_true")
    args = parser.parse_args()
    if args.report_only:
        write_report(json.loads(args.output.read_text()))
        return
    results = run(args)
    report_lib.write_results(results, args.output, RESULTS, write_report)


if __name__ == "__main__":
    main()
