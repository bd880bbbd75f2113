"""The paper's robot experiment (section III, Fig. 6) in simulation: whole-scene visual servoing
of the iiwa's wrist camera back to the pose where the reference cloud was captured.

The reference is captured at ``sim.HOME_Q``, 0.55 m above the cluttered table. Start poses
move every joint at random (seeded) and fall in two sets by the camera's displacement from
the reference pose:

* ``moderate``: under 0.2 m and under 30 degrees;
* ``large``: 0.2 m or 30 degrees and more, under 0.45 m and 60 degrees;
* ``extreme`` (only with ``--sets extreme``): 0.45 m or 60 degrees and more, under 0.6 m
  and 90 degrees, with at least 30% of the reference in view (the start check of
  ``spectral-vs servo-sim``, so both draw the same starts).

Each start is servoed with three estimates of ``spectral_vs.servo``: ``iteration``, the
paper's one update of Algorithm 1 per control step from the identity; ``pose``, Algorithm 1
to convergence per step from the identity (only the first 8 starts of each set, for time);
``pose+warm``, the same started from the previous estimate carried along the measured
camera motion. Kinematic simulation, control period 0.1 s, at most 100 steps; a joint
reaching its limit is clamped and the other joints carry on. Success: final camera pose
error (ground truth: PyBullet's link state) under 5 mm and 1 degree. Writes
``benchmarks/results/servo.json`` and ``docs/figures/servo_*.png`` and prints the tables of
``docs/servoing.md``. Usage::

    python benchmarks/servo_experiment.py               # about 16 min on 2 busy cores
    python benchmarks/servo_experiment.py --quick       # 2 starts per set, writes nothing
    python benchmarks/servo_experiment.py --report-only # figures and tables from the JSON

Needs pybullet and matplotlib.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import sys
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import report as report_lib

import spectral_vs as svs
from spectral_vs import experiment, sim
from spectral_vs import servo as servo_lib
from spectral_vs.plotting import plot_servo

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "servo.json"
FIGURES = ROOT / "docs" / "figures"

SETS = experiment.START_SETS  # joint perturbation and accepted camera displacement
DEFAULT_SETS = ("moderate", "large")  # the runs of docs/servoing.md
#: The estimates compared: label -> ServoParams fields.
MODES: dict[str, dict[str, Any]] = {
    "iteration": {"mode": "iteration"},
    "pose": {"mode": "pose"},
    "pose+warm": {"mode": "pose", "warm_start": True},
}
#: Runs of the cold-started 'pose' estimate per set (the first starts only, for time).
COLD_POSE_STARTS = 8
SUCCESS_MM = 5.0
SUCCESS_DEG = 1.0
DT = 0.1  # control period, s
MAX_STEPS = 100  # 10 s of simulated time
#: Runs drawn in the paper's Fig. 6 layout ('iteration' estimate): (set, start index, figure).
EPISODES = (
    ("moderate", 0, "servo_episode_moderate.png"),
    ("large", 3, "servo_episode_large.png"),
    ("large", 0, "servo_episode_failure.png"),
)
QUICK_STARTS = 2  # per set, --quick
IMAGE = (320, 240)  # pixels (at 160 x 120 the final rotation error was about 0.6 deg)


def machine() -> dict[str, Any]:
    """The machine, the commit and the compiled core the numbers come from."""
    return {
        "cpu": report_lib.cpu_model(platform.processor() or "unknown"),
        "cores": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "commit": report_lib.commit(),
        "core_sha256": report_lib.core_sha256(),
        "load_average": os.getloadavg()[0],
    }


def sim_params() -> sim.SimParams:
    """The simulation of every run: kinematic mode, ``IMAGE`` depth images."""
    return sim.SimParams(
        mode="kinematic", camera=sim.CameraParams(intrinsics=sim.CameraIntrinsics(*IMAGE))
    )


def flat_settings(params: servo_lib.ServoParams) -> dict[str, Any]:
    """Every setting of ``params`` by its flat name (the groups' fields)."""
    return {
        item.name: getattr(params, item.name)
        for group in dataclasses.fields(params)
        for item in dataclasses.fields(getattr(params, group.name))
    }


def loop_settings() -> dict[str, Any]:
    """The loop's settings and the success test, for the results' record."""
    return {
        "dt_s": DT,
        "max_steps": MAX_STEPS,
        "image": list(IMAGE),
        "success_mm": SUCCESS_MM,
        "success_deg": SUCCESS_DEG,
    }


def start_check(robot: sim.PyBulletRobot, name: str) -> Any:
    """The start check of set ``name`` as ``spectral-vs servo-sim`` builds it: the robot's
    view check for the sets with ``min_view_share``, else none."""
    spec = SETS[name]
    return robot.view_check(spec["min_view_share"]) if "min_view_share" in spec else None


def starts(
    kinematics: svs.Kinematics, name: str, count: int, seed: int, accept: Any = None
) -> list[dict]:
    """``count`` seeded start configurations of a set (``experiment.start_poses``; ``accept``:
    :func:`start_check`)."""
    return [
        {"q": q.tolist(), "start_mm": 1000 * t, "start_deg": math.degrees(r)}
        for q, t, r in experiment.start_poses(kinematics, name, count, seed, accept=accept)
    ]


def servo_run(
    robot: sim.PyBulletRobot,
    start: dict,
    controller: Any,
    T_world_reference: np.ndarray,
    driven: Any = None,
) -> tuple[dict, servo_lib.ServoLog]:
    """Servo ``robot`` from ``start`` with ``controller`` (``driven``: the robot as the
    controller sees it, ``robot`` itself by default) and measure the true final error.

    Returns the fields every run records (start and final errors, mm and degrees, the
    success, how it ended, steps, simulated and wall time, the true errors of every step)
    and the log.
    """
    robot.reset_joint_positions(start["q"])
    clock = robot.time()
    log = servo_lib.run_servo(
        robot if driven is None else driven,
        robot.kinematics,
        controller,
        dt=DT,
        max_steps=MAX_STEPS,
        stop_at_joint_limit=False,  # let the arm slide along a limit with the other joints
    )
    t, r = servo_lib.pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
    errors = experiment.true_errors(log, T_world_reference)
    row = {
        "start_mm": start["start_mm"],
        "start_deg": start["start_deg"],
        "final_mm": 1000 * t,
        "final_deg": math.degrees(r),
        "success": bool(1000 * t < SUCCESS_MM and math.degrees(r) < SUCCESS_DEG),
        "reason": log.reason,
        "steps": len(log.records),
        "sim_time_s": float(robot.time() - clock),
        "wall_s": log.wall_seconds,
        "true_mm": np.round(errors[:, 0], 2).tolist(),
        "true_deg": np.round(errors[:, 1], 3).tolist(),
    }
    return row, log


def run_episode(
    robot: sim.PyBulletRobot,
    reference: svs.PointCloud,
    T_world_reference: np.ndarray,
    start: dict,
    mode: str,
    keep_clouds: bool,
) -> tuple[dict, servo_lib.ServoLog, list[np.ndarray]]:
    recorder = experiment.CloudRecorder(robot) if keep_clouds else None
    servo = servo_lib.SpectralServo(reference, servo_lib.ServoParams(**MODES[mode]))
    common, log = servo_run(robot, start, servo, T_world_reference, recorder)
    row = {"mode": mode} | common
    row |= {
        "message": log.status.message,
        "step_wall_s": log.wall_seconds / len(log.records),
        "servo_step_s_median": float(np.median(log.array("seconds"))),
        "iterations_median": float(np.median(log.array("iterations"))),
        "final_fitness": float(log.records[-1].fitness),
        "estimated_mm": np.round(1000 * log.array("translation_error"), 2).tolist(),
    }
    return row, log, [] if recorder is None else recorder.clouds


def median(rows: list[dict], key: str) -> float | None:
    """Median of ``key`` over ``rows``, None for no rows."""
    return float(np.median([r[key] for r in rows])) if rows else None


def outcomes(cell: list[dict]) -> dict:
    """What every summary row of runs (:func:`servo_run`'s fields) holds: runs, successes,
    convergences away from the goal, median start, final errors of the successes (median
    and max), their median steps, and the count of each way the runs ended."""
    ok = [r for r in cell if r["success"]]
    return {
        "runs": len(cell),
        "successes": len(ok),
        "false_convergences": sum(r["reason"] == "converged" and not r["success"] for r in cell),
        "start_mm_median": median(cell, "start_mm"),
        "start_deg_median": median(cell, "start_deg"),
        "final_mm_median": median(ok, "final_mm"),
        "final_mm_max": max((r["final_mm"] for r in ok), default=None),
        "final_deg_median": median(ok, "final_deg"),
        "final_deg_max": max((r["final_deg"] for r in ok), default=None),
        "steps_median": median(ok, "steps"),
        "reasons": dict(Counter(r["reason"] for r in cell)),
    }


def groups(
    rows: list[dict], sets: Iterable[str], key: str, labels: Iterable[str]
) -> Iterator[tuple[str, str, list[dict]]]:
    """``(set, label, runs)`` for every set and label (``run[key]``) that has runs, in the
    order of ``sets``, then ``labels``."""
    for name in sets:
        for label in labels:
            cell = [r for r in rows if r["set"] == name and r[key] == label]
            if cell:
                yield name, label, cell


def summarize(rows: list[dict]) -> list[dict]:
    """Per (set, mode): success rate, final errors of the successes, steps, times."""
    return [
        {"set": name, "mode": mode}
        | outcomes(cell)
        | {
            "success_rate": sum(r["success"] for r in cell) / len(cell),
            "sim_time_s_median": median([r for r in cell if r["success"]], "sim_time_s"),
            "step_wall_ms_median": 1000 * median(cell, "step_wall_s"),
            "servo_step_ms_median": 1000 * median(cell, "servo_step_s_median"),
        }
        for name, mode, cell in groups(rows, SETS, "mode", MODES)
    ]


def fmt(value: float | None, digits: int) -> str:
    """``value`` with ``digits`` decimals, ``-`` for none."""
    return "-" if value is None else f"{value:.{digits}f}"


def progress(name: str, index: int, label: str, width: int, row: dict) -> str:
    """The start of the line printed after a run."""
    return (
        f"{name:8s} #{index:2d} {label:{width}s} start {row['start_mm']:5.0f} mm "
        f"{row['start_deg']:4.1f} deg -> {row['reason']:14s} final "
        f"{row['final_mm']:7.2f} mm {row['final_deg']:6.2f} deg, {row['steps']:3d} steps"
    )


#: Columns of :func:`outcome_cells`.
OUTCOME_HEADER = "Start (median) | Final error of successes (median / max) | Steps (median)"


def outcome_cells(c: dict) -> str:
    """The start, final error and steps columns of a summary row (:func:`outcomes`)."""
    return (
        f"{c['start_mm_median']:.0f} mm, {c['start_deg_median']:.1f} deg | "
        f"{fmt(c['final_mm_median'], 2)} / {fmt(c['final_mm_max'], 2)} mm, "
        f"{fmt(c['final_deg_median'], 2)} / {fmt(c['final_deg_max'], 2)} deg | "
        f"{fmt(c['steps_median'], 0)}"
    )


def ends(c: dict) -> str:
    """How the runs of a summary row ended, and how many converged away from the goal."""
    text = ", ".join(f"{k} {v}" for k, v in sorted(c["reasons"].items()))
    if c["false_convergences"]:
        text += f" ({c['false_convergences']} converged away from the goal)"
    return text


def markdown(results: dict) -> str:
    lines = [
        f"| Set | Estimate | Success | {OUTCOME_HEADER} | Simulated time "
        "| Wall time per step (loop / servo) | Ends |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in results["summary"]:
        lines.append(
            f"| {c['set']} | {c['mode']} | {c['successes']}/{c['runs']} "
            f"({100 * c['success_rate']:.0f}%) | {outcome_cells(c)} | "
            f"{fmt(c['sim_time_s_median'], 1)} s | {c['step_wall_ms_median']:.0f} / "
            f"{c['servo_step_ms_median']:.0f} ms | {ends(c)} |"
        )
    return "\n".join(lines)


# --- Figures -----------------------------------------------------------------------------


def plot_errors(results: dict, path: Path) -> None:
    """True camera errors over time of every run: rows = estimate mode, columns = mm / deg."""
    from spectral_vs.plotting import _new_figure

    modes = [m for m in MODES if any(r["mode"] == m for r in results["records"])]
    figure = _new_figure(11.0, 3.6 * len(modes))
    axes = np.atleast_2d(figure.subplots(len(modes), 2, squeeze=False))
    colors = {"moderate": "tab:blue", "large": "tab:orange"}
    for row, mode in enumerate(modes):
        for column, (key, unit, limit) in enumerate(
            (
                ("true_mm", "translation error (mm)", SUCCESS_MM),
                ("true_deg", "rotation error (deg)", SUCCESS_DEG),
            )
        ):
            axis = axes[row, column]
            for r in results["records"]:
                if r["mode"] != mode:
                    continue
                values = np.maximum(np.asarray(r[key]), 1e-3)
                t = DT * np.arange(len(values))
                axis.plot(
                    t,
                    values,
                    color=colors[r["set"]],
                    alpha=0.8 if r["success"] else 0.25,
                    linewidth=1.0 if r["success"] else 0.8,
                )
            axis.axhline(limit, color="tab:red", linestyle="--", linewidth=1)
            axis.set_yscale("log")
            axis.set_xlabel("simulated time (s)")
            axis.set_ylabel(unit)
            axis.set_title(f"'{mode}' estimate")
            axis.grid(True, which="both", alpha=0.3)
            for name, color in colors.items():
                axis.plot([], [], color=color, label=f"{name} starts")
            axis.plot([], [], color="tab:red", linestyle="--", label="success threshold")
            axis.legend(fontsize="small", loc="upper right")
    figure.suptitle("Camera pose error against the reference pose (faint: failed runs)")
    figure.savefig(path)


def plot_success(results: dict, path: Path) -> None:
    """Start displacement of every run, marked by its outcome, one panel per mode."""
    from spectral_vs.plotting import _new_figure

    modes = [m for m in MODES if any(r["mode"] == m for r in results["records"])]
    figure = _new_figure(5.0 * len(modes), 4.2)
    axes = np.atleast_1d(figure.subplots(1, len(modes), squeeze=False)[0])
    for axis, mode in zip(axes, modes, strict=True):
        rows = [r for r in results["records"] if r["mode"] == mode]
        for success, marker, color, label in (
            (True, "o", "tab:green", "success"),
            (False, "x", "tab:red", "failure"),
        ):
            chosen = [r for r in rows if r["success"] == success]
            axis.scatter(
                [r["start_mm"] for r in chosen],
                [r["start_deg"] for r in chosen],
                marker=marker,
                color=color,
                label=f"{label} ({len(chosen)})",
            )
        axis.axvline(200, color="0.5", linestyle=":")
        axis.axhline(30, color="0.5", linestyle=":")
        axis.set_xlabel("start: camera displacement (mm)")
        axis.set_ylabel("start: camera rotation (deg)")
        axis.set_title(f"'{mode}' estimate")
        axis.legend(fontsize="small")
        axis.grid(True, alpha=0.3)
    figure.savefig(path)


# --- Main --------------------------------------------------------------------------------


def new_parser(
    description: str, starts: int, sets: Iterable[str], quick: int, drawn: str
) -> argparse.ArgumentParser:
    """The options of every servo script: starts per set (``quick`` with ``--quick``), the
    sets, the seed, and ``--report-only`` (redraws ``drawn`` from the JSON)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument(
        "--starts", type=int, default=starts, help=f"starts per set (default {starts})"
    )
    parser.add_argument(
        "--sets", default=",".join(sets), help=f"sets to run (default: {','.join(sets)})"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"{quick} start{'s' * (quick > 1)} per set, write nothing",
    )
    parser.add_argument("--report-only", action="store_true", help=f"{drawn} from the JSON")
    return parser


def main() -> None:
    parser = new_parser(__doc__.splitlines()[0], 20, DEFAULT_SETS, QUICK_STARTS, "figures")
    parser.add_argument("--modes", default=",".join(MODES), help="estimates (default: all)")
    parser.add_argument(
        "--pose-starts",
        type=int,
        default=COLD_POSE_STARTS,
        help=f"cold 'pose' runs on the first N starts of each set (default {COLD_POSE_STARTS})",
    )
    parser.add_argument(
        "--episodes-only", action="store_true", help="re-run and draw only the EPISODES"
    )
    args = parser.parse_args()

    if args.report_only:
        results = json.loads(RESULTS.read_text())
        write_figures(results)
        print(markdown(results))
        return

    count = QUICK_STARTS if args.quick else args.starts
    sets = [s for s in args.sets.split(",") if s]
    modes = [m for m in args.modes.split(",") if m]
    started = time.perf_counter()
    load_before = os.getloadavg()[0]
    params = sim_params()
    rows: list[dict] = []
    episodes: dict[str, Any] = {}
    drawn = {(name, index): figure for name, index, figure in EPISODES}
    with sim.PyBulletRobot(params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        if args.episodes_only:
            for name, index, figure in EPISODES:
                check = start_check(robot, name)
                start = starts(robot.kinematics, name, index + 1, args.seed, check)[index]
                row, log, clouds = run_episode(
                    robot, reference, T_world_reference, start, "iteration", True
                )
                episodes[figure] = (name, log, clouds)
                print(f"{figure}: {row['reason']}, {row['final_mm']:.2f} mm")
            draw_episodes(episodes, reference, T_world_reference)
            return
        for name in sets:
            check = start_check(robot, name)
            for index, start in enumerate(starts(robot.kinematics, name, count, args.seed, check)):
                for mode in modes:
                    if mode == "pose" and index >= args.pose_starts:
                        continue
                    keep = (name, index) in drawn and mode == "iteration"
                    row, log, clouds = run_episode(
                        robot, reference, T_world_reference, start, mode, keep
                    )
                    row |= {"set": name, "index": index, "q_start": start["q"]}
                    rows.append(row)
                    if keep:
                        episodes[drawn[name, index]] = (name, log, clouds)
                    print(
                        progress(name, index, mode, 9, row)
                        + f", {1000 * row['step_wall_s']:4.0f} ms/step",
                        flush=True,
                    )
    results = {
        "command": "python benchmarks/servo_experiment.py " + " ".join(sys.argv[1:]),
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine() | {"load_average_at_start": load_before},
        "settings": loop_settings()
        | {
            "sets": {k: SETS[k] for k in sets},
            "servo_params": {
                k: v
                for k, v in flat_settings(servo_lib.ServoParams()).items()
                if k not in ("mode", "align_overrides", "view_overrides")
            },
        },
        "runtime_s": time.perf_counter() - started,
        "summary": summarize(rows),
        "records": rows,
    }
    print(markdown(results))
    print(f"total {results['runtime_s']:.0f} s")
    if args.quick:
        return
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    write_figures(results)
    draw_episodes(episodes, reference, T_world_reference)


def write_figures(results: dict) -> None:
    FIGURES.mkdir(parents=True, exist_ok=True)
    plot_errors(results, FIGURES / "servo_errors.png")
    plot_success(results, FIGURES / "servo_success.png")


def draw_episodes(episodes: dict, reference: svs.PointCloud, T_world_reference: Any) -> None:
    FIGURES.mkdir(parents=True, exist_ok=True)
    for figure, (name, log, clouds) in episodes.items():
        plot_servo(
            log,
            T_world_reference,
            FIGURES / figure,
            reference=reference,
            clouds=dict(enumerate(clouds)),
            title=f"Servoing from a {name} start ('iteration' estimate): {log.reason} "
            f"after {len(log.records)} steps",
        )


if __name__ == "__main__":
    main()
