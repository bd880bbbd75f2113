"""Ours against the registration methods a user would pick instead, on identical cases.

Every method of ``benchmarks/peers.py`` (ours in both modes, Open3D point-to-plane ICP,
GICP, FPFH + RANSAC + ICP, FPFH + FGR + ICP, small_gicp GICP and point-to-plane ICP)
registers the same cases of ``benchmarks/cases.py`` (families ``full`` C-1, ``partial``
C-2, ``clutter`` C-3 and the real ``milk`` scene; initial rotations 10-180 degrees),
built once per case from its seed. The local methods start from the identity, i.e. the
cell's angle and offset away, like ours in paper mode. Success as in
``benchmarks/experiments.py``: rotation error < 5 degrees and error of the model
centroid < 10 mm, the minimum over the object's symmetries. Times are wall clock per
registration, downsampling, normals and features included, one thread for every
method unless ``--threads``. A subset is registered again to check determinism.

Writes ``benchmarks/results/peers.json``, ``docs/figures/peers_success.png``,
``docs/figures/peers_time.png`` and the tables between the ``peers`` markers of
``docs/benchmarks.md``. Usage::

    python benchmarks/peers_benchmark.py             # everything (about 25 min on 2 cores)
    python benchmarks/peers_benchmark.py --quick     # smoke run (about 1 min), writes nothing
    python benchmarks/peers_benchmark.py --report-only    # figures and tables from the JSON
    python benchmarks/peers_benchmark.py --sweep-local-distance   # the peers' ICP distance
    python benchmarks/peers_benchmark.py --methods ours,paper --replace-methods  # rerun ours

Needs the ``bench`` extra (open3d, small_gicp), pybullet (cases) and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before any OpenMP runtime loads

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cases as case_lib
import peers
import report as report_lib
from report import markdown, num, pct

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "peers.json"
SWEEP_RESULTS = ROOT / "benchmarks" / "results" / "peers_local_distance.json"
FIGURES = ROOT / "docs" / "figures"

FAMILIES = ("full", "partial", "clutter", "milk")
ANGLES = (10, 30, 60, 90, 120, 150, 180)
#: Cases per (family, angle) cell. The real milk scene is one scene under different
#: perturbations, and its registrations are the slowest (120 000 scene points): 10.
CASES_PER_CELL = {"full": 20, "partial": 20, "clutter": 20, "milk": 10}
DETERMINISM_CASES = 3  # per family, registered a second time by every method
RANDOM_METHODS = ("o3d_ransac", "o3d_fgr")  # also rerun with another seed
PEER_METHODS = tuple(m for m in peers.METHODS if m not in ("ours", "paper"))
LOCAL_PEERS = tuple(m for m in peers.LOCAL_METHODS if m != "paper")
SUCCESS_DEG, SUCCESS_M = case_lib.SUCCESS_DEG, case_lib.SUCCESS_M
VOXEL = 0.008  # metres: ours' default voxel, used by every method
QUICK = {"angles": (30, 120), "cases": 1, "determinism": 1}
SWEEP = {"angles": (10, 30, 60, 90), "cases": 3, "distances": (0.75, 1.0, 1.5, 2.5, 5, 10, 25)}
FAMILY_TITLES = {
    "full": "C-1 full model (sim)",
    "partial": "C-2 partial view (sim)",
    "clutter": "C-3 clutter (sim)",
    "milk": "C-3 milk scene (real)",
}


# --- Running ------------------------------------------------------------------------------


def progress(line: str) -> None:
    print(line, flush=True)


def pose_difference(case: case_lib.Case, A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(degrees, metres) between two estimates: rotation angle of A^-1 B and the
    distance between where they put the model centroid. The angle comes from the chord,
    |R_A - R_B| = 2 sqrt(2) sin(angle / 2), exact down to the last bits (the arccosine of
    the trace cannot resolve less than about 1e-6 degrees)."""
    center = np.append(case.model_center, 1.0)
    chord = float(np.linalg.norm(A[:3, :3] - B[:3, :3])) / (2.0 * math.sqrt(2.0))
    rotation = math.degrees(2.0 * math.asin(min(chord, 1.0)))
    return rotation, float(np.linalg.norm((A @ center - B @ center)[:3]))


