"""Where the time of ``align`` goes, stage by stage, per family of model-to-scan cases.

Each case of ``benchmarks/cases.py`` (the tuning families and the held-out ones, at 30, 90
and 150 degrees) is aligned once with the defaults and one thread, the scan's sensor
declared where it has one, as a user calls it: ``svs.align(model, scene)``, whose Python
side downsamples both clouds first. The call's CPU time is split into that Python side
(the call's CPU time less ``AlignResult.timings.total``) and the C++ stages of
``AlignResult.timings``. Writes ``benchmarks/results/stage_profile.json`` and the table
between the ``stage_profile`` markers of docs/benchmarks.md::

    OMP_NUM_THREADS=1 python benchmarks/stage_profile.py [--cases-per-cell 3]
"""

from __future__ import annotations

import argparse
import json
import time

import cases as case_lib
import numpy as np
from report import BENCHMARKS_DOC, RESULTS, commit, machine, replace_block

import spectral_vs as svs

ANGLES = (30.0, 90.0, 150.0)


def profile(case: case_lib.Case) -> dict:
    """One alignment's CPU time, split by stage, seconds."""
    model, scene = case.model_cloud(), case.scene_cloud()
    sensor = {}
    if np.all(np.isfinite(case.viewpoint)):
        sensor = {"sensor_origin": case.viewpoint, "scene_view": "single_view"}
    start = time.process_time()
    result = svs.align(model, scene, threads=1, **sensor)
    cpu = time.process_time() - start
    # The C++ stages of AlignTimings, in the order align() runs them.
    stages = result.timings.as_dict()
    row = {"python": max(0.0, cpu - stages.pop("total"))} | stages
    row["cpu"] = cpu
    row["reliable"] = bool(result.reliable)
    return row


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
        label = f"{family} ({case_lib.CONDITIONS[family]})"
        lines.append(
            f"| {label} | {len(family_rows)} | {1000 * float(np.median(cpu)):.1f} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases-per-cell", type=int, default=3, help="cases per family and angle")
    parser.add_argument("--families", nargs="+", default=list(case_lib.FAMILIES))
    args = parser.parse_args()
    rows = run(tuple(args.families), args.cases_per_cell)
    stamp = (
        f"Commit `{commit()}`, {machine()}, one thread, CPU time; "
        f"`OMP_NUM_THREADS=1 python benchmarks/stage_profile.py "
        f"--cases-per-cell {args.cases_per_cell}`. Per stage: the mean ms per call (its share "
        "of the call). `python`: the Python side of `svs.align` (its downsampling of both "
        "clouds)."
    )
    (RESULTS / "stage_profile.json").write_text(
        json.dumps({"stamp": stamp, "rows": rows}, indent=1) + "\n"
    )
    text = stamp + "\n\n" + table(rows)
    print(text)
    if replace_block(BENCHMARKS_DOC, "stage_profile", text):
        print(f"wrote the table into {BENCHMARKS_DOC}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
