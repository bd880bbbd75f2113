"""The cost of the alternatives stage: a default global align with and without it.

Per case, the CPU time of ``align(model, scene, threads=1)`` with the defaults and with
``max_alternatives=0`` (no search for the other poses a symmetric object allows), the
best of ``--repeats`` runs each, and whether both return the same pose (they do unless
the reselection returned an alternative instead: ``stop_reason == 'reselected'``).
Cases: the real milk scene and a few per benchmark family, in the camera frame as
benchmarks/experiments.py runs them (a timing only: nothing is chosen on the held-out
families here). Writes benchmarks/results/alternatives.json and
the table in docs/alignment.md. Usage (2 cores shared: one thread, niced)::

    OMP_NUM_THREADS=1 nice -n 10 python benchmarks/alternatives_benchmark.py [--cases 4]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cases as case_lib
import numpy as np
from report import RESULTS, commit, machine, replace_block

import spectral_vs as svs

ALIGNMENT_DOC = Path(__file__).resolve().parents[1] / "docs" / "alignment.md"
ANGLES = (30.0, 120.0, 60.0, 150.0)


def cpu_seconds(model, scene, repeats: int, **settings) -> tuple[float, svs.AlignResult]:
    best, result = float("inf"), None
    for _ in range(repeats):
        start = time.process_time()
        result = svs.align(model, scene, threads=1, **settings)
        best = min(best, time.process_time() - start)
    return best, result


# The reference case: the milk carton's model aligned onto a copy of itself turned
# by 60 degrees, at a 10 mm voxel with 8 hypotheses.
CARTON_SETTINGS = {"voxel_size": 0.010, "hypotheses": 8}


def carton_clouds() -> tuple[svs.PointCloud, svs.PointCloud]:
    model = case_lib.make_case(case_lib.CaseSpec("milk", "milk", 30.0, 0)).model_cloud()
    points, normals = np.asarray(model.points), np.asarray(model.normals)
    R = case_lib.axis_angle(np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0), np.radians(60.0))
    center = points.mean(axis=0)
    moved = (points - center) @ R.T + center + np.array([0.02, -0.01, 0.03])
    return model, svs.PointCloud(moved, normals @ R.T)


def run_case(spec: case_lib.CaseSpec | None, repeats: int) -> dict:
    if spec is None:
        (model, scene), settings = carton_clouds(), CARTON_SETTINGS
        case_id, family, name = "milk carton onto a turned copy", "carton (10 mm, 8 hyp.)", "milk"
    else:
        case = case_lib.in_camera_frame(case_lib.make_case(spec))
        model, scene, settings = case.model_cloud(), case.scene_cloud(), {}
        case_id, family, name = spec.case_id, spec.family, spec.object
    without, bare = cpu_seconds(model, scene, repeats, **settings, max_alternatives=0)
    default, full = cpu_seconds(model, scene, repeats, **settings)
    return {
        "case": case_id,
        "family": family,
        "object": name,
        "without_s": without,
        "default_s": default,
        "added": default / without - 1.0,
        "same_pose": bool(np.array_equal(bare.T_scene_model, full.T_scene_model)),
        "reselected": full.stop_reason == "reselected",
        "alternatives": len(full.alternatives),
    }


def table(rows: list[dict]) -> str:
    lines = [
        "| family | cases | without (median) | default (median) | added (median) "
        "| added (max) | ambiguous | same pose | reselected |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for family in dict.fromkeys(r["family"] for r in rows):
        f = [r for r in rows if r["family"] == family]
        lines.append(
            f"| {family} | {len(f)} | {1000 * np.median([r['without_s'] for r in f]):.0f} ms "
            f"| {1000 * np.median([r['default_s'] for r in f]):.0f} ms "
            f"| {100 * np.median([r['added'] for r in f]):.0f}% "
            f"| {100 * max(r['added'] for r in f):.0f}% "
            f"| {sum(r['alternatives'] > 0 for r in f)} "
            f"| {sum(r['same_pose'] for r in f)}/{len(f)} "
            f"| {sum(r.get('reselected', False) for r in f)} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=4, help="cases per synthetic family")
    parser.add_argument("--repeats", type=int, default=2, help="runs per setting (best kept)")
    parser.add_argument("--no-docs", action="store_true", help="do not rewrite the docs table")
    args = parser.parse_args()
    specs: list[case_lib.CaseSpec | None] = [None, case_lib.CaseSpec("milk", "milk", 30.0, 0)]
    for family in case_lib.FAMILIES:
        if family == "milk":
            continue
        objects = case_lib.FAMILY_OBJECTS[family]
        count = 1 if family == "bunny_scan" else args.cases
        specs += [
            case_lib.CaseSpec(family, objects[i % len(objects)], ANGLES[i % len(ANGLES)], i)
            for i in range(count)
        ]
    rows = []
    for spec in specs:
        rows.append(run_case(spec, args.repeats))
        r = rows[-1]
        print(
            f"{r['case']:<40} {1000 * r['without_s']:7.0f} ms {1000 * r['default_s']:7.0f} ms "
            f"+{100 * r['added']:4.0f}%  alternatives {r['alternatives']}  same {r['same_pose']}",
            flush=True,
        )
    text = table(rows)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    record = {"machine": machine(), "commit": commit(), "rows": rows}
    (RESULTS / "alternatives.json").write_text(json.dumps(record, indent=2) + "\n")
    if not args.no_docs:
        block = (
            f"Commit {commit()}; {machine()}; CPU time of `align(model, scene, threads=1)`, "
            f"best of {args.repeats}, scans in the camera frame "
            f"(`benchmarks/alternatives_benchmark.py`).\n\n{text}"
        )
        replace_block(ALIGNMENT_DOC, "alternatives-cost", block)


if __name__ == "__main__":
    main()