def register(
    case: case_lib.Case, method: str, settings: peers.PeerSettings, seed: int | None = None
) -> peers.PeerResult:
    return peers.register(
        method,
        case.model_points,
        case.model_normals,
        case.scene_points,
        case.scene_normals,
        settings.voxel_size,
        np.eye(4),
        settings=settings,
        seed=case.seed if seed is None else seed,
        scene_viewpoint=case.viewpoint,
    )


def run(
    specs: list[case_lib.CaseSpec],
    determinism: set[str],
    settings: peers.PeerSettings,
    log,
    methods: tuple[str, ...] = peers.METHODS,
) -> tuple[list[dict], list[dict]]:
    """One record per (case, method); and for the cases in ``determinism``, one record
    per method comparing a second run (same seed; another seed for the random ones)."""
    records, reruns = [], []
    for n, spec in enumerate(specs, 1):
        case = case_lib.make_case(spec)
        line = []
        for method in methods:
            result = register(case, method, settings)
            rotation, translation = case_lib.pose_error(case, result.T_scene_model)
            success = rotation < SUCCESS_DEG and translation < SUCCESS_M
            records.append(
                {
                    "case_id": case.case_id,
                    "family": case.family,
                    "object": case.object,
                    "angle_deg": case.angle_deg,
                    "offset_m": case.offset,
                    "method": method,
                    "rotation_error_deg": rotation,
                    "translation_error_m": translation,
                    "success": success,
                    "time_s": result.seconds,
                    "cpu_s": result.cpu_seconds,
                }
            )
            verdict = "ok" if success else f"{rotation:5.1f}d"
            line.append(f"{method} {verdict} {result.cpu_seconds:.2f}s")
            if spec.case_id in determinism:
                reruns.append(rerun(case, method, settings, result.T_scene_model, success))
        log(f"[{n}/{len(specs)}] {spec.case_id:28s} " + " | ".join(line))
    return records, reruns


def rerun(
    case: case_lib.Case, method: str, settings: peers.PeerSettings, first: np.ndarray, ok: bool
) -> dict:
    again = register(case, method, settings).T_scene_model
    rotation, translation = pose_difference(case, first, again)
    record = {
        "case_id": case.case_id,
        "family": case.family,
        "method": method,
        "identical": bool(np.array_equal(first, again)),
        "rotation_difference_deg": rotation,
        "translation_difference_m": translation,
    }
    if method in RANDOM_METHODS:
        other = register(case, method, settings, seed=case.seed + 1).T_scene_model
        rotation, translation = pose_difference(case, first, other)
        r, t = case_lib.pose_error(case, other)
        record |= {
            "other_seed_rotation_difference_deg": rotation,
            "other_seed_translation_difference_m": translation,
            "other_seed_same_verdict": (r < SUCCESS_DEG and t < SUCCESS_M) == ok,
        }
    return record


def sweep_local_distance(specs: list[case_lib.CaseSpec], log) -> dict:
    """Success of the local peers at each correspondence distance (in voxels)."""
    counts: dict[str, dict[str, list[int]]] = {}
    for n, spec in enumerate(specs, 1):
        case = case_lib.make_case(spec)
        for d in SWEEP["distances"]:
            settings = peers.PeerSettings(
                voxel_size=VOXEL, plane_icp_distance_voxels=d, gicp_distance_voxels=d
            )
            for method in LOCAL_PEERS:
                T = register(case, method, settings).T_scene_model
                rotation, translation = case_lib.pose_error(case, T)
                cell = counts.setdefault(method, {}).setdefault(f"{d:g}", [0, 0])
                cell[0] += int(rotation < SUCCESS_DEG and translation < SUCCESS_M)
                cell[1] += 1
        log(f"[{n}/{len(specs)}] {spec.case_id}")
    return {
        "families": sorted({s.family for s in specs}, key=FAMILIES.index),
        "angles": SWEEP["angles"],
        "cases": len(specs),
        "distances_voxels": SWEEP["distances"],
        "success": counts,
    }


