"""The paper's model-alignment experiments (section III-B, C-1 to C-3), reproduced and extended.

For every family of cases (``benchmarks/cases.py``) and every initial rotation angle, runs
both modes of ``spectral_vs.align``:

* ``paper``: the paper's controller, gradient ascent from the identity
  (``global_search=False``), so it starts ``angle`` degrees and the offset away;
* ``ours``: the default, a global SO(3) search and then the same controller.

Success: rotation error < 5 degrees and translation error of the model centroid < 10 mm,
the minimum over the object's symmetries. Writes ``benchmarks/results/experiments.json``,
the figures ``docs/figures/experiments_*.png`` and the tables between the markers of
``docs/experiments.md``. Usage::

    python benchmarks/experiments.py            # everything (about 25 min on 2 cores)
    python benchmarks/experiments.py --quick    # a smoke run (about 1 min), writes nothing
    python benchmarks/experiments.py --report-only   # figures and tables from the JSON
    python benchmarks/experiments.py --families full,partial --angles 30,90 --cases-per-cell 5

Needs pybullet (cases) and matplotlib (figures).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cases as case_lib
import report as report_lib
from report import markdown, num, pct

import spectral_vs as svs

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "experiments.json"
DOC = ROOT / "docs" / "experiments.md"
FIGURES = ROOT / "docs" / "figures"

ANGLES = (10, 30, 60, 90, 120, 150, 180)
OFFSETS = (0.0, 0.05, 0.10, 0.15, 0.20)  # translation sweep, metres, at OFFSET_ANGLE
OFFSET_ANGLE = 30.0
#: Cases per (family, angle) cell. Lower one family's count here if the aligner gets slow on
#: it (the real milk scene is the largest grid, 300 x 180 x 240 voxels of 8 mm).
CASES_PER_CELL = {"full": 20, "bunny_scan": 20, "partial": 20, "clutter": 20, "milk": 20}
SWEEP_CASES = 10  # cases per offset of the translation sweep
SWEEP_FAMILIES = ("full", "partial", "clutter")
MODES = {"paper": {"global_search": False}, "ours": {"global_search": True}}
SUCCESS_DEG, SUCCESS_M = case_lib.SUCCESS_DEG, case_lib.SUCCESS_M
CONVERGENCE_PLOT_CASES = 3  # per family: cases 0..2 at 30 degrees keep their history
QUICK = {"angles": (30, 120), "cases": 1, "offsets": (0.1,)}


# --- Running ------------------------------------------------------------------------------


def failure_kind(rotation_deg: float, translation_m: float) -> str:
    """How a case failed: 'ok', 'translation' (rotation right, centroid >= 10 mm off),
    'near' (rotation 5-20 degrees off), 'wrong' (20-150 degrees) or 'flip' (> 150)."""
    if rotation_deg < SUCCESS_DEG:
        return "ok" if translation_m < SUCCESS_M else "translation"
    if rotation_deg <= 20.0:
        return "near"
    return "wrong" if rotation_deg <= 150.0 else "flip"


def run_case(case: case_lib.Case, mode: str, keep_history: bool) -> dict:
    # The defaults: the scans come in their camera's frame (case_lib.in_camera_frame), from
    # which align() detects a single view itself, and the voxel is derived from the model.
    settings = dict(MODES[mode])
    start = time.perf_counter()
    result = svs.align(case.model_cloud(), case.scene_cloud(), threads=1, **settings)
    seconds = time.perf_counter() - start
    rotation, translation = case_lib.pose_error(case, result.T_scene_model)
    last = result.history[-1] if result.history else None
    record = {
        "error_axis_object": error_axis(case, result.T_scene_model),
        "mode": mode,
        "rotation_error_deg": rotation,
        "translation_error_m": translation,
        "success": rotation < SUCCESS_DEG and translation < SUCCESS_M,
        "kind": failure_kind(rotation, translation),
        "iterations": result.iterations,
        "converged": bool(result.converged),
        "fitness": result.fitness,
        "correlation": result.correlation,
        "hypothesis": result.hypothesis,
        "voxel_size_m": result.voxel_size,
        "single_view": bool(result.single_view),
        "time_s": seconds,
        "final_translation_cost": last.translation_cost if last else math.nan,
        "final_rotation_cost": last.rotation_cost if last else math.nan,
        "final_translation_step": last.translation_step if last else math.nan,
        "final_rotation_gradient": last.rotation_gradient if last else math.nan,
    }
    if keep_history:
        record["history"] = {
            key: [getattr(it, key) for it in result.history]
            for key in (
                "translation_cost",
                "rotation_cost",
                "translation_step",
                "rotation_gradient",
            )
        }
    return record


def error_axis(case: case_lib.Case, T: np.ndarray) -> list[float] | None:
    """Axis of the rotation error in the object's frame (+Z up for the meshes), or None
    for real scans; the sign is chosen with a non-negative Z."""
    if "T_scene_object" not in case.info or case.family not in ("full", "partial", "clutter"):
        return None
    A = np.linalg.inv(case.T_true) @ np.asarray(case.info["T_scene_object"])  # object -> model
    E = A[:3, :3].T @ T[:3, :3].T @ case.T_true[:3, :3] @ A[:3, :3]  # error, object frame
    axis = np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    if np.linalg.norm(axis) < 1e-9:  # no rotation, or a half turn: the axis from E + I
        w, v = np.linalg.eigh(0.5 * (E + E.T))
        axis = v[:, np.argmax(w)] if np.trace(E) < 0.0 else np.zeros(3)
    norm = np.linalg.norm(axis)
    if norm == 0.0:
        return None
    axis = axis / norm
    return (axis if axis[2] >= 0.0 else -axis).tolist()


TRUTH_FIELDS = ("rotation_error_deg", "translation_error_m", "success", "fitness", "correlation")


def drift_from_truth(case: case_lib.Case) -> dict:
    """The paper's controller started at the true pose: how far its fixed point is from the
    truth (an accuracy floor of the costs themselves, whatever the start)."""
    result = svs.align(
        case.model_cloud(),
        case.scene_cloud(),
        threads=1,
        global_search=False,
        initial_guess=case.T_true,
    )
    rotation, translation = case_lib.pose_error(case, result.T_scene_model)
    return {
        "case_id": case.case_id,
        "family": case.family,
        "object": case.object,
        "rotation_error_deg": rotation,
        "translation_error_m": translation,
        "success": rotation < SUCCESS_DEG and translation < SUCCESS_M,
        "iterations": result.iterations,
        "fitness": result.fitness,
        "correlation": result.correlation,
    }


def case_fields(case: case_lib.Case) -> dict:
    info = {
        k: v for k, v in case.info.items() if k not in ("T_world_camera", "poses", "T_scene_object")
    }
    return {
        "case_id": case.case_id,
        "family": case.family,
        "condition": case.condition,
        "object": case.object,
        "seed": case.seed,
        "angle_deg": case.angle_deg,
        "offset_m": case.offset,
        "model_points": len(case.model_points),
        "scene_points": len(case.scene_points),
        "symmetries": len(case.symmetries),
        "info": json.loads(json.dumps(info, default=str)),
    }


def run(specs: list[case_lib.CaseSpec], sweep: set[str], log) -> tuple[list[dict], list[dict]]:
    records, drift, drift_done = [], [], set()
    for n, spec in enumerate(specs, 1):
        start = time.perf_counter()
        case = case_lib.in_camera_frame(case_lib.make_case(spec))
        generation = time.perf_counter() - start
        keep = (
            spec.offset is None
            and spec.angle_deg == OFFSET_ANGLE
            and spec.index < CONVERGENCE_PLOT_CASES
        )
        fields = case_fields(case) | {"sweep": spec.case_id in sweep, "generation_s": generation}
        for mode in MODES:
            records.append(fields | run_case(case, mode, keep))
        truth = None
        ours = records[-1]
        if not ours["success"] and not fields["sweep"]:
            # Would the truth have won? Refine it with the same controller and compare the
            # fitness that ranks the global-search hypotheses.
            truth = drift_from_truth(case)
            ours["truth"] = {k: truth[k] for k in TRUTH_FIELDS}
        line = " ".join(
            f"{r['mode']} {r['rotation_error_deg']:6.1f} deg "
            f"{1000 * r['translation_error_m']:6.1f} mm {r['time_s']:5.2f} s"
            for r in records[-len(MODES) :]
        )
        log(f"[{n}/{len(specs)}] {spec.case_id:34s} {line}")
        # Drift from the truth: the first case of each (family, object), at 30 degrees.
        if (
            spec.offset is None
            and spec.angle_deg == OFFSET_ANGLE
            and (spec.family, spec.object) not in drift_done
        ):
            drift_done.add((spec.family, spec.object))
            drift.append(truth or drift_from_truth(case))
    return records, drift


# --- Summaries ----------------------------------------------------------------------------

KINDS = ("translation", "near", "wrong", "flip")


def median(values) -> float | None:
    values = [v for v in values if v is not None and not math.isnan(v)]
    return float(np.median(values)) if values else None


def mean_or_none(values) -> float | None:
    values = list(values)
    return float(np.mean(values)) if values else None


ORDER = {
    "family": case_lib.FAMILIES,
    "mode": tuple(MODES),
    "object": (*case_lib.OBJECTS, "bunny_scan", "milk"),
}


def group_by(records: list[dict], *keys: str) -> dict[tuple, list[dict]]:
    """Records grouped by the values of ``keys``, in the order families, modes and objects
    are listed (other keys by value)."""
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)

    def rank(item):
        return tuple(
            ORDER[k].index(v) if k in ORDER else v for k, v in zip(keys, item[0], strict=True)
        )

    return dict(sorted(groups.items(), key=rank))


def statistics(group: list[dict]) -> dict:
    """Success rate, medians of the successes' errors, iterations, time, failure kinds,
    and the share of rotation failures that are turns about the object's up (Z) axis."""
    ok = [r for r in group if r["success"]]
    axes = [
        r["error_axis_object"]
        for r in group
        if r["kind"] in ("near", "wrong", "flip") and r.get("error_axis_object")
    ]
    return {
        "rotation_failures_about_up_axis": (
            sum(abs(a[2]) > math.cos(math.radians(25.0)) for a in axes) / len(axes)
            if axes
            else None
        ),
        "cases": len(group),
        "success_rate": len(ok) / len(group),
        "median_rotation_error_deg": median(r["rotation_error_deg"] for r in ok),
        "median_translation_error_m": median(r["translation_error_m"] for r in ok),
        "median_iterations": median(r["iterations"] for r in group),
        "median_time_s": median(r["time_s"] for r in group),
        "p90_time_s": float(np.percentile([r["time_s"] for r in group], 90)),
        "converged_rate": sum(r["converged"] for r in group) / len(group),
        "kinds": {k: sum(r["kind"] == k for r in group) for k in KINDS},
    }


