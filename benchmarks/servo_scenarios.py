"""The servo when it cannot see: every scenario of ``spectral_vs.sim.scenarios`` (boxes and
a hand in front of the camera, a tool left in view, stray points, late, dropped, empty and
stale frames) from seeded starts on both arms, for the spectral servo and its peers, with
success, final error, worst excursion and step time (docs/servoing.md, "What the servo
does when it cannot see").

The loop is that of ``spectral-vs servo-sim --scenario NAME`` (kinematic simulation, 320 x
240, control period 0.1 s, at most 150 steps, a joint at its limit clamped while the others
carry on). Success: the final camera pose within 5 mm and 1 degree of the reference pose.
Excursion: the largest camera error of the run minus the start's; a run *wandered* when it
exceeds 20 mm or 5 degrees (``scenarios.EXCURSION_MM`` / ``EXCURSION_DEG``). Step time:
CPU time (``time.process_time``) of the controller's ``step_record``, one thread.

Seeds 201-203: no setting of the servo was chosen on them. Controllers: ``spectral``
(``ServoParams()``), ``ICP-PBVS``, ``FPFH-PBVS`` (``benchmarks/servo_peers.py``) and
``dense depth``, the last on the depth image, so only under the scenarios that put
something in the rendered scene (``clean``, the boxes, the hands, the tool): the faults
that spoil a point cloud (stray points, late, dropped or stale frames) have no depth-image
form here.

Each (robot, set, seed, scenario, controller) writes its own file,
``benchmarks/results/servo_scenarios/<robot>_<set>_<seed>_<scenario>_<controller>.json``;
``--report-only`` joins them into the table of docs/servoing.md (block
``servo-scenarios``). Usage::

    python benchmarks/servo_scenarios.py                 # the full run: 20 starts x 3 seeds
    python benchmarks/servo_scenarios.py --starts 5 --seeds 201 --controllers spectral
    python benchmarks/servo_scenarios.py --robots panda --scenarios box_25cm_1s,hand_20cm
    python benchmarks/servo_scenarios.py --report-only
    python benchmarks/servo_scenarios.py --out servo_calibration --seeds 0,1  # apart

Needs pybullet, and open3d for the peers (the ``bench`` extra).
"""

from __future__ import annotations

import argparse
import json
import math
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before Open3D loads: one thread

import time
from pathlib import Path
from typing import Any

import numpy as np
import peer_servos
import report as report_lib
import servo_peers
from servo_peers import CpuTimed, slug

from spectral_vs import experiment, sim
from spectral_vs import servo as servo_lib
from spectral_vs.poses import pose_error
from spectral_vs.sim import scenarios

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = "servo_scenarios"
RUNS = ROOT / "benchmarks" / "results" / DEFAULT_OUT
#: Per-step verdict records of the spectral runs (score, the estimate's true error, whether
#: the step moved), beside each run file; too large to keep in the repository, rebuilt by
#: the same command (benchmarks/servo_confidence.py reads them).
STEPS = ROOT / "benchmarks" / "results" / "servo_steps" / "servo_scenarios"
SERVOING_DOC = ROOT / "docs" / "servoing.md"
ROBOTS = ("iiwa", "panda")
SETS = ("moderate", "large")
SEEDS = (201, 202, 203)
STARTS = 20
DT = 0.1
MAX_STEPS = 150
SUCCESS_MM, SUCCESS_DEG = 5.0, 1.0
SPECTRAL = "spectral"
CONTROLLERS = (SPECTRAL, "ICP-PBVS", "FPFH-PBVS", "dense depth")
#: The scenarios whose fault is in the rendered scene: the depth-image peer runs them.
DEPTH_SCENARIOS = (
    "clean",
    "box_15cm_1s",
    "box_15cm_3s",
    "box_25cm_1s",
    "box_25cm_3s",
    "hand_20cm",
    "hand_40cm",
    "tool_left",
)


def run_file(robot: str, name: str, seed: int, scenario: str, label: str) -> Path:
    return RUNS / f"{robot}_{name}_{seed}_{scenario}_{slug(label)}.json"


def set_output(name: str) -> None:
    """Write the run files to ``benchmarks/results/<name>`` and the per-step records to
    ``benchmarks/results/servo_steps/<name>`` (the confidence's calibration runs are kept
    apart from the scenarios' table this way)."""
    global RUNS, STEPS
    RUNS = ROOT / "benchmarks" / "results" / name
    STEPS = ROOT / "benchmarks" / "results" / "servo_steps" / name