# --- Summaries ----------------------------------------------------------------------------


def statistics(group: list[dict]) -> dict:
    ok = [r for r in group if r["success"]]
    cpu = [r["cpu_s"] for r in group]
    return {
        "cases": len(group),
        "success_rate": len(ok) / len(group),
        "median_rotation_error_deg": report_lib.median(r["rotation_error_deg"] for r in ok),
        "median_translation_error_m": report_lib.median(r["translation_error_m"] for r in ok),
        "median_cpu_s": float(np.median(cpu)),
        "p10_cpu_s": float(np.percentile(cpu, 10)),
        "p90_cpu_s": float(np.percentile(cpu, 90)),
        "median_time_s": float(np.median([r["time_s"] for r in group])),
    }


def summarize(records: list[dict], *keys: str) -> list[dict]:
    """Statistics per (family, method, *keys), families and methods in table order."""
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault((r["family"], r["method"], *(r[k] for k in keys)), []).append(r)

    def rank(key: tuple) -> tuple:
        return (FAMILIES.index(key[0]), peers.METHODS.index(key[1]), *key[2:])

    return [
        dict(zip(("family", "method", *keys), key, strict=True)) | statistics(groups[key])
        for key in sorted(groups, key=rank)
    ]


def determinism_summary(reruns: list[dict]) -> list[dict]:
    rows = []
    for method in peers.METHODS:
        group = [r for r in reruns if r["method"] == method]
        if not group:
            continue
        row = {
            "method": method,
            "cases": len(group),
            "identical": sum(r["identical"] for r in group),
            "max_rotation_difference_deg": max(r["rotation_difference_deg"] for r in group),
            "max_translation_difference_m": max(r["translation_difference_m"] for r in group),
        }
        if method in RANDOM_METHODS:
            row |= {
                "other_seed_max_rotation_difference_deg": max(
                    r["other_seed_rotation_difference_deg"] for r in group
                ),
                "other_seed_max_translation_difference_m": max(
                    r["other_seed_translation_difference_m"] for r in group
                ),
                "other_seed_same_verdict": sum(r["other_seed_same_verdict"] for r in group),
            }
        rows.append(row)
    return rows


def targets(cells: list[dict], summary: list[dict]) -> list[dict]:
    """The issue's targets for ours, per family: (1) at least the best peer's success at
    every angle, (2) more than every local peer beyond 45 degrees, (3) a median time
    below FPFH + RANSAC's (CPU time, one thread each)."""
    rows = []
    for family in FAMILIES:
        cell = {
            (c["method"], c["angle_deg"]): c["success_rate"] for c in cells if c["family"] == family
        }
        present = {m for m, _ in cell}
        if not cell or not present >= set(peers.METHODS):
            continue  # the targets compare ours with every peer
        angles = sorted({a for _, a in cell})
        below_best, not_beating = [], []
        for a in angles:
            best = max(PEER_METHODS, key=lambda m, a=a: cell[(m, a)])
            if cell[("ours", a)] < cell[(best, a)]:
                below_best.append({"angle_deg": a, "ours": cell[("ours", a)], "peer": best,
                                   "peer_success": cell[(best, a)]})  # fmt: skip
            if a > 45:
                for m in LOCAL_PEERS:
                    if cell[("ours", a)] <= cell[(m, a)]:
                        not_beating.append({"angle_deg": a, "ours": cell[("ours", a)],
                                            "peer": m, "peer_success": cell[(m, a)]})  # fmt: skip
        time_of = {s["method"]: s["median_cpu_s"] for s in summary if s["family"] == family}
        rows.append(
            {
                "family": family,
                "below_best_peer": below_best,
                "not_beating_local": not_beating,
                "ours_median_time_s": time_of["ours"],
                "ransac_median_time_s": time_of["o3d_ransac"],
            }
        )
    return rows


# --- Report -------------------------------------------------------------------------------


