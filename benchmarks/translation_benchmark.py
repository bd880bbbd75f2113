"""Time the translation step against the bare FFT of its grid; write JSON and a docs table.

Runs the C++ program ``translation_benchmark`` (built by ``make install`` into the build
directory) so that the step and the FFT baseline are timed the same way, without
Python in the loop. Usage::

    python benchmarks/translation_benchmark.py --build-dir build/cp311-cp311-linux_x86_64
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

from report import BENCHMARKS_DOC, RESULTS, machine, replace_block


def table(rows: list[dict]) -> str:
    lines = [
        "| voxel | grid (voxels) | bare FFT pair | step, binary grid | ratio "
        "| step, trilinear grid | ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        dims = " x ".join(map(str, r["dims"]))
        lines.append(
            f"| {1000 * r['voxel_size_m']:.0f} mm | {dims} | {r['bare_fft_ms']:.2f} ms "
            f"| {r['step_binary_ms']:.2f} ms | {r['ratio_binary']:.2f} "
            f"| {r['step_trilinear_ms']:.2f} ms | {r['ratio_trilinear']:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build-dir", type=Path, required=True)
    parser.add_argument("--runs", type=int, default=100, help="timed runs per case (median)")
    args = parser.parse_args()
    program = args.build_dir / "benchmarks" / "translation_benchmark"
    output = subprocess.run(
        [str(program), str(args.runs)], check=True, capture_output=True, text=True
    )
    rows = json.loads(output.stdout)
    results = {"machine": machine(), "runs": args.runs, "cases": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "translation.json").write_text(json.dumps(results, indent=2) + "\n")
    text = table(rows)
    print(text)
    block = f"Machine: {machine()}; median of {args.runs} runs.\n\n{text}"
    replace_block(BENCHMARKS_DOC, "translation-benchmark", block)


if __name__ == "__main__":
    main()