def summarize(records: list[dict], *keys: str) -> list[dict]:
    """Statistics per (family, mode, *keys)."""
    return [
        dict(zip(("family", "mode", *keys), key, strict=True)) | statistics(group)
        for key, group in group_by(records, "family", "mode", *keys).items()
    ]


def table_one(records: list[dict]) -> list[dict]:
    """The paper's Table I: average final costs J_t, J_r (C-1, C-2) and final gradients
    (C-3), plus the mean squared errors (all cases, and successes only)."""
    rows = []
    for (family, mode), group in group_by(records, "family", "mode").items():
        ok = [r for r in group if r["success"]]
        row = {"family": family, "mode": mode, "cases": len(group)}
        for key in ("translation_cost", "rotation_cost", "translation_step", "rotation_gradient"):
            row[f"mean_final_{key}"] = float(np.mean([r[f"final_{key}"] for r in group]))
        for name, subset in (("all", group), ("successes", ok)):
            row[f"mse_translation_{name}_m2"] = mean_or_none(
                r["translation_error_m"] ** 2 for r in subset
            )
            row[f"mse_rotation_{name}_rad2"] = mean_or_none(
                math.radians(r["rotation_error_deg"]) ** 2 for r in subset
            )
        rows.append(row)
    return rows


# --- Environment --------------------------------------------------------------------------