def difference(degrees: float, metres: float) -> str:
    """A pose difference; exact zeros as 0, last-bit ones in scientific notation."""

    def one(x: float, unit: str) -> str:
        return "0" if x == 0.0 else (f"{x:.1e} {unit}" if x < 0.01 else f"{x:.2f} {unit}")

    return f"{one(degrees, 'deg')} / {one(1000.0 * metres, 'mm')}"


def success_table(cells: list[dict], summary: list[dict]) -> str:
    angles = sorted({c["angle_deg"] for c in cells})
    overall = {(s["family"], s["method"]): s for s in summary}
    rows = []
    for family, method in overall:
        by_angle = {
            c["angle_deg"]: c for c in cells if c["family"] == family and c["method"] == method
        }
        row = [FAMILY_TITLES[family], peers.TITLES[method]]
        row += [pct(by_angle[a]["success_rate"]) if a in by_angle else "-" for a in angles]
        rows.append([*row, pct(overall[(family, method)]["success_rate"])])
    return markdown(["family", "method", *[f"{a:g} deg" for a in angles], "all"], rows)


def summary_table(summary: list[dict]) -> str:
    header = ["family", "method", "cases", "success", "median rot. err.*"]
    header += ["median transl. err.*", "median CPU time", "90th pct. CPU", "median wall time"]
    rows = [
        [
            FAMILY_TITLES[s["family"]],
            peers.TITLES[s["method"]],
            str(s["cases"]),
            pct(s["success_rate"]),
            num(s["median_rotation_error_deg"], " deg"),
            num(s["median_translation_error_m"], " mm", 1000.0),
            num(s["median_cpu_s"], " s", digits=3),
            num(s["p90_cpu_s"], " s", digits=3),
            num(s["median_time_s"], " s", digits=3),
        ]
        for s in summary
    ]
    return markdown(header, rows)


def determinism_table(rows: list[dict]) -> str:
    header = ["method", "second run, same seed: identical", "max difference"]
    header += ["another seed: max difference", "another seed: same verdict"]
    body = []
    for r in rows:
        other = "-", "-"
        if "other_seed_same_verdict" in r:
            other = (
                difference(
                    r["other_seed_max_rotation_difference_deg"],
                    r["other_seed_max_translation_difference_m"],
                ),
                f"{r['other_seed_same_verdict']} of {r['cases']}",
            )
        body.append(
            [
                peers.TITLES[r["method"]],
                f"{r['identical']} of {r['cases']}",
                difference(r["max_rotation_difference_deg"], r["max_translation_difference_m"]),
                *other,
            ]
        )
    return markdown(header, body)


def targets_table(rows: list[dict]) -> str:
    def misses(items: list[dict]) -> str:
        if not items:
            return "yes"
        return "**no**: " + "; ".join(
            f"{i['angle_deg']:g} deg {pct(i['ours'])} vs {i['peer']} {pct(i['peer_success'])}"
            for i in items
        )

    body = [
        [
            FAMILY_TITLES[r["family"]],
            misses(r["below_best_peer"]),
            misses(r["not_beating_local"]),
            f"{'yes' if r['ours_median_time_s'] < r['ransac_median_time_s'] else '**no**'}: "
            f"{num(r['ours_median_time_s'], ' s', digits=3)} vs "
            f"{num(r['ransac_median_time_s'], ' s', digits=3)}",
        ]
        for r in rows
    ]
    header = ["family", "ours >= best peer at every angle", "ours > every local peer beyond 45 deg"]
    return markdown([*header, "ours faster than FPFH + RANSAC (median CPU time)"], body)


def sweep_table(sweep: dict) -> str:
    distances = [f"{d:g}" for d in sweep["distances_voxels"]]
    rows = [
        [peers.TITLES[m], *[f"{sweep['success'][m][d][0]}" for d in distances]]
        for m in LOCAL_PEERS
        if m in sweep["success"]
    ]
    per = sweep["success"][LOCAL_PEERS[0]][distances[0]][1]
    header = ["method", *[f"{d} v" for d in distances]]
    return (
        f"Successes out of {per} cases ({', '.join(sweep['families'])}; "
        f"{', '.join(f'{a:g}' for a in sweep['angles'])} deg; 3 per cell),\n"
        f"`python benchmarks/peers_benchmark.py --sweep-local-distance`:\n\n"
        + markdown(header, rows)
    )