def step_verdicts(log: servo_lib.ServoLog, reference: Any, T_reference: np.ndarray) -> dict:
    """Per step of a spectral run: the uncalibrated score, the calibrated confidence, whether
    the step moved on its estimate, whether the estimate was carried along the odometry
    (not the registration's), and the estimate's true error (mm, degrees; the translation
    at the reference's centroid) against the camera pose of the step's frame."""
    centroid = np.asarray(reference.points).mean(axis=0)
    rows: dict[str, list] = {
        k: [] for k in ("score", "confidence", "moved", "carried", "mm", "deg")
    }
    for record in log.records:
        T_true = np.linalg.inv(record.T_base_camera) @ T_reference
        error = pose_error(record.T_current_desired, T_true, center=centroid)
        rows["score"].append(_rounded(record.score, 4))
        rows["confidence"].append(_rounded(record.confidence, 4))
        rows["moved"].append(bool(record.reliable and not record.hold))
        rows["carried"].append(bool(record.carried))
        rows["mm"].append(_rounded(error.translation_mm, 2))
        rows["deg"].append(_rounded(error.rotation_deg, 3))
    return rows


def _rounded(value: float, digits: int) -> float | None:
    return round(float(value), digits) if math.isfinite(value) else None


def run_one(
    robot: Any, scenario: scenarios.Scenario, label: str, q: np.ndarray, refs: tuple
) -> dict[str, Any]:
    """One run of ``label`` through ``scenario`` from ``q``: its record."""
    reference, depth, T_reference = refs
    factory, uses_depth = servo_peers.CONTROLLERS[label]
    controller = CpuTimed(factory(reference, depth, robot.params.camera.intrinsics))
    robot.reset_joint_positions(q)
    faulty = scenario.wrap(robot)
    # The dense depth servo sees the depth image, with the scenario's box in it.
    driven: Any = peer_servos.DepthImageRobot(faulty) if uses_depth else faulty
    log = servo_lib.run_servo(
        driven,
        robot.kinematics,
        controller,  # type: ignore[arg-type]  # any controller with step_record and reset
        dt=DT,
        max_steps=MAX_STEPS,
        stop_at_joint_limit=False,
    )
    remove = getattr(faulty, "remove", None)
    if callable(remove):
        remove()
    run = scenarios.summarize(log, T_reference, robot.camera_pose())
    verdicts = step_verdicts(log, reference, T_reference) if label == SPECTRAL else None
    return {
        "controller": label,
        "reason": run.reason,
        "success": bool(run.final_mm < SUCCESS_MM and run.final_deg < SUCCESS_DEG),
        "final_mm": run.final_mm,
        "final_deg": run.final_deg,
        "worst_excursion_mm": run.worst_excursion_mm,
        "worst_excursion_deg": run.worst_excursion_deg,
        "wandered": run.wandered(),
        "held_steps": run.held_steps,
        "steps": run.steps,
        "step_cpu_ms": [round(1000 * s, 3) for s in controller.seconds],
        "verdicts": verdicts,
    }


def run(args: argparse.Namespace) -> None:
    """Every cell of the arguments, one robot (noise-free, then noisy) at a time."""
    RUNS.mkdir(parents=True, exist_ok=True)
    for robot_name in args.robots:
        for noisy in (False, True):
            chosen = [s for s in args.scenarios if scenarios.SCENARIOS[s].noise == noisy]
            if chosen:
                run_robot(args, robot_name, noisy, chosen)


def run_robot(args: argparse.Namespace, robot_name: str, noisy: bool, chosen: list[str]) -> None:
    noise = sim.DepthNoise.kinect(seed=0) if noisy else sim.DepthNoise()
    params = sim.SimParams(
        mode="kinematic", robot=sim.robot_model(robot_name), camera=sim.CameraParams(noise=noise)
    )
    with sim.PyBulletRobot(params) as robot:
        refs = (robot.capture(), robot.capture_depth(), robot.camera_pose())
        for name in args.sets:
            for seed in args.seeds:
                starts = experiment.start_poses(
                    robot.kinematics,
                    name,
                    args.starts,
                    seed,
                    params.robot.home_q,
                    servo_peers.start_check(robot, name),
                )
                for scenario_name, label in (
                    (scenario_name, label)
                    for scenario_name in chosen
                    for label in args.controllers
                    if label != "dense depth" or scenario_name in DEPTH_SCENARIOS
                ):
                    cell = (robot_name, name, seed, scenario_name, label)
                    if args.resume and _done(run_file(*cell), args.starts):
                        continue
                    run_cell(robot, refs, cell, starts)


