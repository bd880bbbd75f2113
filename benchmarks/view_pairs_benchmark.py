"""Scene-to-scene registration on view pairs (issue 14): ours against Open3D and KISS-Matcher.

Direct visual servoing registers a reference view onto the current view of the same scene.
The pairs are those of :mod:`spectral_vs.data`: two disjoint, overlapping pixel windows of
a real Kinect scan (``table``: milk_cartoon_all_small_clorox.pcd, ``room``:
five_people.pcd) at 640 x 480 and downscaled to 320 x 240, the current moved by a seeded
random transform (5-60 degrees, up to 0.15 m), and views rendered in the simulation
(``sim``, ``sim-panda``: the iiwa's or the Panda's home view against views from the
``large`` start poses of the servo experiments that keep 30% of the reference in view). Every
method registers the reference (source) onto the current (target) and returns
``T_current_reference``, compared with the ground truth: rotation error (degrees) and
the distance of the translations (mm). Success: under 5 degrees and 10 mm.

Methods (one thread each, ``OMP_NUM_THREADS=1``, ``OMP_WAIT_POLICY=PASSIVE``):

* ``ours``: ``spectral_vs.align_views(reference, current, sensor_origin=...)`` with its
  defaults (every length derived from the views);
* ``o3d_icp``: Open3D point-to-plane ICP from the identity (``peers.register``);
* ``o3d_ransac``: Open3D FPFH + RANSAC + point-to-plane ICP (``peers.register``);
* ``kiss_icp``: KISS-Matcher + the same point-to-plane ICP
  (``peers.register_kiss_matcher``: the points scaled so that its voxel is 0.3, its
  translation scaled back).

The peers work at one voxel size per pair, the same for all, from the views' extent:
``v`` = 1% of the diagonal of the box spanning the 1st-99th percentiles of the
reference's coordinates, rounded to 1 mm, at least 5 mm (10-21 mm on the table, 56-97 mm
in the room, 10 mm in the simulation); their settings are those of
``benchmarks/peers.py`` (Open3D's tutorial, in units of ``v``). Each method's time is the
CPU time of the process (``time.process_time``) over its whole call, and the wall time.

Writes benchmarks/results/view_pairs.json and, for that default output, the table between
the ``view-pairs`` markers of docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import peers
import report as report_lib

from spectral_vs import data

RESULTS = report_lib.RESULTS / "view_pairs.json"
METHODS = ("ours", "o3d_icp", "o3d_ransac", "kiss_icp")
TITLES = {
    "ours": "ours (`align_views`)",
    "o3d_icp": "Open3D point-to-plane ICP (identity)",
    "o3d_ransac": "Open3D FPFH + RANSAC + ICP",
    "kiss_icp": "KISS-Matcher + ICP",
}
#: Families: name -> (scan or "sim", downscale).
FAMILIES = {
    "table-640": ("table", 1),
    "room-640": ("room", 1),
    "table-320": ("table", 2),
    "room-320": ("room", 2),
    "sim-320": ("sim", 1),
    "sim-panda-320": ("sim-panda", 1),
}
SUCCESS_DEG = 5.0
SUCCESS_M = 0.010
#: The voxel rule of the peers: this share of the extent's diagonal, at least MIN_VOXEL.
VOXEL_SHARE = 0.01
MIN_VOXEL = 0.005


def voxel_for(pair: data.ViewPair) -> float:
    """The peers' voxel for a pair, metres: :data:`VOXEL_SHARE` of the diagonal of the
    box of the reference's 1st-99th percentile coordinates, to 1 mm, >= :data:`MIN_VOXEL`."""
    low, high = np.percentile(pair.reference.points, [1.0, 99.0], axis=0)
    return max(MIN_VOXEL, round(VOXEL_SHARE * float(np.linalg.norm(high - low)), 3))


