"""Servo runs drawn in docs/servoing.md: the sensor faults, and the Panda.

Faults (``docs/figures/servo_faults.png``): the simulated iiwa of ``spectral-vs servo-sim``
(kinematic, 320 x 240, control period 0.1 s, default ``ServoParams``) servoes back from
moderate start ``--start`` (seed 0) once without a fault and once through each wrapper of
``spectral_vs.sim.faults``, the fault set ``FAULT_AT`` seconds into the run, once the
servo has locked on:

* ``dropped frames``: ``DroppedFrames``, captures 20, 25 and 30 come back empty;
* ``0.3 s burst``: ``Outage(2.0, 0.3)``, every capture empty for 0.3 s;
* ``repeated frames``: ``RepeatedFrames``, captures 20, 25 and 30 repeat the one before;
* ``box for 1 s``: ``HandOccluder(2.0, 1.0)``, a 9 cm box 25 cm in front of the camera;
* ``outage for good``: ``Outage(2.0, inf)``, the camera lost: the servo must stop.

Panda (``docs/figures/servo_panda.png``): the Panda preset from large start
``--panda-start`` (seed 0), the layout of the paper's Fig. 6 (``plotting.plot_servo``); and
both presets at home seen from beside the table (``docs/figures/servo_robots.png``).

Writes ``benchmarks/results/servo_episodes.json`` (per run: how it ended, the final
error, the held steps and why, the true error of every step). Usage::

    python benchmarks/servo_episodes.py                # about 2 min
    python benchmarks/servo_episodes.py --report-only  # the figures from the JSON

Needs pybullet and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import servo_peers as peers

from spectral_vs import experiment, sim
from spectral_vs import servo as servo_lib
from spectral_vs.plotting import plot_servo
from spectral_vs.sim import faults

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "servo_episodes.json"
FIGURES = ROOT / "docs" / "figures"
FAULT_AT = 2.0  # s: when each fault begins (the servo has locked on by then)
FAULT_CAPTURES = (20, 25, 30)  # capture indices of the single faults (2.0, 2.5, 3.0 s)

#: label -> (wrapper factory, the fault's window on the run's clock, s, or None)
FAULTS: dict[str, tuple[Any, tuple[float, float] | None]] = {
    "no fault": (lambda robot: robot, None),
    "dropped frames (captures 20, 25, 30)": (
        lambda robot: faults.DroppedFrames(robot, FAULT_CAPTURES),
        None,
    ),
    "0.3 s burst of dropped frames": (
        lambda robot: faults.Outage(robot, FAULT_AT, 0.3),
        (FAULT_AT, FAULT_AT + 0.3),
    ),
    "repeated frames (captures 20, 25, 30)": (
        lambda robot: faults.RepeatedFrames(robot, FAULT_CAPTURES),
        None,
    ),
    "9 cm box 25 cm in front of the camera for 1 s": (
        lambda robot: faults.HandOccluder(robot, FAULT_AT, 1.0),
        (FAULT_AT, FAULT_AT + 1.0),
    ),
    "camera lost for good": (
        lambda robot: faults.Outage(robot, FAULT_AT, math.inf),
        (FAULT_AT, math.inf),
    ),
}


def record(log: servo_lib.ServoLog, robot: sim.PyBulletRobot, T_reference: np.ndarray) -> dict:
    t, r = servo_lib.pose_error(np.linalg.inv(robot.camera_pose()) @ T_reference)
    errors = experiment.true_errors(log, T_reference)
    return {
        "reason": log.reason,
        "message": log.status.message,
        "final_mm": 1000 * t,
        "final_deg": math.degrees(r),
        "success": bool(1000 * t < peers.SUCCESS_MM and math.degrees(r) < peers.SUCCESS_DEG),
        "steps": len(log.records),
        "time_s": [round(x.time, 3) for x in log.records],
        "hold": [x.hold for x in log.records],
        "occluded_points": [int(x.occluded_points) for x in log.records],
        "true_mm": np.round(errors[:, 0], 3).tolist(),
        "true_deg": np.round(errors[:, 1], 4).tolist(),
    }


def run_faults(start_index: int) -> dict:
    out: dict[str, Any] = {}
    with sim.PyBulletRobot(peers.sim_params("iiwa")) as robot:
        reference = robot.capture()
        T_reference = robot.camera_pose()
        start = peers.starts(robot, "moderate", start_index + 1, 0)[start_index]
        out["start"] = {k: start[k] for k in ("start_mm", "start_deg")} | {"index": start_index}
        for label, (wrap, window) in FAULTS.items():
            log, faulty = experiment.servo_from(
                robot,
                start["q"],
                reference,
                wrap=wrap,
                dt=peers.DT,
                max_steps=peers.MAX_STEPS,
                stop_at_joint_limit=False,
            )
            if isinstance(faulty, faults.HandOccluder):
                faulty.remove()
            row = record(log, robot, T_reference) | {
                "window_s": None if window is None else [window[0], min(window[1], 1e9)],
                "spoiled_captures": list(getattr(faulty, "faults", [])),
            }
            out[label] = row
            holds = [h for h in row["hold"] if h]
            print(
                f"{label:48s} {row['reason']:14s} {row['final_mm']:6.2f} mm "
                f"{row['final_deg']:5.2f} deg, {row['steps']} steps, held {len(holds)} "
                f"({', '.join(sorted(set(holds)))})",
                flush=True,
            )
    return out


def run_panda(start_index: int) -> tuple[dict, Any]:
    with sim.PyBulletRobot(peers.sim_params("panda")) as robot:
        reference = robot.capture()
        T_reference = robot.camera_pose()
        start = peers.starts(robot, "large", start_index + 1, 0)[start_index]
        log, recorder = experiment.servo_from(
            robot,
            start["q"],
            reference,
            wrap=experiment.CloudRecorder,
            dt=peers.DT,
            max_steps=peers.MAX_STEPS,
            stop_at_joint_limit=False,
        )
        row = record(log, robot, T_reference) | {
            "start": {k: start[k] for k in ("start_mm", "start_deg")} | {"index": start_index}
        }
        print(f"panda large #{start_index}: {row['reason']} {row['final_mm']:.2f} mm", flush=True)
        path = FIGURES / "servo_panda.png"
        plot_servo(
            log,
            T_reference,
            path,
            reference=reference,
            clouds=dict(enumerate(recorder.clouds)),
            title=f"The Panda from large start {start_index} ({start['start_mm']:.0f} mm, "
            f"{start['start_deg']:.0f} deg): {log.reason} after {len(log.records)} steps, "
            f"{row['final_mm']:.2f} mm and {row['final_deg']:.2f} deg off",
        )
    return row, log


def render_robots(path: Path) -> None:
    """Both presets at home, rendered from beside the table (PyBullet's TinyRenderer)."""
    from spectral_vs.plotting import _new_figure

    figure = _new_figure(11.0, 4.4)
    axes = figure.subplots(1, 2)
    for axis, name in zip(axes, peers.ROBOTS, strict=True):
        with sim.PyBulletRobot(peers.sim_params(name)) as robot:
            client = robot.client
            view = client.computeViewMatrix(
                cameraEyePosition=[1.75, -1.45, 1.25],
                cameraTargetPosition=[0.35, 0.0, 0.38],
                cameraUpVector=[0, 0, 1],
            )
            projection = client.computeProjectionMatrixFOV(
                fov=45, aspect=4 / 3, nearVal=0.05, farVal=6.0
            )
            image = client.getCameraImage(
                640,
                480,
                viewMatrix=view,
                projectionMatrix=projection,
                renderer=client.ER_TINY_RENDERER,
            )
            rgb = np.reshape(np.asarray(image[2], dtype=np.uint8), (480, 640, 4))[:, :, :3]
            axis.imshow(rgb)
            axis.set_axis_off()
            model = robot.params.robot
            axis.set_title(
                f"{name}: {model.urdf_path.parent.name}/{model.urdf_path.name}, "
                f"{len(model.home_q)} joints, at home",
                fontsize="medium",
            )
    figure.suptitle("The two presets at home: the wrist camera 0.55 m above the same table")
    figure.savefig(path)


def plot_faults(results: dict, path: Path) -> None:
    """True error over time of every fault run, the fault's window shaded, held steps marked."""
    from spectral_vs.plotting import _new_figure

    labels = [k for k in FAULTS if k in results]
    figure = _new_figure(12.0, 2.0 * len(labels) + 0.8)
    axes = figure.subplots(len(labels), 2, sharex=True, squeeze=False)
    colors = {
        "empty_cloud": "tab:red",
        "stale_frame": "tab:purple",
        "occluded": "tab:orange",
        "too_few_points": "tab:brown",
    }
    for row, label in enumerate(labels):
        run = results[label]
        t = np.asarray(run["time_s"])
        for column, (key, unit, limit) in enumerate(
            (
                ("true_mm", "error (mm)", peers.SUCCESS_MM),
                ("true_deg", "error (deg)", peers.SUCCESS_DEG),
            )
        ):
            axis = axes[row, column]
            values = np.maximum(np.asarray(run[key]), 1e-3)
            axis.plot(t, values, color="tab:blue", linewidth=1.4)
            if run["window_s"] is not None:
                a, b = run["window_s"]
                axis.axvspan(a, min(b, t[-1] + 0.1), color="0.85", zorder=0)
            for hold, color in colors.items():
                chosen = [i for i, h in enumerate(run["hold"]) if h == hold]
                if chosen:
                    axis.scatter(
                        t[chosen],
                        values[chosen],
                        color=color,
                        s=18,
                        zorder=3,
                        label=f"held: {hold}",
                    )
            found = [i for i, n in enumerate(run.get("occluded_points", [])) if n > 0]
            if found:
                axis.scatter(
                    t[found],
                    values[found],
                    marker="^",
                    color="tab:orange",
                    s=22,
                    zorder=3,
                    label="occluder found, its points dropped",
                )
            axis.axhline(limit, color="tab:red", linestyle="--", linewidth=0.9)
            axis.set_yscale("log")
            axis.set_ylabel(unit)
            axis.grid(True, which="both", alpha=0.25)
            if column == 0:
                axis.set_title(
                    f"{label}: {run['reason']} after {run['steps']} steps, "
                    f"{run['final_mm']:.2f} mm, {run['final_deg']:.2f} deg",
                    fontsize="medium",
                    loc="left",
                )
            if any(run["hold"]) or found:
                axis.legend(fontsize="x-small", loc="upper right")
    for axis in axes[-1]:
        axis.set_xlabel("time since the start (s, robot clock)")
    start = results["start"]
    figure.suptitle(
        f"Sensor faults: the iiwa from moderate start {start['index']} "
        f"({start['start_mm']:.0f} mm, {start['start_deg']:.0f} deg); grey: the fault's "
        "window; dots: held steps (zero twist); dashed: 5 mm / 1 deg"
    )
    figure.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--start", type=int, default=0, help="moderate iiwa start (default 0)")
    parser.add_argument("--panda-start", type=int, default=0, help="large Panda start (default 0)")
    parser.add_argument("--report-only", action="store_true", help="the figures from the JSON")
    args = parser.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)
    if args.report_only:
        results = json.loads(RESULTS.read_text())
        plot_faults(results["faults"], FIGURES / "servo_faults.png")
        render_robots(FIGURES / "servo_robots.png")
        return
    started = time.perf_counter()
    fault_runs = run_faults(args.start)
    plot_faults(fault_runs, FIGURES / "servo_faults.png")
    panda, _ = run_panda(args.panda_start)
    render_robots(FIGURES / "servo_robots.png")
    RESULTS.write_text(
        json.dumps(
            {
                "command": "python benchmarks/servo_episodes.py " + " ".join(sys.argv[1:]),
                "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                "machine": peers.report_lib_machine(),
                "runtime_s": time.perf_counter() - started,
                "faults": fault_runs,
                "panda": panda,
            }
        )
        + "\n"
    )


if __name__ == "__main__":
    main()