def _done(path: Path, starts: int) -> bool:
    """Whether ``path`` holds a run of ``starts`` starts already (``--resume``)."""
    if not path.is_file():
        return False
    return len(json.loads(path.read_text())["records"]) == starts


def run_cell(robot: Any, refs: tuple, cell: tuple, starts: list) -> None:
    """The runs of one (robot, set, seed, scenario, controller) from ``starts``: its file."""
    robot_name, name, seed, scenario_name, label = cell
    scenario = scenarios.SCENARIOS[scenario_name]
    began = time.time()
    records = []
    for index, (q, t, r) in enumerate(starts):
        record = run_one(robot, scenario, label, q, refs)
        record.update(index=index, start_mm=1000 * t, start_deg=math.degrees(r))
        records.append(record)
    verdicts = [{"index": r["index"], **r["verdicts"]} for r in records if r["verdicts"]]
    for r in records:
        del r["verdicts"]
    out = {
        "robot": robot_name,
        "set": name,
        "seed": seed,
        "scenario": scenario_name,
        "controller": label,
        "commit": report_lib.commit(),
        "machine": report_lib.machine(),
        "load_at_start": os.getloadavg()[0],
        "threads": os.environ.get("OMP_NUM_THREADS"),
        "wall_s": time.time() - began,
        "records": records,
    }
    path = run_file(robot_name, name, seed, scenario_name, label)
    path.write_text(report_lib.to_json(out))
    if verdicts:
        STEPS.mkdir(parents=True, exist_ok=True)
        (STEPS / path.name).write_text(json.dumps({**out, "records": verdicts}))
    ok = sum(r["success"] for r in records)
    wandered = sum(r["wandered"] for r in records)
    print(
        f"{robot_name} {name} seed {seed} {scenario_name} {label}: {ok}/{len(records)} "
        f"success, {wandered} wandered, {time.time() - began:.0f} s",
        flush=True,
    )


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def falsely_converged(record: dict) -> bool:
    """A run that ended ``converged`` farther than the success tolerances from the goal: a
    wrong answer that looked right."""
    return record["reason"] == "converged" and not record["success"]


def table() -> str:
    """The table of every run file: per robot, set, scenario and controller."""
    cells: dict[tuple, list[dict]] = {}
    meta: dict[tuple, set] = {}
    for path in sorted(RUNS.glob("*.json")):
        data = json.loads(path.read_text())
        key = (data["robot"], data["set"], data["scenario"], data["controller"])
        cells.setdefault(key, []).extend(data["records"])
        meta.setdefault(key, set()).add((data["seed"], data["commit"]))
    order = {name: i for i, name in enumerate(scenarios.SCENARIOS)}
    rows = []
    for key in sorted(
        cells,
        key=lambda k: (k[0], SETS.index(k[1]), order[k[2]], CONTROLLERS.index(k[3])),
    ):
        records = cells[key]
        steps = [ms for r in records for ms in r["step_cpu_ms"]]
        good = [r for r in records if r["success"]]
        seeds = sorted({seed for seed, _ in meta[key]})
        commits = sorted({commit for _, commit in meta[key]})
        rows.append(
            [
                *key[:3],
                key[3],
                f"{len(good)}/{len(records)}",
                f"{sum(not r['wandered'] for r in records)}/{len(records)}",
                str(sum(falsely_converged(r) for r in records)),
                report_lib.num(percentile([r["final_mm"] for r in good], 50), digits=2)
                + " mm, "
                + report_lib.num(percentile([r["final_deg"] for r in good], 50), digits=3)
                + " deg",
                f"{max(r['worst_excursion_mm'] for r in records):.1f} mm, "
                f"{max(r['worst_excursion_deg'] for r in records):.1f} deg",
                report_lib.num(percentile(steps, 50), digits=1)
                + " / "
                + report_lib.num(percentile(steps, 95), digits=1),
                ", ".join(str(s) for s in seeds),
                ", ".join(commits),
            ]
        )
    header = [
        "robot",
        "set",
        "scenario",
        "controller",
        "success",
        "no excursion",
        "converged off the goal",
        "final error (median, successes)",
        "worst excursion",
        "step CPU ms, median / p95",
        "seeds",
        "commit",
    ]
    return report_lib.markdown(header, rows)