STYLES = {
    "ours": dict(color="tab:blue", marker="s", lw=2.2),
    "paper": dict(color="tab:blue", marker="o", ls="--", lw=1.2),
    "o3d_icp": dict(color="tab:orange", marker="v", lw=1.2),
    "o3d_gicp": dict(color="tab:red", marker="^", lw=1.2),
    "o3d_ransac": dict(color="tab:green", marker="D", lw=1.6),
    "o3d_fgr": dict(color="tab:olive", marker="P", lw=1.2),
    "sg_gicp": dict(color="tab:purple", marker="<", lw=1.2, ls=":"),
    "sg_icp": dict(color="tab:brown", marker=">", lw=1.2, ls=":"),
}


def figures(results: dict) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIGURES.mkdir(parents=True, exist_ok=True)
    families = [f for f in FAMILIES if any(c["family"] == f for c in results["angle_cells"])]
    written = []

    fig, axes = report_lib.success_by_angle(
        plt,
        results["angle_cells"],
        families,
        FAMILY_TITLES,
        "method",
        {m: STYLES[m] | {"ms": 4} for m in peers.METHODS},
        peers.TITLES,
        (3.4, 3.4),
    )
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    written.append(report_lib.save_figure(fig, FIGURES / "peers_success.png"))

    fig, ax = plt.subplots(figsize=(9, 3.6))
    methods = [m for m in peers.METHODS if any(s["method"] == m for s in results["family_summary"])]
    width = 0.8 / len(methods)
    summary = {(s["family"], s["method"]): s for s in results["family_summary"]}
    for j, method in enumerate(methods):
        xs, med, low, high = [], [], [], []
        for i, family in enumerate(families):
            s = summary.get((family, method))
            if s is None:
                continue
            xs.append(i - 0.4 + (j + 0.5) * width)
            med.append(s["median_cpu_s"])
            low.append(s["median_cpu_s"] - s["p10_cpu_s"])
            high.append(s["p90_cpu_s"] - s["median_cpu_s"])
        ax.bar(
            xs, med, width, yerr=[low, high], capsize=2, label=peers.TITLES[method],
            color=STYLES[method]["color"], alpha=1.0 if method == "ours" else 0.75,
            hatch="//" if method == "paper" else None, edgecolor="white",
        )  # fmt: skip
    ax.set_yscale("log")
    ax.set_xticks(range(len(families)))
    ax.set_xticklabels([FAMILY_TITLES[f] for f in families], fontsize=9)
    ax.set_ylabel("CPU time per registration (s)")
    ax.set_title(
        "Median CPU time per registration, one thread (whiskers: 10th-90th percentile)", fontsize=9
    )
    ax.grid(alpha=0.3, axis="y", which="both")
    ax.legend(fontsize=7, ncol=2, loc="upper left")
    fig.tight_layout()
    written.append(report_lib.save_figure(fig, FIGURES / "peers_time.png"))
    return [str(p.relative_to(ROOT)) for p in written]


