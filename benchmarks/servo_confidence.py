"""The servo's per-step confidence: its calibration and its validation (docs/trust.md, "The
servo's confidence").

Every step of a servo run that registers the reference (tracking, relocalizing or held on
an occluder) reports ``ServoRecord.score``, uncalibrated, and ``ServoRecord.confidence``,
the probability that the step's estimate ``T_current_desired`` is right: within 5 degrees
and 10 mm of the true pose of the desired camera in the frame's camera, the translation at
the reference's centroid (as for ``align_views``). This script fits the map from score to
confidence (an isotonic regression, as benchmarks/verdict_benchmark.py fits the
registrations') on the calibration runs and measures it on the validation runs:

- calibration: ``python benchmarks/servo_scenarios.py --out servo_calibration --robots iiwa
  --seeds 0,1 --starts 5 --controllers spectral`` (the iiwa's tuning seeds, every
  scenario, moderate and large starts);
- validation: the scenario benchmark's own runs, ``python benchmarks/servo_scenarios.py
  --controllers spectral`` (seeds 201-203, both arms; no map was fitted on them, and the
  Panda is held out of every servo setting).

Both write their per-step records under ``benchmarks/results/servo_steps``. Steps of the
latency scenarios are left out: their frame was captured one or two periods before the
pose the record carries, so the truth of the frame is not known here. Usage::

    python benchmarks/servo_confidence.py            # fit, validate, write the doc block
    python benchmarks/servo_confidence.py --no-doc   # print only
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import report as report_lib
from report import auc, markdown, pct
from verdict_benchmark import (
    _f,
    calibrated,
    expected_calibration_error,
    fit_calibration,
    reliability_panel,
)

import spectral_vs as svs

ROOT = Path(__file__).resolve().parents[1]
STEPS = ROOT / "benchmarks" / "results" / "servo_steps"
#: The calibration map of each kind of step: the estimate is the registration's, or the
#: last one carried along the odometry (ServoRecord.carried).
KINDS = ("servo", "servo_carried")
CALIBRATION_RUNS = STEPS / "servo_calibration"
VALIDATION_RUNS = STEPS / "servo_scenarios"
DOC = ROOT / "docs" / "trust.md"
FIGURE = ROOT / "docs" / "figures" / "servo_confidence_reliability.png"
MARKER = "servo-confidence"
RIGHT_MM, RIGHT_DEG = 10.0, 5.0
#: Scenarios whose frames are older than the pose their records carry.
LATE = ("latency_1", "latency_2")


def read_steps(folder: Path, seeds: set[int] | None = None) -> dict[str, np.ndarray]:
    """Every step with a score of the run files in ``folder`` (seeds in ``seeds`` when given,
    the latency scenarios left out): score, confidence, moved, carried, right, and the
    run's robot."""
    names = ("score", "confidence", "moved", "carried", "right", "robot")
    columns: dict[str, list] = {k: [] for k in names}
    commits = set()
    for path in sorted(folder.glob("*.json")):
        data = json.loads(path.read_text())
        if data["scenario"] in LATE or (seeds is not None and data["seed"] not in seeds):
            continue
        commits.add(data["commit"])
        for run in data["records"]:
            for i, score in enumerate(run["score"]):
                if score is None:
                    continue
                columns["score"].append(score)
                columns["confidence"].append(run["confidence"][i])
                columns["moved"].append(run["moved"][i])
                columns["carried"].append(run["carried"][i])
                columns["right"].append(run["mm"][i] <= RIGHT_MM and run["deg"][i] <= RIGHT_DEG)
                columns["robot"].append(data["robot"])
    kinds = {"score": float, "confidence": float, "moved": bool, "carried": bool}
    kinds |= {"right": bool, "robot": str}
    out = {k: np.array(v, dtype=kinds[k]) for k, v in columns.items()}
    out["commits"] = np.array(sorted(commits))
    return out


def metrics(conf: np.ndarray, right: np.ndarray, moved: np.ndarray) -> dict:
    """The figures of one set of steps at confidence ``conf``."""
    confident = conf >= svs.RELIABLE_CONFIDENCE
    return {
        "steps": len(conf),
        "right": int(right.sum()),
        "auc": auc(conf, right),
        "ece": expected_calibration_error(conf, right),
        "moved": int(moved.sum()),
        "wrong_moved": int((moved & ~right).sum()),
        "moved_confident": float(confident[moved].mean()) if moved.any() else None,
        "wrong_confident": float((~right[confident]).mean()) if confident.any() else None,
        "right_confident": float(confident[right].mean()) if right.any() else None,
    }


