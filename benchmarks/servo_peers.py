"""Servoing against other controllers: the spectral servo, the dense depth-map servo and
position-based servoing on Open3D's registration, from the same seeded start poses, on
both simulated arms.

The loop is that of ``spectral-vs servo-sim`` (docs/servoing.md): the robot preset
(``--robots iiwa,panda``, ``sim.robot_model``), kinematic simulation, 320 x 240 depth
images, the reference captured at the robot's home, control period 0.1 s, at most 150
steps, a joint at its limit clamped while the others carry on; success: the final camera
pose (PyBullet's link state) within 5 mm and 1 degree of the reference pose. Start sets:
``experiment.START_SETS`` drawn by ``experiment.start_poses`` with the command's seed and start
check, so start ``i`` of a set, robot and seed is the start ``i`` of ``servo-sim`` and of
every controller here (the report checks the joints match).

Controllers (``CONTROLLERS``):

* ``spectral``: ``SpectralServo(ServoParams())``, what ``servo-sim`` runs;
* ``dense depth``: ``peer_servos.DenseDepthServo``, Teuliere and Marchand's depth-map servo
  (Gauss-Newton, interaction matrix at the current depth map) on the raw depth images;
* ``ICP-PBVS``: Open3D point-to-plane ICP from the identity every step, then the PBVS law;
* ``ICP-PBVS warm``: the same ICP started from the previous estimate carried along the
  measured camera motion;
* ``FPFH-PBVS``: Open3D FPFH + RANSAC + point-to-plane ICP every step.

Every registration-based peer downsamples at 15 mm and uses the PBVS law, gains and speed
limits of ``ServoParams`` (their settings: docs/benchmarks.md); every controller runs on
one thread (``OMP_NUM_THREADS=1`` before Open3D loads). The servo step's time is the CPU
time (``time.process_time``) of the controller's ``step_record`` (everything the
controller does with a capture; the rendering and the capture's cloud are not in it).

Each run of (robot, set, controller) writes its own file,
``benchmarks/results/servo_peers/<robot>_<set>_<controller>.json``, so that one controller
can be rerun alone (``--controllers spectral``) and separate processes can share the work;
``--report-only`` joins the files: the start-by-start comparison
(``benchmarks/results/servo_peers.json``), the tables of docs/benchmarks.md (block
``servo-peers``) and docs/servoing.md (block ``servo-peers-summary``), and the figures
``docs/figures/servo_domain.png`` (success against the start's displacement, per
controller and robot) and ``docs/figures/servo_step_times.png`` (distribution of the
servo step times per set). Usage::

    python benchmarks/servo_peers.py --starts 20                # every controller, robot, set
    python benchmarks/servo_peers.py --controllers spectral     # the spectral servo alone
    python benchmarks/servo_peers.py --robots panda --sets large --controllers FPFH-PBVS
    python benchmarks/servo_peers.py --quick       # 1 start per set, writes nothing
    python benchmarks/servo_peers.py --report-only # join the files: tables and figures

Needs pybullet, open3d (the ``bench`` extra) and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import peer_servos
import report as report_lib
from report import BENCHMARKS_DOC, replace_block

from spectral_vs import experiment, sim
from spectral_vs import servo as servo_lib

# Open3D is imported later (peer_servos.open3d_module); its thread count is fixed then.
os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread, like ours
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "benchmarks" / "results" / "servo_peers"
RESULTS = ROOT / "benchmarks" / "results" / "servo_peers.json"
FIGURES = ROOT / "docs" / "figures"
SERVOING_DOC = ROOT / "docs" / "servoing.md"

ROBOTS = ("iiwa", "panda")
SETS = tuple(experiment.START_SETS)  # moderate, large, extreme
DT = 0.1  # control period, s (servo-sim's default)
MAX_STEPS = 150  # servo-sim's default
SUCCESS_MM = 5.0
SUCCESS_DEG = 1.0
SPECTRAL = "spectral"


def _registration(**fields: Any) -> Callable[..., Any]:
    return lambda cloud, depth, intrinsics: peer_servos.RegistrationServo(
        cloud, peer_servos.RegistrationServoParams(**fields)
    )


#: label -> (factory(reference cloud, reference depth image, intrinsics), uses depth images)
CONTROLLERS: dict[str, tuple[Callable[..., Any], bool]] = {
    SPECTRAL: (
        lambda cloud, depth, intrinsics: servo_lib.SpectralServo(cloud, servo_lib.ServoParams()),
        False,
    ),
    "dense depth": (
        lambda cloud, depth, intrinsics: peer_servos.DenseDepthServo(depth, intrinsics),
        True,
    ),
    "ICP-PBVS": (_registration(method="icp"), False),
    "ICP-PBVS warm": (_registration(method="icp", warm_start=True), False),
    "FPFH-PBVS": (_registration(method="fpfh"), False),
}
PEERS = tuple(label for label in CONTROLLERS if label != SPECTRAL)


def slug(label: str) -> str:
    """The file-name form of a controller's label: ``ICP-PBVS warm`` -> ``icp-pbvs_warm``."""
    return label.lower().replace(" ", "_")