def report(results: dict) -> None:
    """Figures and the tables between the ``peers`` markers of docs/benchmarks.md."""
    written = figures(results)
    counts = ", ".join(f"{f} {n}" for f, n in results["cases_per_family"].items())
    versions = ", ".join(f"{k} {v}" for k, v in results["versions"].items())
    commands = results["commands"]
    runtime = f"{results['runtime_s'] / 60:.0f} min"
    if len(commands) == 1:
        head = f"Command: `{commands[0]}` ({runtime})."
    else:
        head = f"Commands ({runtime} in all):\n\n" + "\n".join(f"- `{c}`" for c in commands)
    lines = [
        f"Machine: {results['machine']}; {versions}; commit {results['commit']} (compiled "
        f"module sha256 {results.get('core_sha256', '?')}); {results['date']};",
        f"{results['threads']} thread(s) per method; load average "
        f"{results['load_average'][0]:.1f} at the start, {results['load_average'][1]:.1f} at "
        "the end (other jobs shared the cores).",
        f"Cases: {results['cases']} ({counts}), {len(results.get('methods', peers.METHODS))} "
        f"methods each, voxel {1000 * results['voxel_size']:.0f} mm for all.",
        "Figures: " + ", ".join(f"`{w}`" for w in written) + ".",
    ]
    for rerun in results.get("replaced", []):
        lines.append(
            "Rows of " + " and ".join(peers.TITLES[m] for m in rerun["methods"])
            + f" replaced by a rerun on {', '.join(rerun['families'])}: commit {rerun['commit']} "
            f"(compiled module sha256 {rerun['core_sha256']}); {rerun['date']}; load average "
            f"{rerun['load_average'][0]:.1f} at the start, {rerun['load_average'][1]:.1f} at "
            f"the end; {rerun['runtime_s'] / 60:.0f} min."
        )  # fmt: skip
    if results.get("skipped"):
        lines.append(f"Skipped: {results['skipped']}.")
    blocks = [
        head + "\n\n" + "\n".join(lines),
        "Success by initial rotation:\n\n"
        + success_table(results["angle_cells"], results["family_summary"]),
        "Errors of the successes (*) and time per registration (CPU time of the process,\n"
        "one thread, which other jobs on the cores do not inflate; wall time for reference):"
        "\n\n" + summary_table(results["family_summary"]),
        f"Determinism ({results['determinism_cases']} cases per family, each registered "
        "again in the same process):\n\n" + determinism_table(results["determinism"]),
        "The issue's targets for ours:\n\n" + targets_table(results["targets"]),
    ]
    if SWEEP_RESULTS.is_file():
        blocks.append(
            "Correspondence distance of the local peers (the pilot that set it):\n\n"
            + sweep_table(json.loads(SWEEP_RESULTS.read_text()))
        )
    if not report_lib.replace_block(report_lib.BENCHMARKS_DOC, "peers", "\n\n".join(blocks)):
        print(f"no peers markers in {report_lib.BENCHMARKS_DOC}: tables not written")


def command_line() -> str:
    return "python benchmarks/peers_benchmark.py" + "".join(f" {a}" for a in sys.argv[1:])


