"""The paper's robot experiment (section III, Fig. 6) in simulation: whole-scene visual servoing
of the iiwa's wrist camera back to the pose where the reference cloud was captured.

The reference is captured at ``sim.HOME_Q``, 0.55 m above the cluttered table. Start poses
move every joint at random (seeded) and fall in two sets by the camera's displacement from
the reference pose:

* ``moderate``: under 0.2 m and under 30 degrees;
* ``large``: 0.2 m or 30 degrees and more, under 0.45 m and 60 degrees.

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
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import spectral_vs as svs
from spectral_vs import servo as servo_lib
from spectral_vs import sim

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "servo.json"
FIGURES = ROOT / "docs" / "figures"

SETS = servo_lib.START_SETS  # joint perturbation and accepted camera displacement
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
IMAGE = (320, 240)  # pixels (at 160 x 120 the final rotation error was about 0.6 deg)


def machine() -> dict[str, Any]:
    """The machine, the commit and the compiled core the numbers come from."""
    cpu = platform.processor() or "unknown"
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        names = [line for line in cpuinfo.read_text().splitlines() if line.startswith("model name")]
        if names:
            cpu = names[0].split(":", 1)[1].strip()
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
    except OSError:
        commit = ""
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "commit": commit or "unknown",
        "core_sha256": hashlib.sha256(Path(svs._core.__file__).read_bytes()).hexdigest()[:12],
        "load_average": os.getloadavg()[0],
    }


def starts(kinematics: svs.Kinematics, name: str, count: int, seed: int) -> list[dict]:
    """``count`` seeded start configurations of a set."""
    spec = SETS[name]
    rng = np.random.default_rng([seed, list(SETS).index(name)])
    out = []
    for _ in range(count):
        q, t, r = servo_lib.random_start(
            kinematics,
            np.asarray(sim.HOME_Q),
            rng,
            joint_range=spec["joint_range"],
            translation_range=spec["translation"],
            rotation_range=tuple(math.radians(a) for a in spec["rotation_deg"]),
        )
        out.append({"q": q.tolist(), "start_mm": 1000 * t, "start_deg": math.degrees(r)})
    return out


def run_episode(
    robot: sim.PyBulletRobot,
    reference: svs.PointCloud,
    T_world_reference: np.ndarray,
    start: dict,
    mode: str,
    keep_clouds: bool,
) -> tuple[dict, servo_lib.ServoLog, list[np.ndarray]]:
    robot.reset_joint_positions(start["q"])
    clock = robot.time()
    recorder = servo_lib.CloudRecorder(robot) if keep_clouds else robot
    servo = servo_lib.SpectralServo(reference, servo_lib.ServoParams(**MODES[mode]))
    log = servo_lib.run_servo(
        recorder,
        robot.kinematics,
        servo,
        dt=DT,
        max_steps=MAX_STEPS,
        stop_at_joint_limit=False,  # let the arm slide along a limit with the other joints
    )
    t, r = servo_lib.pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
    errors = servo_lib.true_errors(log, T_world_reference)
    seconds = log.array("seconds")
    row = {
        "mode": mode,
        "start_mm": start["start_mm"],
        "start_deg": start["start_deg"],
        "final_mm": 1000 * t,
        "final_deg": math.degrees(r),
        "success": bool(1000 * t < SUCCESS_MM and math.degrees(r) < SUCCESS_DEG),
        "reason": log.reason,
        "message": log.status.message,
        "steps": len(log.records),
        "sim_time_s": float(robot.time() - clock),
        "wall_s": log.wall_seconds,
        "step_wall_s": log.wall_seconds / len(log.records),
        "servo_step_s_median": float(np.median(seconds)),
        "iterations_median": float(np.median(log.array("iterations"))),
        "final_fitness": float(log.records[-1].fitness),
        "true_mm": np.round(errors[:, 0], 2).tolist(),
        "true_deg": np.round(errors[:, 1], 3).tolist(),
        "estimated_mm": np.round(1000 * log.array("translation_error"), 2).tolist(),
    }
    clouds = recorder.clouds if isinstance(recorder, servo_lib.CloudRecorder) else []
    return row, log, clouds


def summarize(rows: list[dict]) -> list[dict]:
    """Per (set, mode): success rate, final errors of the successes, steps, times."""
    table = []
    for name in SETS:
        for mode in MODES:
            cell = [r for r in rows if r["set"] == name and r["mode"] == mode]
            if not cell:
                continue
            ok = [r for r in cell if r["success"]]
            false = [r for r in cell if r["reason"] == "converged" and not r["success"]]
            reasons: dict[str, int] = {}
            for r in cell:
                reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1

            def median(key: str, among: list[dict]) -> float | None:
                return float(np.median([r[key] for r in among])) if among else None

            table.append(
                {
                    "set": name,
                    "mode": mode,
                    "runs": len(cell),
                    "successes": len(ok),
                    "false_convergences": len(false),
                    "success_rate": len(ok) / len(cell),
                    "start_mm_median": median("start_mm", cell),
                    "start_deg_median": median("start_deg", cell),
                    "final_mm_median": median("final_mm", ok),
                    "final_mm_max": max((r["final_mm"] for r in ok), default=None),
                    "final_deg_median": median("final_deg", ok),
                    "final_deg_max": max((r["final_deg"] for r in ok), default=None),
                    "steps_median": median("steps", ok),
                    "sim_time_s_median": median("sim_time_s", ok),
                    "step_wall_ms_median": 1000 * median("step_wall_s", cell),
                    "servo_step_ms_median": 1000 * median("servo_step_s_median", cell),
                    "reasons": reasons,
                }
            )
    return table


def markdown(results: dict) -> str:
    lines = [
        "| Set | Estimate | Success | Start (median) | Final error of successes "
        "(median / max) | Steps (median) | Simulated time | Wall time per step (loop / servo) "
        "| Ends |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in results["summary"]:

        def fmt(value: float | None, digits: int) -> str:
            return "-" if value is None else f"{value:.{digits}f}"

        ends = ", ".join(f"{k} {v}" for k, v in sorted(c["reasons"].items()))
        if c["false_convergences"]:
            ends += f" ({c['false_convergences']} converged away from the goal)"
        lines.append(
            f"| {c['set']} | {c['mode']} | {c['successes']}/{c['runs']} "
            f"({100 * c['success_rate']:.0f}%) | {c['start_mm_median']:.0f} mm, "
            f"{c['start_deg_median']:.1f} deg | {fmt(c['final_mm_median'], 2)} / "
            f"{fmt(c['final_mm_max'], 2)} mm, {fmt(c['final_deg_median'], 2)} / "
            f"{fmt(c['final_deg_max'], 2)} deg | {fmt(c['steps_median'], 0)} | "
            f"{fmt(c['sim_time_s_median'], 1)} s | {c['step_wall_ms_median']:.0f} / "
            f"{c['servo_step_ms_median']:.0f} ms | {ends} |"
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=20, help="starts per set (default 20)")
    parser.add_argument("--sets", default=",".join(SETS), help="sets to run (default: all)")
    parser.add_argument("--modes", default=",".join(MODES), help="estimates (default: all)")
    parser.add_argument(
        "--pose-starts",
        type=int,
        default=COLD_POSE_STARTS,
        help=f"cold 'pose' runs on the first N starts of each set (default {COLD_POSE_STARTS})",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="2 starts per set, write nothing")
    parser.add_argument("--report-only", action="store_true", help="figures from the JSON")
    parser.add_argument(
        "--episodes-only", action="store_true", help="re-run and draw only the EPISODES"
    )
    args = parser.parse_args()

    if args.report_only:
        results = json.loads(RESULTS.read_text())
        write_figures(results)
        print(markdown(results))
        return

    count = 2 if args.quick else args.starts
    sets = [s for s in args.sets.split(",") if s]
    modes = [m for m in args.modes.split(",") if m]
    started = time.perf_counter()
    load_before = os.getloadavg()[0]
    params = sim.SimParams(
        mode="kinematic", camera=sim.CameraParams(intrinsics=sim.CameraIntrinsics(*IMAGE))
    )
    rows: list[dict] = []
    episodes: dict[str, Any] = {}
    drawn = {(name, index): figure for name, index, figure in EPISODES}
    with sim.PyBulletRobot(params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        if args.episodes_only:
            for name, index, figure in EPISODES:
                start = starts(robot.kinematics, name, index + 1, args.seed)[index]
                row, log, clouds = run_episode(
                    robot, reference, T_world_reference, start, "iteration", True
                )
                episodes[figure] = (name, log, clouds)
                print(f"{figure}: {row['reason']}, {row['final_mm']:.2f} mm")
            draw_episodes(episodes, reference, T_world_reference)
            return
        for name in sets:
            for index, start in enumerate(starts(robot.kinematics, name, count, args.seed)):
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
                        f"{name:8s} #{index:2d} {mode:9s} start {row['start_mm']:5.0f} mm "
                        f"{row['start_deg']:4.1f} deg -> {row['reason']:14s} final "
                        f"{row['final_mm']:7.2f} mm {row['final_deg']:6.2f} deg, "
                        f"{row['steps']:3d} steps, {1000 * row['step_wall_s']:4.0f} ms/step",
                        flush=True,
                    )
    results = {
        "command": "python benchmarks/servo_experiment.py " + " ".join(sys.argv[1:]),
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine() | {"load_average_at_start": load_before},
        "settings": {
            "dt_s": DT,
            "max_steps": MAX_STEPS,
            "image": list(IMAGE),
            "success_mm": SUCCESS_MM,
            "success_deg": SUCCESS_DEG,
            "sets": {k: SETS[k] for k in sets},
            "servo_params": {
                k: v
                for k, v in servo_lib.ServoParams().__dict__.items()
                if k not in ("mode", "align_overrides")
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
        servo_lib.plot_servo(
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