FIGURE = ROOT / "docs" / "figures" / "servo_occluded.png"
#: The runs of the figure: (robot, set, seed, start index, scenarios).
FIGURE_RUNS = ("iiwa", "moderate", 201, 0, ("clean", "box_25cm_3s", "hand_20cm"))


def plot_figure(path: Path) -> None:
    """The true camera error over time of one start through a few scenarios, held steps
    marked and the fault's window shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robot_name, name, seed, index, chosen = FIGURE_RUNS
    params = sim.SimParams(mode="kinematic", robot=sim.robot_model(robot_name))
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    with sim.PyBulletRobot(params) as robot:
        T_reference = robot.camera_pose()
        reference = robot.capture()
        q = experiment.start_poses(robot.kinematics, name, index + 1, seed, params.robot.home_q)[
            index
        ][0]
        for scenario_name in chosen:
            _, log = scenarios.run_scenario(
                robot, scenario_name, q, reference, T_reference, max_steps=MAX_STEPS
            )
            errors = experiment.true_errors(log, T_reference)
            print(
                f"{scenario_name}: {log.reason} after {log.records[-1].time:.1f} s, "
                f"{errors[-1, 0]:.2f} mm, {errors[-1, 1]:.3f} deg"
            )
            t = np.array([r.time for r in log.records])
            held = np.array([bool(r.hold) for r in log.records])
            for axis, column, unit in ((axes[0], 0, "mm"), (axes[1], 1, "deg")):
                (line,) = axis.plot(t, errors[:, column], label=f"{scenario_name} ({log.reason})")
                axis.plot(t[held], errors[held, column], "x", color=line.get_color())
                axis.set_ylabel(f"camera error, {unit}")
    for axis in axes:
        axis.axvspan(scenarios.FAULT_AT, scenarios.FAULT_AT + 3.0, color="0.9", zorder=0)
        axis.set_xlabel("time, s")
        axis.set_yscale("log")
    axes[0].legend(fontsize=8)
    fig.suptitle(
        f"{robot_name}, {name} start {index} of seed {seed}: the box from 1 s to 4 s (shaded), "
        "the hand from 1 s to 3 s; x: held steps",
        fontsize=9,
    )
    fig.tight_layout()
    report_lib.save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", default=",".join(ROBOTS))
    parser.add_argument("--sets", default=",".join(SETS))
    parser.add_argument("--seeds", default=",".join(map(str, SEEDS)))
    parser.add_argument("--starts", type=int, default=STARTS)
    parser.add_argument("--scenarios", default=",".join(scenarios.SCENARIOS))
    parser.add_argument("--controllers", default=",".join(CONTROLLERS))
    parser.add_argument(
        "--out",
        default=DEFAULT_OUT,
        help="folder of benchmarks/results for the run files (default %(default)s: the table)",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="skip the cells whose run file already holds --starts starts (an interrupted run)",
    )
    parser.add_argument("--report-only", action="store_true")
    parser.add_argument("--figure", action="store_true", help=f"draw {FIGURE.name} and exit")
    args = parser.parse_args()
    if args.figure:
        plot_figure(FIGURE)
        return
    if Path(args.out).name != args.out:
        parser.error(f"--out must be a folder name under benchmarks/results, got {args.out}")
    set_output(args.out)
    if not args.report_only:
        args.robots = args.robots.split(",")
        args.sets = args.sets.split(",")
        args.seeds = [int(s) for s in args.seeds.split(",")]
        args.scenarios = args.scenarios.split(",")
        args.controllers = args.controllers.split(",")
        unknown = set(args.scenarios) - set(scenarios.SCENARIOS)
        if unknown or set(args.controllers) - set(CONTROLLERS):
            parser.error(f"unknown scenario or controller: {unknown or args.controllers}")
        run(args)
    text = table()
    machine = report_lib.machine()
    block = (
        f"Command: `python benchmarks/servo_scenarios.py` (options as listed in the notes "
        f"below). Machine: {machine}. One thread each.\n\n{text}"
    )
    if args.out == DEFAULT_OUT and report_lib.replace_block(SERVOING_DOC, "servo-scenarios", block):
        print(f"table written to {SERVOING_DOC.relative_to(ROOT)}")
    else:
        print(text)


if __name__ == "__main__":
    main()