# --- Command line -------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--families", default=",".join(FAMILIES), help="subset of " + ", ".join(FAMILIES)
    )
    parser.add_argument("--angles", default=",".join(map(str, ANGLES)), help="degrees")
    report_lib.add_cases_per_cell(parser, CASES_PER_CELL)
    parser.add_argument("--determinism-cases", type=int, default=DETERMINISM_CASES)
    parser.add_argument("--threads", type=int, default=1, help="threads of every method")
    parser.add_argument(
        "--voxel", type=float, default=VOXEL, help="voxel size of every method, metres"
    )
    parser.add_argument(
        "--methods", default=",".join(peers.METHODS), help="subset of " + ", ".join(peers.METHODS)
    )
    parser.add_argument("--quick", action="store_true", help="smoke run; writes only with --output")
    parser.add_argument("--output", type=Path, default=None, help="JSON results")
    parser.add_argument(
        "--report-only", action="store_true", help="figures and tables from the JSON"
    )
    parser.add_argument(
        "--sweep-local-distance",
        action="store_true",
        help=f"success of the local peers by correspondence distance ({SWEEP_RESULTS.name})",
    )  # fmt: skip
    parser.add_argument(
        "--determinism-only",
        action="store_true",
        help="redo only the second runs of the determinism subset, into the results' JSON",
    )
    parser.add_argument(
        "--merge",
        type=Path,
        nargs="+",
        default=None,
        help="merge the JSONs of runs over different families into the results (or --output)",
    )
    parser.add_argument(
        "--replace-methods",
        action="store_true",
        help="put this run's records of --methods in place of theirs in the results (or "
        "--output), keeping every other method's (same cases and settings)",
    )
    args = parser.parse_args()

    if args.report_only:
        report(json.loads((args.output or RESULTS).read_text()))
        return
    if args.merge:
        finish(merge([json.loads(p.read_text()) for p in args.merge]), args.output or RESULTS)
        return
    families = [f for f in args.families.split(",") if f]
    unknown = set(families) - set(FAMILIES)
    if unknown:
        parser.error(f"unknown families {sorted(unknown)}; choose from {FAMILIES}")
    skipped = ""
    if "milk" in families and not (case_lib.data_dir() / "milk.pcd").is_file():
        families.remove("milk")
        skipped = f"milk (no milk.pcd in {case_lib.data_dir()}: set SPECTRAL_VS_DATA)"
        print(f"skipping {skipped}")
    peers.configure_threads(args.threads)
    versions = peers.import_peers()
    settings = peers.PeerSettings(voxel_size=args.voxel, threads=args.threads)
    methods = tuple(m for m in args.methods.split(",") if m)
    if set(methods) - set(peers.METHODS):
        parser.error(f"unknown methods {sorted(set(methods) - set(peers.METHODS))}")

    if args.sweep_local_distance:
        specs = case_lib.case_specs(families, SWEEP["angles"], SWEEP["cases"])
        sweep = sweep_local_distance(specs, progress)
        print(sweep_table(sweep))
        SWEEP_RESULTS.write_text(json.dumps(sweep, indent=1) + "\n")
        return

    angles = QUICK["angles"] if args.quick else tuple(float(a) for a in args.angles.split(","))
    n_det = QUICK["determinism"] if args.quick else args.determinism_cases
    specs = []
    for family in families:
        per_cell = args.cases_per_cell or CASES_PER_CELL[family]
        specs += case_lib.case_specs([family], angles, QUICK["cases"] if args.quick else per_cell)
    determinism = set()
    for family in families:
        spread = [angles[round(i * (len(angles) - 1) / max(n_det - 1, 1))] for i in range(n_det)]
        determinism |= {f"{family}-{case_lib.FAMILY_OBJECTS[family][0]}-a{a:g}-0" for a in spread}

    if args.determinism_only:
        output = args.output or RESULTS
        results = json.loads(output.read_text())
        chosen = [s for s in specs if s.case_id in determinism]
        _, reruns = run(chosen, determinism, settings, progress, methods)
        results["determinism_records"] = reruns
        results["commands"].append(command_line())
        finish(with_summaries(results), output)
        return

    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    records, reruns = run(specs, determinism, settings, progress, methods)
    results = {
        "commands": [command_line()],
        "date": time.strftime("%Y-%m-%d"),
        "machine": report_lib.machine(),
        "commit": report_lib.commit(),
        "core_sha256": report_lib.core_sha256(),
        "versions": versions,
        "threads": args.threads,
        "load_average": [load_start, os.getloadavg()[0]],
        "runtime_s": time.perf_counter() - start,
        "voxel_size": args.voxel,
        "methods": methods,
        "settings": vars(settings),
        "success": {"rotation_deg": SUCCESS_DEG, "translation_m": SUCCESS_M},
        "skipped": skipped,
        "cases": len(specs),
        "cases_per_family": {f: sum(s.family == f for s in specs) for f in families},
        "determinism_cases": n_det,
        "determinism_records": reruns,
        "records": records,
    }
    if args.replace_methods and not args.quick:
        output = args.output or RESULTS
        finish(replace_methods(json.loads(output.read_text()), results), output)
        return
    finish(with_summaries(results), args.output or (None if args.quick else RESULTS))


def with_summaries(results: dict) -> dict:
    """The results with their tables' data computed from the records."""
    cells = summarize(results["records"], "angle_deg")
    summary = summarize(results["records"])
    return results | {
        "angle_cells": cells,
        "family_summary": summary,
        "determinism": determinism_summary(results["determinism_records"]),
        "targets": targets(cells, summary),
    }