def errors(T: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """Rotation error (degrees) and translation error (mm) of ``T`` against ``T_true``."""
    rotation = data.rotation_angle_deg(T[:3, :3].T @ T_true[:3, :3])
    return rotation, 1000.0 * float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


def ours_available() -> bool:
    import spectral_vs as svs

    return hasattr(svs, "align_views")


def run_method(method: str, pair: data.ViewPair, arrays: dict, voxel: float, seed: int) -> dict:
    """One registration of ``pair``: its estimate, the times and what the method reports."""
    extra: dict[str, Any] = {}
    if method == "ours":
        import spectral_vs as svs

        start, cpu_start = time.perf_counter(), time.process_time()
        result = svs.align_views(pair.reference, pair.current, sensor_origin=pair.current_viewpoint)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        T = np.asarray(result.T_current_reference)
        support = result.support
        extra = {
            "converged": bool(result.converged),
            "score": float(support.score),
            "fitness": float(support.fitness),
            # The support's overlap (its share of checked points on a facing surface), not
            # the pair's: "overlap" is the pair's (the windows' shared share).
            "support_overlap": float(support.overlap),
            "voxel": float(result.scale.voxel_size),
        }
    else:
        (ref_xyz, ref_normals), (cur_xyz, cur_normals) = arrays["reference"], arrays["current"]
        if method == "kiss_icp":
            out, valid = peers.register_kiss_matcher(
                ref_xyz, ref_normals, cur_xyz, cur_normals, voxel
            )
            extra = {"valid": valid}
        else:
            out = peers.register(
                method, ref_xyz, ref_normals, cur_xyz, cur_normals, voxel, seed=seed
            )
        T, seconds, cpu = out.T_scene_model, out.seconds, out.cpu_seconds
    rotation_error, translation_error = errors(T, pair.T_current_reference)
    return {
        "rotation_error_deg": rotation_error,
        "translation_error_mm": translation_error,
        "success": rotation_error < SUCCESS_DEG and translation_error < 1000 * SUCCESS_M,
        "cpu_seconds": cpu,
        "seconds": seconds,
        **extra,
    }


def family_pairs(family: str, count: int, seed: int, data_folder: Path | None) -> list:
    scan, downscale = FAMILIES[family]
    if scan.startswith("sim"):
        from spectral_vs import sim

        robot = sim.robot_model("panda" if scan == "sim-panda" else "iiwa")
        params = sim.SimParams(robot=robot)
        return data.sim_view_pairs(count, start_set="large", seed=seed, params=params)
    return data.view_pairs(data.scan_path(scan, data_folder), count, seed=seed, downscale=downscale)


def run(families: list[str], methods: list[str], count: int, seed: int, data_folder) -> list:
    records = []
    for family in families:
        for index, pair in enumerate(family_pairs(family, count, seed, data_folder)):
            # Writeable copies (Open3D refuses the read-only views), made outside the timing.
            arrays = {
                name: (np.array(cloud.points), np.array(cloud.normals))
                for name, cloud in (("reference", pair.reference), ("current", pair.current))
            }
            voxel = voxel_for(pair)
            base = {
                "family": family,
                "pair": index,
                "image_size": list(pair.image_size),
                "overlap": pair.overlap,
                "rotation_deg": pair.rotation_deg,
                "translation_mm": 1000.0 * pair.translation,
                "reference_points": len(pair.reference),
                "current_points": len(pair.current),
                "voxel_size": voxel,
            }
            for method in methods:
                record = base | {"method": method}
                record |= run_method(method, pair, arrays, voxel, seed=1000 * seed + index)
                records.append(record)
                print(
                    f"{family} {index:2d} {method:10s} {pair.rotation_deg:5.1f} deg "
                    f"{record['rotation_error_deg']:7.2f} deg {record['translation_error_mm']:8.1f}"
                    f" mm {'ok  ' if record['success'] else 'FAIL'} {record['cpu_seconds']:.2f} s",
                    flush=True,
                )
    return records


def summarize(records: list[dict]) -> list[dict]:
    """Per (family, method): success rate, median errors, median and 90th percentile CPU
    and wall seconds."""
    out = []
    keys = dict.fromkeys((r["family"], r["method"]) for r in records)
    for family, method in keys:
        chosen = [r for r in records if r["family"] == family and r["method"] == method]
        column = {
            k: np.array([r[k] for r in chosen], dtype=float)
            for k in ("rotation_error_deg", "translation_error_mm", "cpu_seconds", "seconds")
        }
        out.append(
            {
                "family": family,
                "method": method,
                "pairs": len(chosen),
                "success_rate": float(np.mean([r["success"] for r in chosen])),
                "median_rotation_error_deg": float(np.median(column["rotation_error_deg"])),
                "median_translation_error_mm": float(np.median(column["translation_error_mm"])),
                "median_cpu_s": float(np.median(column["cpu_seconds"])),
                "p90_cpu_s": float(np.percentile(column["cpu_seconds"], 90)),
                "median_wall_s": float(np.median(column["seconds"])),
            }
        )
    return out


def pairs_table(records: list[dict]) -> str:
    """The pairs of each family: count, overlap, motion, points, voxel."""
    rows = []
    for family in dict.fromkeys(r["family"] for r in records):
        first: dict[int, dict] = {}
        for r in records:
            if r["family"] == family:
                first.setdefault(r["pair"], r)
        chosen = list(first.values())

        def span(key: str, scale: float = 1.0, digits: int = 0, rs: list = chosen) -> str:
            values = [scale * r[key] for r in rs if r[key] is not None]
            return f"{min(values):.{digits}f}-{max(values):.{digits}f}" if values else "-"

        size = "x".join(map(str, chosen[0]["image_size"]))
        rows.append(
            [family, size, str(len(chosen)), span("overlap", 100), span("rotation_deg"),
             span("translation_mm"), span("reference_points", 1e-3, 1), span("voxel_size", 1e3)]
        )  # fmt: skip
    header = ["family", "image", "pairs", "overlap (%)", "rotation (deg)", "translation (mm)",
              "reference points (k)", "voxel (mm)"]  # fmt: skip
    return report_lib.markdown(header, rows)


def summary_table(summary: list[dict]) -> str:
    rows = [
        [
            s["family"],
            TITLES[s["method"]],
            f"{s['pairs']}",
            report_lib.pct(s["success_rate"]),
            report_lib.num(s["median_rotation_error_deg"]),
            report_lib.num(s["median_translation_error_mm"], digits=1),
            report_lib.num(s["median_cpu_s"]),
            report_lib.num(s["p90_cpu_s"]),
            report_lib.num(s["median_wall_s"]),
        ]
        for s in summary
    ]
    header = ["family", "method", "pairs", "success", "median rot. error (deg)",
              "median transl. error (mm)", "median CPU (s)", "p90 CPU (s)",
              "median wall (s)"]  # fmt: skip
    return report_lib.markdown(header, rows)


def merged(before: dict, new: dict) -> dict:
    """``new``'s records with ``before``'s of the (family, method) cells ``new`` did not
    run; ``provenance`` says which run each method's records come from."""
    ran = {(r["family"], r["method"]) for r in new["records"]}
    kept = [r for r in before["records"] if (r["family"], r["method"]) not in ran]
    fields = ("command", "date", "commit", "core_sha256", "load_average")
    provenance = dict(before.get("provenance", {}))
    for method in {r["method"] for r in kept}:
        provenance.setdefault(method, {k: before.get(k) for k in fields})
    for method in new["methods"]:
        provenance[method] = {k: new[k] for k in fields}
    records = kept + new["records"]
    order = {family: i for i, family in enumerate(FAMILIES)}
    records.sort(
        key=lambda r: (order.get(r["family"], len(order)), METHODS.index(r["method"]), r["pair"])
    )
    return new | {
        "records": records,
        "summary": summarize(records),
        "methods": sorted({r["method"] for r in records}, key=list(METHODS).index),
        "provenance": provenance,
    }


def report(results: dict) -> None:
    """The tables between the ``view-pairs`` markers of docs/benchmarks.md."""
    versions = ", ".join(f"{k} {v}" for k, v in results["versions"].items())
    lines = [
        f"Command: `{results['command']}` ({results['runtime_s'] / 60:.0f} min).",
        "",
        f"Machine: {results['machine']}; {versions}; commit {results['commit']} (compiled "
        f"module sha256 {results['core_sha256']}); {results['date']}; one thread per method; "
        f"load average {results['load_average'][0]:.1f} at the start, "
        f"{results['load_average'][1]:.1f} at the end (other jobs shared the cores).",
    ]
    for method, run in results.get("provenance", {}).items():
        lines.append(
            f"- {TITLES[method]}: `{run['command']}`, commit {run['commit']} (module "
            f"{run['core_sha256']}), {run['date']}, load average {run['load_average'][0]:.1f}."
        )
    if results.get("skipped"):
        lines.append(f"Skipped: {results['skipped']}.")
    blocks = [
        "\n".join(lines),
        "The pairs (the 320 x 240 scan pairs are the 640 x 480 ones downscaled: same windows "
        "and transforms):\n\n" + pairs_table(results["records"]),
        "Success (rotation error < 5 degrees and translation error < 10 mm), median errors "
        "over all pairs (failures included), CPU time of the whole call (`time.process_time`) "
        "and wall time:\n\n" + summary_table(results["summary"]),
    ]
    if not report_lib.replace_block(report_lib.BENCHMARKS_DOC, "view-pairs", "\n\n".join(blocks)):
        print(f"no view-pairs markers in {report_lib.BENCHMARKS_DOC}: table not written")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=20, help="pairs per family (default 20)")
    parser.add_argument("--families", default=",".join(FAMILIES), help="comma-separated")
    parser.add_argument("--methods", default=",".join(METHODS), help="comma-separated")
    parser.add_argument("--seed", type=int, default=0, help="seed of the pairs")
    parser.add_argument(
        "--data",
        type=Path,
        default=None,
        help="folder of the scans (default: $SPECTRAL_VS_DATA, else ../shared/data)",
    )
    parser.add_argument("--output", type=Path, default=RESULTS, help="JSON results")
    parser.add_argument(
        "--report-only", action="store_true", help="redo the docs table from --output"
    )
    parser.add_argument(
        "--merge",
        action="store_true",
        help="keep --output's records of the methods not run (their commit and load stay "
        "in its provenance)",
    )
    args = parser.parse_args()
    if args.report_only:
        report(json.loads(args.output.read_text()))
        return
    families = args.families.split(",")
    methods = args.methods.split(",")
    for name, chosen, known in (("families", families, FAMILIES), ("methods", methods, METHODS)):
        unknown = sorted(set(chosen) - set(known))
        if unknown:
            parser.error(f"unknown {name} {unknown}: choose from {list(known)}")
    skipped = ""
    if "ours" in methods and not ours_available():
        skipped = "ours: spectral_vs.align_views does not exist yet in this build"
        print(f"skipping {skipped}", file=sys.stderr)
        methods.remove("ours")
    peers.configure_threads(1)
    versions = peers.import_peers()
    from importlib.metadata import version

    versions["kiss-matcher"] = version("kiss-matcher")
    import kiss_matcher  # type: ignore[import-untyped]  # noqa: F401  (before any timing)

    command = "python benchmarks/view_pairs_benchmark.py" + "".join(f" {a}" for a in sys.argv[1:])
    start, load_start = time.perf_counter(), os.getloadavg()[0]
    records = run(families, methods, args.pairs, args.seed, args.data)
    results = {
        "command": command,
        "date": time.strftime("%Y-%m-%d"),
        "machine": report_lib.machine(),
        "commit": report_lib.commit(),
        "core_sha256": report_lib.core_sha256(),
        "versions": versions,
        "load_average": [load_start, os.getloadavg()[0]],
        "runtime_s": time.perf_counter() - start,
        "methods": methods,
        "skipped": skipped,
        "success": {"rotation_deg": SUCCESS_DEG, "translation_m": SUCCESS_M},
        "voxel_rule": f"{VOXEL_SHARE} x diagonal of the reference's 1-99th percentile box, "
        f"to 1 mm, >= {MIN_VOXEL} m",
        "settings": {k: v for k, v in vars(peers.PeerSettings()).items() if k != "voxel_size"},
        "summary": summarize(records),
        "records": records,
    }  # fmt: skip
    if args.merge and args.output.is_file():
        results = merged(json.loads(args.output.read_text()), results)
    if report_lib.write_results(results, args.output, RESULTS, report):
        print(f"wrote {args.output} and the table in {report_lib.BENCHMARKS_DOC}")
    else:
        print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