def machine() -> dict:
    return {
        "core_sha256": report_lib.core_sha256(),
        "cpu": report_lib.cpu_model(platform.processor() or "unknown CPU"),
        "cores": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "commit": report_lib.commit(),
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


# --- Report -------------------------------------------------------------------------------

FAMILY_TITLES = {
    "full": "C-1 full model (sim)",
    "bunny_scan": "C-1 bunny scan (real)",
    "partial": "C-2 partial view (sim)",
    "clutter": "C-3 clutter (sim)",
    "milk": "C-3 milk scene (real)",
}
#: The issue's targets for ours (global search) and the peer's figures (docs: NOTES).
TARGETS = {"full": 0.99, "partial": 0.90, "clutter": 0.80, "milk": 1.00}
EVERY_ANGLE = ("full", "milk")  # targets that hold at every angle, not on average
PEER_SUCCESS = {"full": "100%", "partial": "84%", "clutter": "71%", "milk": "100%"}
PEER_ERRORS = {"full": "0.1 deg / 0.1 mm", "partial": "0.9 deg / 1 mm"}


def sci(x: float | None, unit: str = "") -> str:
    # None as the JSON stores it, NaN as a fresh run holds it (no run of Algorithm 1).
    return "-" if x is None or math.isnan(x) else f"{x:.3g}{unit}"


def errors(c: dict) -> list[str]:
    """Median errors of the successes, iterations and time of a summary row."""
    return [
        num(c["median_rotation_error_deg"], " deg"),
        num(c["median_translation_error_m"], " mm", 1000.0),
        num(c["median_iterations"], digits=0),
        num(c["median_time_s"], " s"),
    ]


def success_table(cells: list[dict]) -> str:
    angles = sorted({c["angle_deg"] for c in cells})
    rows = []
    for (family, mode), group in group_by(cells, "family", "mode").items():
        by_angle = {c["angle_deg"]: c for c in group}
        total = sum(c["cases"] for c in group)
        ok = sum(c["success_rate"] * c["cases"] for c in group)
        values = [pct(by_angle[a]["success_rate"]) if a in by_angle else "-" for a in angles]
        rows.append([FAMILY_TITLES[family], mode, *values, f"{pct(ok / total)} of {total}"])
    return markdown(["family", "mode", *[f"{a:g} deg" for a in angles], "all"], rows)


def cell_table(cells: list[dict], key: str) -> str:
    header = ["family", "mode", "angle" if key == "angle_deg" else "offset", "cases", "success"]
    header += ["median rot. err.*", "median transl. err.*", "median iter.", "median time"]
    header += ["converged", "failures t/n/w/f"]
    rows = []
    for c in cells:
        value = f"{c[key]:g} deg" if key == "angle_deg" else f"{1000 * c[key]:.0f} mm"
        kinds = " / ".join(str(c["kinds"][k]) for k in KINDS)
        rows.append(
            [
                FAMILY_TITLES[c["family"]],
                c["mode"],
                value,
                str(c["cases"]),
                pct(c["success_rate"]),
                *errors(c),
                pct(c["converged_rate"]),
                kinds,
            ]
        )
    return markdown(header, rows)


def summary_table(rows: list[dict]) -> str:
    header = ["family", "mode", "cases", "success", "median rot. err.*", "median transl. err.*"]
    header += ["median iter.", "median time", "90th pct. time"]
    body = [
        [
            FAMILY_TITLES[r["family"]],
            r["mode"],
            str(r["cases"]),
            pct(r["success_rate"]),
            *errors(r),
            num(r["p90_time_s"], " s"),
        ]
        for r in rows
    ]
    return markdown(header, body)


def table_one_markdown(rows: list[dict]) -> str:
    header = ["family", "mode", "cases", "final J_t", "final J_r", "final transl. step"]
    header += ["final grad C", "MSE transl.", "MSE rot.", "MSE transl.*", "MSE rot.*"]
    body = [
        [
            FAMILY_TITLES[r["family"]],
            r["mode"],
            str(r["cases"]),
            sci(r["mean_final_translation_cost"]),
            sci(r["mean_final_rotation_cost"]),
            sci(r["mean_final_translation_step"], " vox"),
            sci(r["mean_final_rotation_gradient"]),
            sci(r["mse_translation_all_m2"], " m²"),
            sci(r["mse_rotation_all_rad2"], " rad²"),
            sci(r["mse_translation_successes_m2"], " m²"),
            sci(r["mse_rotation_successes_rad2"], " rad²"),
        ]
        for r in rows
    ]
    return markdown(header, body)


def objects_table(rows: list[dict]) -> str:
    families = list(dict.fromkeys(r["family"] for r in rows))
    names = list(dict.fromkeys(r["object"] for r in rows))
    body = []
    for name in names:
        spec = case_lib.OBJECTS.get(name)
        row = [name, spec.symmetry.note if spec else "none"]
        for family in families:
            got = {r["mode"]: r for r in rows if r["family"] == family and r["object"] == name}
            cell = " / ".join(pct(got[m]["success_rate"]) if m in got else "-" for m in MODES)
            spin = got["ours"].get("rotation_failures_about_up_axis") if "ours" in got else None
            row.append(cell if spin is None else f"{cell} (up {pct(spin)})")
        body.append(row)
    header = [
        "object",
        "symmetry counted",
        *[f"{FAMILY_TITLES[f]}: paper / ours" for f in families],
    ]
    return markdown(header, body)


def failures_table(cells: list[dict]) -> str:
    header = ["family", "mode", "cases", "success", "translation only", "near (5-20 deg)"]
    header += ["wrong (20-150 deg)", "flip (> 150 deg)", "not converged"]
    body = [
        [FAMILY_TITLES[c["family"]], c["mode"], str(c["cases"]), pct(c["success_rate"])]
        + [str(c["kinds"][k]) for k in KINDS]
        + [str(round(c["cases"] * (1 - c["converged_rate"])))]
        for c in cells
    ]
    return markdown(header, body)


def diagnosis(records: list[dict]) -> list[dict]:
    """Per family, ours' failures of the angle sweep against the truth refined by the same
    controller: does the controller keep the truth (still a success from there), and does
    the refined truth have a higher fitness, the score that ranks the global-search
    hypotheses, than the pose ours returned (then the search never offered it; else the
    fitness itself prefers the wrong pose)."""
    rows = []
    for (family,), group in group_by(records, "family").items():
        failed = [r for r in group if r["mode"] == "ours" and "truth" in r]
        if not failed:
            continue
        kept = [r for r in failed if r["truth"]["success"]]
        fitter = [r for r in failed if r["truth"]["fitness"] > r["fitness"]]
        rows.append(
            {
                "family": family,
                "failures": len(failed),
                "truth_kept": len(kept),
                "truth_fitter": len(fitter),
                "kept_and_fitter": sum(r["truth"]["fitness"] > r["fitness"] for r in kept),
                "median_fitness_ours": median(r["fitness"] for r in failed),
                "median_fitness_truth": median(r["truth"]["fitness"] for r in failed),
                "median_truth_drift_deg": median(r["truth"]["rotation_error_deg"] for r in failed),
            }
        )
    return rows


def diagnosis_table(rows: list[dict]) -> str:
    header = ["family", "ours' failures", "truth kept (refined truth still a success)"]
    header += ["refined truth fitter than ours' pose", "kept and fitter"]
    header += ["median fitness: ours / refined truth", "median drift of the truth"]
    body = [
        [
            FAMILY_TITLES[r["family"]],
            str(r["failures"]),
            str(r["truth_kept"]),
            str(r["truth_fitter"]),
            str(r["kept_and_fitter"]),
            f"{num(r['median_fitness_ours'])} / {num(r['median_fitness_truth'])}",
            num(r["median_truth_drift_deg"], " deg", digits=1),
        ]
        for r in rows
    ]
    return markdown(header, body)


def drift_table(rows: list[dict]) -> str:
    body = []
    for family in case_lib.FAMILIES:
        group = [r for r in rows if r["family"] == family]
        if not group:
            continue
        rot = [r["rotation_error_deg"] for r in group]
        tr = [r["translation_error_m"] for r in group]
        ok = sum(a < SUCCESS_DEG and b < SUCCESS_M for a, b in zip(rot, tr, strict=True))
        body.append(
            [
                FAMILY_TITLES[family],
                str(len(group)),
                num(float(np.median(rot)), " deg"),
                num(max(rot), " deg", digits=1),
                num(float(np.median(tr)), " mm", 1000.0),
                f"{ok} of {len(group)}",
            ]
        )
    header = ["family", "cases", "median rot. drift", "max rot. drift", "median transl. drift"]
    worst = sorted(rows, key=lambda r: -r["rotation_error_deg"])[:6]
    largest = ", ".join(
        f"{r['case_id']} {r['rotation_error_deg']:.1f} deg / "
        f"{1000 * r['translation_error_m']:.1f} mm"
        for r in worst
    )
    table = markdown([*header, "still a success"], body)
    return f"{table}\n\nLargest drifts: {largest}."


def targets_table(cells: list[dict], summary: list[dict]) -> str:
    body = []
    for family, target in TARGETS.items():
        at_angles = [c for c in cells if c["family"] == family and c["mode"] == "ours"]
        overall = [r for r in summary if r["family"] == family and r["mode"] == "ours"]
        if not at_angles or not overall:
            continue
        worst = min(at_angles, key=lambda c: c["success_rate"])
        s = overall[0]
        every = family in EVERY_ANGLE
        met = (worst if every else s)["success_rate"] >= target
        body.append(
            [
                FAMILY_TITLES[family],
                f">= {100 * target:.0f}%" + (" at every angle" if every else ""),
                f"{pct(worst['success_rate'])} at {worst['angle_deg']:g} deg",
                pct(s["success_rate"]),
                "yes" if met else "**no**",
                PEER_SUCCESS[family],
                f"{num(s['median_rotation_error_deg'], ' deg')} / "
                f"{num(s['median_translation_error_m'], ' mm', 1000.0)}",
                PEER_ERRORS.get(family, "-"),
            ]
        )
    header = ["family", "target (ours)", "ours, worst angle", "ours, all angles", "met"]
    header += ["peer success", "ours: median errors*", "peer: median errors*"]
    return markdown(header, body)


def replace_block(text: str, name: str, body: str) -> str:
    begin, end = f"<!-- experiments:{name}:begin -->", f"<!-- experiments:{name}:end -->"
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise ValueError(f"{DOC} has no markers {begin} ... {end}")
    return pattern.sub(lambda _: f"{begin}\n{body}\n{end}", text)


def figures(results: dict) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIGURES.mkdir(parents=True, exist_ok=True)
    written = []
    families = [
        f for f in case_lib.FAMILIES if any(c["family"] == f for c in results["angle_cells"])
    ]
    styles = {
        "paper": dict(color="tab:orange", marker="o"),
        "ours": dict(color="tab:blue", marker="s"),
    }

    # Success rate against the initial angle, one panel per family.
    fig, axes = report_lib.success_by_angle(
        plt,
        results["angle_cells"],
        families,
        FAMILY_TITLES,
        "mode",
        {mode: styles[mode] for mode in MODES},
        {mode: mode for mode in MODES},
        (3.2, 3.0),
    )
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    written.append(report_lib.save_figure(fig, FIGURES / "experiments_success_vs_angle.png"))

    # Success rate against the translation offset at 30 degrees.
    sweep = [f for f in families if any(c["family"] == f for c in results["offset_cells"])]
    if sweep:
        fig, axes = plt.subplots(
            1, len(sweep), figsize=(3.2 * len(sweep), 3.0), sharey=True, squeeze=False
        )
        for ax, family in zip(axes[0], sweep, strict=True):
            for mode in MODES:
                cells = [
                    c
                    for c in results["offset_cells"]
                    if c["family"] == family and c["mode"] == mode
                ]
                ax.plot(
                    [1000 * c["offset_m"] for c in cells],
                    [100 * c["success_rate"] for c in cells],
                    label=mode,
                    **styles[mode],
                )
            ax.set_title(f"{FAMILY_TITLES[family]}, {OFFSET_ANGLE:g} deg", fontsize=9)
            ax.set_xlabel("initial translation offset (mm)")
            ax.set_ylim(-5, 105)
            ax.grid(alpha=0.3)
        axes[0][0].set_ylabel("success (%)")
        axes[0][0].legend(fontsize=8)
        fig.tight_layout()
        written.append(report_lib.save_figure(fig, FIGURES / "experiments_success_vs_offset.png"))

    # Convergence (the paper's Fig. 3 and 5): costs and gradients per iteration.
    traced = [r for r in results["records"] if "history" in r]
    if traced:
        keys = [
            ("translation_cost", "J_t (voxel units)"),
            ("rotation_cost", "J_r"),
            ("translation_step", "translation step (voxels)"),
            ("rotation_gradient", "|grad C|"),
        ]
        rows = [f for f in families if any(r["family"] == f for r in traced)]
        fig, axes = plt.subplots(len(rows), len(keys), figsize=(12, 2.3 * len(rows)), squeeze=False)
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for i, family in enumerate(rows):
            group = [r for r in traced if r["family"] == family]
            ids = sorted({r["case_id"] for r in group})
            for j, (key, label) in enumerate(keys):
                ax = axes[i][j]
                for r in group:
                    values = np.asarray(r["history"][key], dtype=float)
                    if len(values) == 0:
                        continue
                    color = colors[ids.index(r["case_id"]) % len(colors)]
                    style = "-" if r["mode"] == "paper" else "--"
                    marker = "" if len(values) > 1 else "s"
                    tag = f"{r['object']} {r['mode']}{' ok' if r['success'] else ' fail'}"
                    ax.plot(
                        np.arange(1, len(values) + 1),
                        np.maximum(values, 1e-12),
                        style,
                        color=color,
                        marker=marker,
                        label=tag,
                        lw=1.2,
                    )
                ax.set_yscale("log")
                ax.grid(alpha=0.3)
                if i == 0:
                    ax.set_title(label, fontsize=9)
                if i == len(rows) - 1:
                    ax.set_xlabel("iteration")
                if j == 0:
                    ax.set_ylabel(FAMILY_TITLES[family], fontsize=8)
            axes[i][-1].legend(fontsize=6, loc="upper right")
        fig.suptitle(
            f"Convergence at {OFFSET_ANGLE:g} deg initial rotation: paper mode solid, ours dashed",
            fontsize=10,
        )
        fig.tight_layout()
        written.append(report_lib.save_figure(fig, FIGURES / "experiments_convergence.png", 100))

    # Errors of every case (log scale), the success box marked.
    fig, axes = plt.subplots(
        1, len(families), figsize=(3.2 * len(families), 3.0), sharey=True, squeeze=False
    )
    for ax, family in zip(axes[0], families, strict=True):
        for mode in MODES:
            group = [r for r in results["records"] if r["family"] == family and r["mode"] == mode]
            ax.scatter(
                [max(1000 * r["translation_error_m"], 0.01) for r in group],
                [max(r["rotation_error_deg"], 0.01) for r in group],
                s=8, alpha=0.5, label=mode, color=styles[mode]["color"],
            )  # fmt: skip
        ax.axvline(1000 * SUCCESS_M, color="k", lw=0.8, ls=":")
        ax.axhline(SUCCESS_DEG, color="k", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(FAMILY_TITLES[family], fontsize=9)
        ax.set_xlabel("translation error (mm)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("rotation error (deg)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    written.append(report_lib.save_figure(fig, FIGURES / "experiments_errors.png"))
    return [str(p.relative_to(ROOT)) for p in written]


def report(results: dict) -> None:
    """Figures and the tables between the markers of docs/experiments.md."""
    written = figures(results)
    m = results["machine"]
    counts = ", ".join(f"{f} {n}" for f, n in results["cases_per_family"].items())
    minutes = {k: results[k] / 60 for k in ("runtime_s", "align_time_s", "generation_time_s")}
    setup = (
        f"Command: `{results['command']}`: {results['cases']} cases ({counts}) x {len(MODES)} "
        f"modes in {minutes['runtime_s']:.1f} min, one process (alignment "
        f"{minutes['align_time_s']:.1f} min, case generation {minutes['generation_time_s']:.1f} "
        f"min).\nMachine: {m['cpu']}, {m['cores']} cores, {m['system']}, Python {m['python']}; "
        f"commit {m['commit']} (compiled module sha256 {m.get('core_sha256', '?')}); "
        f"{results['date']}; load average {m['load_average_at_start']:.1f} "
        f"at the start, {m['load_average']:.1f} at the end (other jobs share the cores). Figures: "
        + ", ".join(f"`{w}`" for w in written)
        + "."
    )
    blocks = {
        "setup": setup,
        "success": success_table(results["angle_cells"]),
        "summary": summary_table(results["family_summary"]),
        "targets": targets_table(results["angle_cells"], results["family_summary"]),
        "failures": failures_table(results["family_summary"]),
        "cells": cell_table(results["angle_cells"], "angle_deg"),
        "offsets": cell_table(results["offset_cells"], "offset_m"),
        "table1": table_one_markdown(results["table_one"]),
        "objects": objects_table(results["per_object"]),
        "drift": drift_table(results["drift"]),
        "diagnosis": diagnosis_table(results["diagnosis"]),
    }
    text = DOC.read_text()
    for name, body in blocks.items():
        text = replace_block(text, name, body)
    DOC.write_text(text)


# --- Command line -------------------------------------------------------------------------


def parse_list(text: str, kind):
    return tuple(kind(x) for x in text.split(",") if x.strip())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--families",
        default=",".join(case_lib.TUNING_FAMILIES),
        help="comma-separated subset of " + ", ".join(case_lib.FAMILIES),
    )
    parser.add_argument(
        "--angles", default=",".join(map(str, ANGLES)), help="initial rotation angles, degrees"
    )
    parser.add_argument(
        "--offsets",
        default=",".join(f"{o:g}" for o in OFFSETS),
        help=f"translation sweep offsets at {OFFSET_ANGLE:g} deg, metres ('' for none)",
    )
    report_lib.add_cases_per_cell(parser, CASES_PER_CELL, f"; {SWEEP_CASES} per offset")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: 2 angles, 1 case per cell, one offset; writes only with --output",
    )
    parser.add_argument(
        "--output",
        type=Path,
        default=None,
        help=f"JSON results (default {RESULTS.relative_to(ROOT)}, which also updates the "
        "figures and docs/experiments.md)",
    )
    parser.add_argument(
        "--ours-setting",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="an AlignParams setting of the 'ours' mode, e.g. icp_refinement=false "
        "(repeatable; use with --output to keep the default results)",
    )
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="redo the figures and tables from the JSON without running",
    )
    args = parser.parse_args()

    if args.report_only:
        results = json.loads((args.output or RESULTS).read_text())
        results["diagnosis"] = diagnosis([r for r in results["records"] if not r["sweep"]])
        report(results)
        return
    for setting in args.ours_setting:
        name, _, value = setting.partition("=")
        if not hasattr(svs.AlignParams(), name):
            parser.error(f"--ours-setting: AlignParams has no setting {name!r}")
        MODES["ours"][name] = json.loads(value)
    families = parse_list(args.families, str)
    unknown = set(families) - set(case_lib.FAMILIES)
    if unknown:
        parser.error(f"unknown families {sorted(unknown)}; choose from {case_lib.FAMILIES}")
    angles = QUICK["angles"] if args.quick else parse_list(args.angles, float)
    offsets = QUICK["offsets"] if args.quick else parse_list(args.offsets, float)
    per_cell = {
        f: (QUICK["cases"] if args.quick else args.cases_per_cell or CASES_PER_CELL[f])
        for f in families
    }
    sweep_cases = QUICK["cases"] if args.quick else args.cases_per_cell or SWEEP_CASES
    specs, sweep = [], set()
    for family in families:
        specs += case_lib.case_specs([family], angles, per_cell[family])
        if family in SWEEP_FAMILIES and offsets:
            extra = case_lib.case_specs(
                [family], (), sweep_cases, offsets=offsets, offset_angle=OFFSET_ANGLE
            )
            specs += extra
            sweep |= {s.case_id for s in extra}

    start = time.perf_counter()
    load_before = machine()["load_average"]
    records, drift = run(specs, sweep, lambda line: print(line, flush=True))
    runtime = time.perf_counter() - start
    angle_records = [r for r in records if not r["sweep"]]
    results = {
        "command": "python benchmarks/experiments.py" + "".join(f" {a}" for a in sys.argv[1:]),
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine() | {"load_average_at_start": load_before},
        "success": {
            "rotation_deg": SUCCESS_DEG,
            "translation_m": SUCCESS_M,
            "translation_of": "model centroid",
        },
        "cases": len(specs),
        "cases_per_family": {f: sum(s.family == f for s in specs) for f in families},
        "runtime_s": runtime,
        "align_time_s": float(sum(r["time_s"] for r in records)),
        "generation_time_s": float(sum(r["generation_s"] for r in records) / len(MODES)),
        "angle_cells": summarize(angle_records, "angle_deg"),
        "offset_cells": summarize([r for r in records if r["sweep"]], "offset_m"),
        "family_summary": summarize(angle_records),
        "table_one": table_one(angle_records),
        "per_object": summarize(angle_records, "object"),
        "drift": drift,
        "diagnosis": diagnosis(angle_records),
        "records": records,
    }
    print(f"\n{len(specs)} cases in {runtime / 60:.1f} min\n")
    print(success_table(results["angle_cells"]))
    print()
    print(summary_table(results["family_summary"]))
    output = args.output or (None if args.quick else RESULTS)
    if output is not None and report_lib.write_results(results, output, RESULTS, report):
        print(f"\nwrote {output.relative_to(ROOT)}, {DOC.relative_to(ROOT)} and the figures")


if __name__ == "__main__":
    main()