def run_file(robot: str, name: str, label: str) -> Path:
    return RUNS / f"{robot}_{name}_{slug(label)}.json"


class CpuTimed:
    """A controller wrapper that keeps the CPU time of every ``step_record`` call, s
    (``time.process_time``: the one-thread cost, whatever else the machine runs)."""

    def __init__(self, controller: Any) -> None:
        self.controller = controller
        self.seconds: list[float] = []

    def reset(self) -> None:
        self.controller.reset()
        self.seconds = []

    def step_record(self, *args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        out = self.controller.step_record(*args, **kwargs)
        self.seconds.append(time.process_time() - start)
        return out


def sim_params(robot: str) -> sim.SimParams:
    """``servo-sim``'s simulation: kinematic, the preset, the default 320 x 240 camera."""
    return sim.SimParams(mode="kinematic", robot=sim.robot_model(robot))


def start_check(robot: sim.PyBulletRobot, name: str) -> Any:
    """The start check of set ``name`` (``start_poses``'s ``accept``), as ``spectral-vs
    servo-sim`` uses it: a view check for the sets with ``min_view_share``, else None."""
    spec = experiment.START_SETS[name]
    return robot.view_check(spec["min_view_share"]) if "min_view_share" in spec else None


def starts(robot: sim.PyBulletRobot, name: str, count: int, seed: int) -> list[dict]:
    """The ``count`` seeded starts of set ``name``, as ``spectral-vs servo-sim`` draws them."""
    accept = start_check(robot, name)
    return [
        {"q": q.tolist(), "start_mm": 1000 * t, "start_deg": math.degrees(r)}
        for q, t, r in experiment.start_poses(
            robot.kinematics,
            name,
            count,
            seed,
            q_reference=robot.params.robot.home_q,
            accept=accept,
        )
    ]


def run_one(
    robot: sim.PyBulletRobot,
    references: tuple[Any, np.ndarray],
    T_world_reference: np.ndarray,
    start: dict,
    label: str,
) -> dict:
    """Servo ``robot`` from ``start`` with controller ``label``; the run's record."""
    factory, uses_depth = CONTROLLERS[label]
    controller = CpuTimed(factory(references[0], references[1], robot.params.camera.intrinsics))
    driven = peer_servos.DepthImageRobot(robot) if uses_depth else robot
    robot.reset_joint_positions(start["q"])
    log = servo_lib.run_servo(
        driven,
        robot.kinematics,
        controller,  # type: ignore[arg-type]
        dt=DT,
        max_steps=MAX_STEPS,
        stop_at_joint_limit=False,  # servo-sim's default: slide along a limit
    )
    t, r = servo_lib.pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
    errors = experiment.true_errors(log, T_world_reference)
    success = bool(1000 * t < SUCCESS_MM and math.degrees(r) < SUCCESS_DEG)
    return {
        "controller": label,
        "start_mm": start["start_mm"],
        "start_deg": start["start_deg"],
        "final_mm": 1000 * t,
        "final_deg": math.degrees(r),
        "success": success,
        "reason": log.reason,
        "false_convergence": bool(log.reason == "converged" and not success),
        "steps": len(log.records),
        "relocalizations": sum(bool(getattr(x, "relocalized", False)) for x in log.records),
        "held_steps": sum(bool(getattr(x, "hold", "")) for x in log.records),
        "wall_s": log.wall_seconds,
        "step_cpu_ms": [round(1000 * s, 3) for s in controller.seconds],
        "true_mm": np.round(errors[:, 0], 2).tolist(),
        "true_deg": np.round(errors[:, 1], 3).tolist(),
        "q_start": start["q"],
    }


def setup(label: str, robot: str) -> dict[str, Any]:
    """What a run file records of the setting besides its runs."""
    out: dict[str, Any] = {
        "robot": robot,
        "dt_s": DT,
        "max_steps": MAX_STEPS,
        "image": [320, 240],
        "sim_mode": "kinematic",
        "stop_at_joint_limit": False,
        "success_mm": SUCCESS_MM,
        "success_deg": SUCCESS_DEG,
        "threads": os.environ.get("OMP_NUM_THREADS"),
    }
    if label == SPECTRAL:
        out["servo_params"] = {
            k: v
            for k, v in servo_lib.ServoParams().__dict__.items()
            if isinstance(v, (int, float, str, bool))
        }
    elif label == "dense depth":
        out["depth_params"] = dict(peer_servos.DepthServoParams().__dict__)
    else:
        out["registration_params"] = dict(
            peer_servos.RegistrationServoParams(
                method="fpfh" if label == "FPFH-PBVS" else "icp",
                warm_start=label == "ICP-PBVS warm",
            ).__dict__
        )
    return out


def run(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    robots = [r for r in args.robots.split(",") if r]
    sets = [s for s in args.sets.split(",") if s]
    controllers = [c for c in args.controllers.split(",") if c]
    for name, allowed, option in (
        (robots, ROBOTS, "--robots"),
        (sets, SETS, "--sets"),
        (controllers, tuple(CONTROLLERS), "--controllers"),
    ):
        for item in name:
            if item not in allowed:
                parser.error(f"{option}: unknown {item!r}; choose from {list(allowed)}")
    if any(c != SPECTRAL for c in controllers):
        o3d = peer_servos.open3d_module()
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    count = 1 if args.quick else args.starts
    command = "python benchmarks/servo_peers.py " + " ".join(sys.argv[1:])
    machine = report_lib_machine()
    for robot_name in robots:
        with sim.PyBulletRobot(sim_params(robot_name)) as robot:
            references = (robot.capture(), robot.capture_depth())
            T_world_reference = robot.camera_pose()
            chosen = {name: starts(robot, name, count, args.seed) for name in sets}
            records: dict[tuple[str, str], list[dict]] = {}
            # Start by start across the sets and controllers: a run cut short still
            # compares every controller on the same first starts of every set.
            for index in range(count):
                for name in sets:
                    for label in controllers:
                        row = run_one(
                            robot, references, T_world_reference, chosen[name][index], label
                        )
                        cell = records.setdefault((name, label), [])
                        cell.append({"index": index} | row)
                        cpu = np.asarray(row["step_cpu_ms"])
                        print(
                            f"{robot_name:5s} {name:8s} #{index:2d} {label:14s} start "
                            f"{row['start_mm']:5.0f} mm {row['start_deg']:4.1f} deg -> "
                            f"{row['reason']:14s} final {row['final_mm']:7.2f} mm "
                            f"{row['final_deg']:6.2f} deg, {row['steps']:3d} steps, step "
                            f"{np.median(cpu):5.1f} ms median (CPU), {row['wall_s']:5.1f} s",
                            flush=True,
                        )
                        if args.quick:
                            continue
                        out = {
                            "command": command,
                            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                            "machine": machine,
                            "controller": label,
                            "set": name,
                            "seed": args.seed,
                            "settings": setup(label, robot_name),
                            "runtime_s": sum(r["wall_s"] for r in cell),
                            "records": cell,
                        }
                        RUNS.mkdir(parents=True, exist_ok=True)  # after every start
                        run_file(robot_name, name, label).write_text(json.dumps(out) + "\n")
    if not args.quick:
        write_report()


def report_lib_machine() -> dict[str, Any]:
    import platform

    return {
        "cpu": report_lib.cpu_model(platform.processor() or "unknown"),
        "cores": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "commit": report_lib.commit(),
        "core_sha256": report_lib.core_sha256(),
        "load_average": round(os.getloadavg()[0], 2),
    }


# --- Report: join the run files ------------------------------------------------------------


def load_runs() -> dict[tuple[str, str, str], dict]:
    """Every run file: (robot, set, controller) -> its content."""
    out = {}
    for path in sorted(RUNS.glob("*.json")):
        data = json.loads(path.read_text())
        out[data["settings"]["robot"], data["set"], data["controller"]] = data
    return out


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def cell_summary(data: dict) -> dict:
    rows = data["records"]
    ok = [r for r in rows if r["success"]]
    cpu = [s for r in rows for s in r["step_cpu_ms"]]

    def med(cell: list[dict], key: str) -> float | None:
        return float(np.median([r[key] for r in cell])) if cell else None

    reasons: dict[str, int] = {}
    for r in rows:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    return {
        "runs": len(rows),
        "successes": len(ok),
        "success_indices": [r["index"] for r in ok],
        "false_convergences": sum(r["false_convergence"] for r in rows),
        "start_mm_median": med(rows, "start_mm"),
        "start_deg_median": med(rows, "start_deg"),
        "final_mm_median": med(ok, "final_mm"),
        "final_mm_max": max((r["final_mm"] for r in ok), default=None),
        "final_deg_median": med(ok, "final_deg"),
        "final_deg_max": max((r["final_deg"] for r in ok), default=None),
        "steps_median": med(ok, "steps"),
        "step_cpu_ms_median": percentile(cpu, 50),
        "step_cpu_ms_p95": percentile(cpu, 95),
        "steps_timed": len(cpu),
        "reasons": dict(sorted(reasons.items())),
        "commit": data["machine"]["commit"],
        "date": data["date"],
        "load_average": data["machine"]["load_average"],
        "runtime_s": data["runtime_s"],
    }


def compare(spectral: dict, peer: dict) -> dict:
    """Start by start: the peer's successes that the spectral servo misses, and the other
    way; ``includes``: every start the peer brings back, the spectral servo does too;
    ``strictly_more``: that, and at least one start more."""
    s = set(spectral["success_indices"])
    p = set(peer["success_indices"])
    return {
        "peer_only": sorted(p - s),
        "spectral_only": sorted(s - p),
        "includes": p <= s,
        "strictly_more": p < s,
    }


def joined(runs: dict[tuple[str, str, str], dict]) -> dict:
    """The start-by-start comparison of every peer with the spectral servo."""
    cells, comparisons = [], []
    for robot in ROBOTS:
        for name in SETS:
            spectral = runs.get((robot, name, SPECTRAL))
            present = [runs[k] for k in runs if k[:2] == (robot, name)]
            # Every controller on the same starts: the first ones all of them completed.
            shared = min((len(d["records"]) for d in present), default=0)
            for label in CONTROLLERS:
                data = runs.get((robot, name, label))
                if data is None:
                    continue
                summary = cell_summary(data | {"records": data["records"][:shared]})
                cells.append({"robot": robot, "set": name, "controller": label} | summary)
                if spectral is None or label == SPECTRAL:
                    continue
                common = shared
                for a, b in zip(
                    spectral["records"][:common], data["records"][:common], strict=True
                ):
                    if not np.allclose(a["q_start"], b["q_start"], atol=1e-12):
                        raise SystemExit(
                            f"{robot} {name} start {a['index']}: the spectral and {label} "
                            "runs started from different joints (seed or code changed): rerun"
                        )
                trimmed = [
                    cell_summary(d | {"records": d["records"][:common]}) for d in (spectral, data)
                ]
                comparisons.append(
                    {"robot": robot, "set": name, "peer": label, "starts": common}
                    | {
                        "spectral_successes": trimmed[0]["successes"],
                        "peer_successes": trimmed[1]["successes"],
                    }
                    | compare(*trimmed)
                )
    return {"cells": cells, "comparisons": comparisons}


def fmt(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def ends(c: dict) -> str:
    text = ", ".join(f"{k} {v}" for k, v in c["reasons"].items())
    if c["false_convergences"]:
        text += f" ({c['false_convergences']} converged away from the goal)"
    return text


def outcome_string(data: dict) -> str:
    """One character per start: ``o`` success, ``.`` failure."""
    return "".join("o" if r["success"] else "." for r in data["records"])


def provenance(runs: dict[tuple[str, str, str], dict]) -> list[str]:
    """Where the numbers come from: per controller, the commits, dates and loads."""
    lines = []
    for label in CONTROLLERS:
        chosen = [d for (_, _, c), d in runs.items() if c == label]
        if not chosen:
            continue
        commits = sorted({d["machine"]["commit"] for d in chosen})
        dates = sorted(d["date"] for d in chosen)
        loads = [d["machine"]["load_average"] for d in chosen]
        minutes = sum(d["runtime_s"] for d in chosen) / 60
        lines.append(
            f"- {label}: commit {', '.join(commits)}; files last written {dates[0]} to "
            f"{dates[-1]}; load average {min(loads):.1f}-{max(loads):.1f} when its processes "
            f"started; {sum(len(d['records']) for d in chosen)} runs, {minutes:.0f} min of "
            "wall time summed over them."
        )
    return lines


def markdown(runs: dict[tuple[str, str, str], dict], result: dict) -> str:
    any_run = next(iter(runs.values()))
    m = any_run["machine"]
    lines = [
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['system']}, Python {m['python']}; "
        f"seed {any_run['seed']}. Per controller:",
        "",
        *provenance(runs),
        "",
        "| Robot | Set | Controller | Success | Start (median) | Final error of successes "
        "(median / max) | Steps (median) | Servo step, CPU (median / p95) | Ends |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in result["cells"]:
        lines.append(
            f"| {c['robot']} | {c['set']} | {c['controller']} | {c['successes']}/{c['runs']} | "
            f"{c['start_mm_median']:.0f} mm, {c['start_deg_median']:.1f} deg | "
            f"{fmt(c['final_mm_median'], 2)} / {fmt(c['final_mm_max'], 2)} mm, "
            f"{fmt(c['final_deg_median'], 2)} / {fmt(c['final_deg_max'], 2)} deg | "
            f"{fmt(c['steps_median'], 0)} | {fmt(c['step_cpu_ms_median'], 1)} / "
            f"{fmt(c['step_cpu_ms_p95'], 1)} ms | {ends(c)} |"
        )
    lines += [
        "",
        "Start by start (`o`: within 5 mm and 1 degree at the end, `.`: not; start 0 first):",
        "",
        "| Robot | Set | " + " | ".join(CONTROLLERS) + " |",
        "|---|---|" + "---|" * len(CONTROLLERS),
    ]
    for robot in ROBOTS:
        for name in SETS:
            if not any((robot, name, label) in runs for label in CONTROLLERS):
                continue
            cells = [
                f"`{outcome_string(runs[robot, name, label])}`"
                if (robot, name, label) in runs
                else "-"
                for label in CONTROLLERS
            ]
            lines.append(f"| {robot} | {name} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "The spectral servo against each peer, start by start (target: on every set the "
        "spectral servo's successes include the peer's; on the large and extreme sets, "
        "strictly more):",
        "",
        "| Robot | Set | Peer | Spectral / peer successes | Peer's starts the spectral servo "
        "misses | Spectral's starts the peer misses | Includes | Strictly more |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in result["comparisons"]:
        target = c["strictly_more"] if c["set"] in ("large", "extreme") else c["includes"]
        lines.append(
            f"| {c['robot']} | {c['set']} | {c['peer']} | {c['spectral_successes']} / "
            f"{c['peer_successes']} of {c['starts']} | "
            f"{', '.join(map(str, c['peer_only'])) or '-'} | "
            f"{', '.join(map(str, c['spectral_only'])) or '-'} | "
            f"{'yes' if c['includes'] else '**no**'} | "
            f"{'yes' if c['strictly_more'] else 'no'}{'' if target else ' (target missed)'} |"
        )
    return "\n".join(lines)


def servoing_summary(result: dict) -> str:
    """The short table of docs/servoing.md: successes per robot, set and controller."""
    labels = [
        label for label in CONTROLLERS if any(c["controller"] == label for c in result["cells"])
    ]
    lines = [
        "| Robot | Set | " + " | ".join(labels) + " |",
        "|---|---|" + "---|" * len(labels),
    ]
    for robot in ROBOTS:
        for name in SETS:
            by = {
                c["controller"]: c
                for c in result["cells"]
                if c["robot"] == robot and c["set"] == name
            }
            if not by:
                continue
            lines.append(
                f"| {robot} | {name} | "
                + " | ".join(
                    f"{by[label]['successes']}/{by[label]['runs']}" if label in by else "-"
                    for label in labels
                )
                + " |"
            )
    return "\n".join(lines)


# --- Figures -------------------------------------------------------------------------------

_SET_MARKERS = {"moderate": "o", "large": "s", "extreme": "D"}


def plot_domain(runs: dict[tuple[str, str, str], dict], path: Path) -> None:
    """The convergence domain: every start's camera displacement (mm) and rotation (deg),
    filled when the controller brought it back, one panel per controller and robot."""
    from spectral_vs.plotting import _new_figure

    labels = [label for label in CONTROLLERS if any(k[2] == label for k in runs)]
    robots = [robot for robot in ROBOTS if any(k[0] == robot for k in runs)]
    figure = _new_figure(3.6 * len(labels), 3.5 * len(robots) + 0.6)
    axes = np.atleast_2d(figure.subplots(len(robots), len(labels), squeeze=False))
    for row, robot in enumerate(robots):
        for column, label in enumerate(labels):
            axis = axes[row, column]
            ok = fail = 0
            for name in SETS:
                data = runs.get((robot, name, label))
                if data is None:
                    continue
                for r in data["records"]:
                    marker = _SET_MARKERS[name]
                    if r["success"]:
                        ok += 1
                        axis.scatter(
                            r["start_mm"],
                            r["start_deg"],
                            marker=marker,
                            s=26,
                            color="tab:green",
                            edgecolor="darkgreen",
                            linewidth=0.6,
                            zorder=3,
                        )
                    else:
                        fail += 1
                        axis.scatter(
                            r["start_mm"],
                            r["start_deg"],
                            marker=marker,
                            s=26,
                            facecolor="none",
                            edgecolor="tab:red",
                            linewidth=1.0,
                            zorder=2,
                        )
            for x, y in ((200, 30), (450, 60), (600, 90)):
                axis.plot([0, x, x], [y, y, 0], color="0.6", linestyle=":", linewidth=0.9)
            axis.set_xlim(0, 620)
            axis.set_ylim(0, 92)
            axis.grid(True, alpha=0.25)
            axis.set_title(f"{label}, {robot}: {ok}/{ok + fail}", fontsize="medium")
            if row == len(robots) - 1:
                axis.set_xlabel("start: camera displacement (mm)")
            if column == 0:
                axis.set_ylabel("start: camera rotation (deg)")
    handles = [
        axes[0, 0].scatter([], [], marker=m, color="0.4", label=f"{name} start")
        for name, m in _SET_MARKERS.items()
    ]
    handles += [
        axes[0, 0].scatter([], [], marker="o", color="tab:green", label="brought back"),
        axes[0, 0].scatter([], [], marker="o", facecolor="none", edgecolor="tab:red", label="not"),
    ]
    figure.legend(handles=handles, loc="outside lower center", ncol=len(handles))
    figure.suptitle(
        "Convergence domain: success (within 5 mm and 1 deg after at most 150 steps) against "
        "the start's displacement; dotted: the set boundaries"
    )
    figure.savefig(path)


def plot_step_times(runs: dict[tuple[str, str, str], dict], path: Path) -> None:
    """Distribution (CDF) of the servo step's CPU time, every step of every run, one panel
    per set: the spectral servo on both robots, the peers on the iiwa for context."""
    from spectral_vs.plotting import _new_figure

    sets = [name for name in SETS if any(k[1] == name for k in runs)]
    figure = _new_figure(5.2 * len(sets), 4.4)
    axes = np.atleast_1d(figure.subplots(1, len(sets), squeeze=False)[0])
    styles = {
        (SPECTRAL, "iiwa"): ("tab:blue", "-", 2.2),
        (SPECTRAL, "panda"): ("tab:cyan", "-", 2.2),
        ("dense depth", "iiwa"): ("tab:purple", "--", 1.2),
        ("ICP-PBVS", "iiwa"): ("tab:orange", "--", 1.2),
        ("ICP-PBVS warm", "iiwa"): ("tab:brown", "--", 1.2),
        ("FPFH-PBVS", "iiwa"): ("tab:gray", "--", 1.2),
    }
    for axis, name in zip(axes, sets, strict=True):
        for (label, robot), (color, style, width) in styles.items():
            data = runs.get((robot, name, label))
            if data is None:
                continue
            cpu = np.sort([s for r in data["records"] for s in r["step_cpu_ms"]])
            if cpu.size == 0:
                continue
            y = np.arange(1, cpu.size + 1) / cpu.size
            median, p95 = np.percentile(cpu, [50, 95])
            axis.step(
                np.maximum(cpu, 0.05),
                100 * y,
                where="post",
                color=color,
                linestyle=style,
                linewidth=width,
                label=f"{label}, {robot}: {median:.1f} / {p95:.1f} ms",
            )
        targets = report_lib.SERVO_STEP_TARGETS_MS
        for value, text in zip(targets, ("median target", "p95 target"), strict=True):
            axis.axvline(value, color="tab:red", linestyle=":", linewidth=1.2)
            axis.text(value * 1.05, 3, text, color="tab:red", rotation=90, fontsize="small")
        axis.axhline(50, color="0.7", linewidth=0.8)
        axis.axhline(95, color="0.7", linewidth=0.8)
        axis.set_xscale("log")
        axis.set_ylim(0, 101)
        axis.set_xlabel("servo step, CPU time (ms, one thread, log scale)")
        axis.set_ylabel("steps at most that long (%)")
        axis.set_title(f"{name} starts")
        axis.grid(True, which="both", alpha=0.25)
        axis.legend(
            fontsize="x-small", loc="lower right", title="median / p95", title_fontsize="x-small"
        )
    figure.suptitle(
        "Servo step times: every step of every run (the controller's step_record; "
        "rendering and capture excluded)"
    )
    figure.savefig(path)


def write_report() -> dict:
    runs = load_runs()
    if not runs:
        raise SystemExit(f"no run files in {RUNS}: run the benchmark first")
    result = joined(runs)
    RESULTS.write_text(
        json.dumps(
            {
                "command": "python benchmarks/servo_peers.py --report-only",
                "runs": sorted(str(run_file(*k).relative_to(ROOT)) for k in runs),
            }
            | result,
            indent=1,
        )
        + "\n"
    )
    text = markdown(runs, result)
    if not replace_block(BENCHMARKS_DOC, "servo-peers", text):
        print(f"no servo-peers block in {BENCHMARKS_DOC}: table not written there")
    if not replace_block(SERVOING_DOC, "servo-peers-summary", servoing_summary(result)):
        print(f"no servo-peers-summary block in {SERVOING_DOC}: table not written there")
    FIGURES.mkdir(parents=True, exist_ok=True)
    plot_domain(runs, FIGURES / "servo_domain.png")
    plot_step_times(runs, FIGURES / "servo_step_times.png")
    print(text)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=20, help="starts per set (default 20)")
    parser.add_argument("--robots", default=",".join(ROBOTS), help="default: iiwa,panda")
    parser.add_argument("--sets", default=",".join(SETS), help="default: every set")
    parser.add_argument(
        "--controllers", default=",".join(CONTROLLERS), help="controllers (default: all)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="1 start per set, write nothing")
    parser.add_argument(
        "--report-only", action="store_true", help="join the run files: tables and figures"
    )
    args = parser.parse_args()
    if args.starts < 1:
        parser.error(f"--starts must be >= 1, got {args.starts}")
    if args.report_only:
        write_report()
        return
    run(args, parser)


if __name__ == "__main__":
    main()