def table(rows: list[tuple[str, dict]]) -> str:
    header = [
        "steps",
        "count (right)",
        "AUC",
        "ECE (<= 0.05)",
        "wrong among confidence >= 0.9",
        "right with confidence >= 0.9",
        "moved (wrong)",
        "moved with confidence >= 0.9",
    ]
    body = [
        [
            name,
            f"{m['steps']} ({m['right']})",
            _f(m["auc"]),
            _f(m["ece"]),
            "-" if m["wrong_confident"] is None else f"{100 * m['wrong_confident']:.2f}%",
            pct(m["right_confident"]),
            f"{m['moved']} ({m['wrong_moved']})",
            pct(m["moved_confident"]),
        ]
        for name, m in rows
    ]
    return markdown(header, body)


def plot(conf: np.ndarray, right: np.ndarray, path: Path) -> None:
    """Reliability diagram of the validation steps: share right per confidence bin."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    reliability_panel(ax, conf, right, f"servo steps, validation ({len(conf)} steps)")
    fig.tight_layout()
    report_lib.save_figure(fig, path)


def fit_maps(steps: dict) -> dict[str, np.ndarray]:
    """The knots of each kind's map, fitted on ``steps``."""
    return {
        kind: fit_calibration(steps["score"][chosen], steps["right"][chosen])
        for kind, chosen in zip(KINDS, (~steps["carried"], steps["carried"]), strict=True)
    }


def with_maps(steps: dict, maps: dict[str, np.ndarray]) -> np.ndarray:
    """The confidence of each step by ``maps`` (its kind's map applied to its score)."""
    out = calibrated(steps["score"], maps["servo"])
    carried = steps["carried"]
    out[carried] = calibrated(steps["score"][carried], maps["servo_carried"])
    return out


def figures(fit: dict, val: dict, maps: dict[str, np.ndarray]) -> list[tuple[str, dict]]:
    """The rows of the table: the calibration by kind and whole, the validation per arm and
    whole. The validation reads the maps fitted here applied to each step's score: what
    the library returns with these knots (tests/python/test_servo.py checks that a record's
    confidence is its score through its kind's map), whatever commit ran the steps."""
    fitted = with_maps(fit, maps)
    rows = []
    for kind, sel in zip(KINDS, (~fit["carried"], fit["carried"]), strict=True):
        rows.append(
            (
                f"calibration (iiwa, seeds 0, 1), {kind}",
                metrics(fitted[sel], fit["right"][sel], fit["moved"][sel]),
            )
        )
    rows.append(("calibration, every step", metrics(fitted, fit["right"], fit["moved"])))
    emulated = with_maps(val, maps)
    for robot in ("iiwa", "panda"):
        for kind, carried in zip(KINDS, (False, True), strict=True):
            sel = (val["robot"] == robot) & (val["carried"] == carried)
            if sel.any():
                rows.append(
                    (
                        f"validation, {robot}, {kind}",
                        metrics(emulated[sel], val["right"][sel], val["moved"][sel]),
                    )
                )
    if len(val["score"]):
        rows.append(("validation, every step", metrics(emulated, val["right"], val["moved"])))
    return rows


def cpp_snippet(maps: dict[str, np.ndarray]) -> str:
    """The maps as C++ for cpp/src/alignment/calibration_maps.inc."""
    names = {"servo": "kServoMap", "servo_carried": "kServoCarriedMap"}
    return "\n".join(
        f"constexpr Knot {names[kind]}[] = {{"
        + ", ".join(f"{{{s:.4f}, {p:.4f}}}" for s, p in knots)
        + "};"
        for kind, knots in maps.items()
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-doc", action="store_true", help="print, write nothing")
    args = parser.parse_args()
    fit = read_steps(CALIBRATION_RUNS)
    if len(fit["score"]) == 0:
        raise SystemExit(f"no calibration runs in {CALIBRATION_RUNS}: run them first (above)")
    maps = fit_maps(fit)
    val = read_steps(VALIDATION_RUNS, seeds={201, 202, 203})
    stamp = (
        f"Calibration runs at {', '.join(fit['commits'])}, validation runs at "
        f"{', '.join(val['commits']) or '-'}; {report_lib.machine()}; "
        "`python benchmarks/servo_confidence.py`."
    )
    knots_text = "\n".join(
        f"- `{kind}`: " + " ".join(f"({s:.3f}, {p:.3f})" for s, p in knots)
        for kind, knots in maps.items()
    )
    text = (
        f"{stamp}\n\n{table(figures(fit, val, maps))}\n\n"
        f"Fitted knots (score, P(right)):\n\n{knots_text}"
    )
    print(text + "\n\n" + cpp_snippet(maps))
    if args.no_doc:
        return
    if len(val["score"]):
        plot(with_maps(val, maps), val["right"], FIGURE)
    if report_lib.replace_block(DOC, MARKER, text):
        print(f"wrote the table into {DOC.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
