"""Where the time of ``align`` goes, stage by stage, per family of model-to-scan cases.

Each case of ``benchmarks/cases.py`` (the tuning families and the held-out ones, at 30, 90
and 150 degrees) is aligned once with the defaults and one thread, the scan's sensor
declared where it has one, as a user calls it: ``svs.align(model, scene)``, whose Python
side downsamples both clouds first. The call's CPU time is split into that Python side
(the call's CPU time less ``AlignResult.timings.total``) and the C++ stages of
``AlignResult.timings``. Writes ``benchmarks/results/stage_profile.json`` and the table
between the ``stage_profile`` markers of docs/benchmarks.md::

    OMP_NUM_THREADS=1 python benchmarks/stage_profile.py [--cases-per-cell 3]

With ``--views``, the same for ``align_views`` (``ViewAlignResult.timings``) on view pairs
of the real scans (``spectral_vs.data.view_pairs``: the table and the room, 320 x 240 and
640 x 480) and rendered pairs of the simulated iiwa (``data.sim_view_pairs``, large
starts), each registered as a user calls it, with the current's sensor origin; written to
``benchmarks/results/view_stage_profile.json`` and the ``view_stage_profile`` block::

    OMP_NUM_THREADS=1 python benchmarks/stage_profile.py --views [--pairs 5]
"""

from __future__ import annotations

import argparse
import json
import time

import cases as case_lib
import numpy as np
import report as report_lib
from report import RESULTS, commit, machine

import spectral_vs as svs

ANGLES = (30.0, 90.0, 150.0)


def timed(call) -> dict:
    """A call's CPU time, split into its result's C++ stages (``timings``, in the order
    they run) and its Python side (the CPU time less their total), seconds."""
    start = time.process_time()
    result = call()
    cpu = time.process_time() - start
    stages = result.timings.as_dict()
    row = {"python": max(0.0, cpu - stages.pop("total"))} | stages
    return row | {"cpu": cpu, "reliable": bool(result.reliable)}


def profile(case: case_lib.Case) -> dict:
    """One alignment's CPU time, split by stage, seconds."""
    model, scene = case.model_cloud(), case.scene_cloud()
    sensor = {}
    if np.all(np.isfinite(case.viewpoint)):
        sensor = {"sensor_origin": case.viewpoint, "scene_view": "single_view"}
    return timed(lambda: svs.align(model, scene, threads=1, **sensor))


def profile_views(pair) -> dict:
    """One align_views call's CPU time, split by stage, seconds."""
    origin = pair.current_viewpoint
    return timed(lambda: svs.align_views(pair.reference, pair.current, sensor_origin=origin))


#: The view-pair families: (label, scan or None for rendered pairs, downscale).
VIEW_FAMILIES = (
    ("table-320", "table", 2),
    ("room-320", "room", 2),
    ("sim-320", None, 1),
    ("table-640", "table", 1),
    ("room-640", "room", 1),
)


def run_views(pairs: int) -> dict[str, list[dict]]:
    from spectral_vs import data
    from spectral_vs.data.scans import scan_path

    rows: dict[str, list[dict]] = {}
    for label, scan, downscale in VIEW_FAMILIES:
        if scan is None:
            family = data.sim_view_pairs(pairs, start_set="large", seed=0)
        else:
            family = data.view_pairs(scan_path(scan), pairs, downscale=downscale, seed=0)
        for i, pair in enumerate(family):
            row = profile_views(pair) | {"case": f"{label}-{i}"}
            rows.setdefault(label, []).append(row)
            print(f"{label}-{i:<10d} {1000 * row['cpu']:8.1f} ms", flush=True)
    return rows


def run(families: tuple[str, ...], cases_per_cell: int) -> dict[str, list[dict]]:
    rows: dict[str, list[dict]] = {}
    for family in families:
        for spec in case_lib.case_specs((family,), ANGLES, cases_per_cell):
            row = profile(case_lib.make_case(spec)) | {"case": spec.case_id}
            rows.setdefault(family, []).append(row)
            print(f"{spec.case_id:40s} {1000 * row['cpu']:8.1f} ms", flush=True)
    return rows


def table(rows: dict[str, list[dict]]) -> str:
    first = next(iter(rows.values()))[0]
    columns = [name for name in first if name not in ("cpu", "reliable", "case")]
    head = (
        "| family | cases | CPU per call, median (ms) | "
        + " | ".join(columns)
        + " |\n|---|---|---|"
        + "---|" * len(columns)
    )
    lines = [head]
    for family, family_rows in rows.items():
        cpu = np.array([r["cpu"] for r in family_rows])
        means = {c: float(np.mean([r[c] for r in family_rows])) for c in columns}
        total = sum(means.values())
        cells = [f"{1000 * means[c]:.1f} ({100 * means[c] / total:.0f}%)" for c in columns]
        label = (
            f"{family} ({case_lib.CONDITIONS[family]})" if family in case_lib.CONDITIONS else family
        )
        lines.append(
            f"| {label} | {len(family_rows)} | {1000 * float(np.median(cpu)):.1f} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def write_profile(rows: dict[str, list[dict]], command: str, what: str, name: str) -> None:
    """The stamped table: into benchmarks/results/<name>.json and the <name> block."""
    stamp = (
        f"Commit `{commit()}`, {machine()}, one thread, CPU time; `{command}`. Per stage: the "
        f"mean ms per call (its share of the call). `python`: the Python side of {what}."
    )
    (RESULTS / f"{name}.json").write_text(
        json.dumps({"stamp": stamp, "rows": rows}, indent=1) + "\n"
    )
    report_lib.publish(name, stamp + "\n\n" + table(rows))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases-per-cell", type=int, default=3, help="cases per family and angle")
    parser.add_argument("--families", nargs="+", default=list(case_lib.FAMILIES))
    parser.add_argument("--views", action="store_true", help="profile align_views instead")
    parser.add_argument("--pairs", type=int, default=5, help="view pairs per family (--views)")
    args = parser.parse_args()
    command = "OMP_NUM_THREADS=1 python benchmarks/stage_profile.py"
    if args.views:
        write_profile(
            run_views(args.pairs),
            f"{command} --views --pairs {args.pairs}",
            "`svs.align_views` (its checks of the inputs)",
            "view_stage_profile",
        )
    else:
        write_profile(
            run(tuple(args.families), args.cases_per_cell),
            f"{command} --cases-per-cell {args.cases_per_cell}",
            "`svs.align` (its downsampling of both clouds)",
            "stage_profile",
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