def merge(parts: list[dict]) -> dict:
    """One result from runs over different families (one run per family keeps each run
    short on a shared machine). The runs must share the build, versions and settings."""
    for key in ("core_sha256", "versions", "threads", "settings", "voxel_size"):
        if any(p[key] != parts[0][key] for p in parts):
            raise ValueError(f"the runs differ in {key}: not merged")
    families = [f for p in parts for f in p["cases_per_family"]]
    if len(set(families)) != len(families):
        raise ValueError(f"a family is in more than one run: {families}")
    merged = dict(parts[0])
    merged |= {
        "commands": [c for p in parts for c in p["commands"]] + [command_line()],
        "date": parts[-1]["date"],
        "load_average": [parts[0]["load_average"][0], parts[-1]["load_average"][1]],
        "runtime_s": sum(p["runtime_s"] for p in parts),
        "skipped": "; ".join(p["skipped"] for p in parts if p["skipped"]),
        "cases": sum(p["cases"] for p in parts),
        "cases_per_family": {f: n for p in parts for f, n in p["cases_per_family"].items()},
        "determinism_records": [r for p in parts for r in p["determinism_records"]],
        "records": [r for p in parts for r in p["records"]],
    }
    return with_summaries(merged)


def replace_methods(base: dict, new: dict) -> dict:
    """``base`` with the records of ``new``'s methods on ``new``'s families taken from
    ``new`` (a rerun of some methods, e.g. ours after a change), every other record kept.
    The runs must share the settings and, per family, the cases. ``replaced`` records
    each such rerun (methods, families, command, build, date, load, runtime) whose rows
    are still there: a rerun of the same methods and families supersedes the earlier."""
    for key in ("threads", "settings", "voxel_size", "success"):
        if base[key] != new[key]:
            raise ValueError(f"the runs differ in {key}: not merged")
    methods, families = set(new["methods"]), set(new["cases_per_family"])
    for family in families:
        old_cases = {r["case_id"] for r in base["records"] if r["family"] == family}
        new_cases = {r["case_id"] for r in new["records"] if r["family"] == family}
        if old_cases != new_cases:
            raise ValueError(f"the runs differ in the cases of {family}: not merged")

    def replaced(key: str) -> list[dict]:
        kept = [r for r in base[key] if r["method"] not in methods or r["family"] not in families]
        order = {c: i for i, c in enumerate(dict.fromkeys(r["case_id"] for r in base[key]))}
        return sorted(
            kept + new[key],
            key=lambda r: (order.get(r["case_id"], len(order)), peers.METHODS.index(r["method"])),
        )

    rerun = {"methods": new["methods"], "families": list(new["cases_per_family"])}
    rerun |= {"command": new["commands"][0]}
    rerun |= {k: new[k] for k in ("date", "commit", "core_sha256", "load_average", "runtime_s")}
    still_there = [
        r
        for r in base.get("replaced", [])
        if not (set(r["methods"]) <= methods and set(r["families"]) <= families)
    ]
    merged = dict(base)
    merged |= {
        "commands": list(dict.fromkeys(base["commands"] + new["commands"])),
        "runtime_s": base["runtime_s"] + new["runtime_s"],
        "replaced": [*still_there, rerun],
        "determinism_records": replaced("determinism_records"),
        "records": replaced("records"),
    }
    return with_summaries(merged)


def finish(results: dict, output: Path | None) -> None:
    """Print the tables; write the JSON to ``output``, and the figures and docs if it is
    the default results file."""
    print(f"\n{results['cases']} cases in {results['runtime_s'] / 60:.1f} min\n")
    print(success_table(results["angle_cells"], results["family_summary"]))
    print()
    print(summary_table(results["family_summary"]))
    print()
    print(determinism_table(results["determinism"]))
    print()
    print(targets_table(results["targets"]))
    if output is not None and report_lib.write_results(results, output, RESULTS, report):
        print(f"\nwrote {output.relative_to(ROOT)}, the figures and docs/benchmarks.md")


if __name__ == "__main__":
    main()
