"""Time whole alignments and Algorithm 1's iterations on C-1 cases; write JSON and a docs table.

C-1 (full models of the experiments, docs/experiments.md) at 8 mm voxels and B = 16, one
thread and two: the median time per whole alignment (global search, hypotheses, windows
and polish included; the clouds come downsampled and with normals, as ``align`` does
first), and the median time per iteration of Algorithm 1 (``AlignIteration.seconds``).
The paper reports 8.7 ms per iteration on a 4-core i7. Usage::

    python benchmarks/alignment_benchmark.py [--cases 20]
"""

from __future__ import annotations

import argparse
import json
import time

import cases as case_lib
import numpy as np
from report import BENCHMARKS_DOC, RESULTS, machine, replace_block

import spectral_vs as svs

ANGLES = (10.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0)
MODES = {"paper": {"global_search": False}, "ours": {"global_search": True}}


def prepared(case: case_lib.Case, voxel: float) -> tuple[svs.PointCloud, svs.PointCloud]:
    """The clouds as ``align`` sees them after its own downsampling (timed apart)."""
    return (
        svs.voxel_downsample(case.model_cloud(), voxel / 2),
        svs.voxel_downsample(case.scene_cloud(), voxel / 2),
    )


def run(clouds, mode: str, threads: int) -> dict:
    model, scene = clouds
    start = time.perf_counter()
    result = svs.align(model, scene, downsample=False, threads=threads, **MODES[mode])
    seconds = time.perf_counter() - start
    return {
        "seconds": seconds,
        "iterations": result.iterations,
        "iteration_seconds": [step.seconds for step in result.history],
        "window_dims": list(map(int, result.window_dims)),
    }


def summary(rows: list[dict]) -> dict:
    per_iteration = [s for r in rows for s in r["iteration_seconds"]]
    return {
        "alignment_ms": 1000 * float(np.median([r["seconds"] for r in rows])),
        "alignment_p90_ms": 1000 * float(np.percentile([r["seconds"] for r in rows], 90)),
        "iteration_ms": 1000 * float(np.median(per_iteration)),
        "iterations": float(np.median([r["iterations"] for r in rows])),
        "window": int(np.median([r["window_dims"][0] for r in rows])),
    }


def table(results: dict) -> str:
    lines = [
        "| mode | threads | per iteration | iterations | per alignment | 90th pct. | window |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, s in results.items():
        mode, threads = key.split("/")
        lines.append(
            f"| {mode} | {threads} | {s['iteration_ms']:.2f} ms | {s['iterations']:.0f} "
            f"| {s['alignment_ms']:.1f} ms | {s['alignment_p90_ms']:.1f} ms "
            f"| {s['window']}^3 |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=21, help="C-1 cases (spread over angles)")
    parser.add_argument("--voxel-size", type=float, default=0.008)
    args = parser.parse_args()
    objects = case_lib.FAMILY_OBJECTS["full"]
    specs = [
        case_lib.CaseSpec("full", objects[i % len(objects)], ANGLES[i % len(ANGLES)], i)
        for i in range(args.cases)
    ]
    clouds = [prepared(case_lib.make_case(spec), args.voxel_size) for spec in specs]
    results, raw = {}, {}
    for mode in MODES:
        for threads in (1, 2):
            rows = [run(c, mode, threads) for c in clouds]
            key = f"{mode}/{threads}"
            raw[key] = rows
            results[key] = summary(rows)
    RESULTS.mkdir(exist_ok=True)
    record = {"machine": machine(), "cases": args.cases, "summary": results, "runs": raw}
    (RESULTS / "alignment.json").write_text(json.dumps(record, indent=2) + "\n")
    text = table(results)
    print(text)
    block = (
        f"Machine: {machine()}; {args.cases} C-1 cases, {1000 * args.voxel_size:g} mm voxels, "
        f"B = 16, medians.\n\n{text}"
    )
    replace_block(BENCHMARKS_DOC, "alignment-benchmark", block)


if __name__ == "__main__":
    main()
