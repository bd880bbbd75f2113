"""Servoing against other controllers: the spectral servo, the dense depth-map servo and
position-based servoing on Open3D's registration, from the same start poses.

The simulated iiwa of benchmarks/servo_experiment.py (kinematic mode, 320 x 240 depth
images, reference at ``sim.HOME_Q``, control period 0.1 s, at most 100 steps, a joint at
its limit clamped while the others carry on; success: final camera pose within 5 mm and
1 degree of the reference pose, ground truth from PyBullet). Start sets: ``moderate`` and
``large`` are the experiment's own (``servo_experiment.starts``, same seed, so the first N
starts are the experiment's first N); ``small`` is added here, under 50 mm and 5 degrees
(joints within +-0.1 rad).

Controllers (``CONTROLLERS``):

* ``spectral``: ``SpectralServo(ServoParams())``, the paper's one iteration per step;
* ``spectral pose+warm``: ``ServoParams(mode="pose", warm_start=True)``;
* ``dense depth``: ``baselines.DenseDepthServo``, Teuliere and Marchand's depth-map servo
  (Gauss-Newton, interaction matrix at the current depth map) on the raw depth images;
* ``ICP-PBVS``: Open3D point-to-plane ICP from the identity every step, then the PBVS law;
* ``ICP-PBVS warm``: the same ICP started from the previous estimate carried along the
  measured camera motion;
* ``FPFH-PBVS``: Open3D FPFH + RANSAC + point-to-plane ICP every step.

Every registration-based controller downsamples at 15 mm and uses the PBVS law, gains and
speed limits of ``ServoParams``; every one runs on one thread (``OMP_NUM_THREADS=1``
before Open3D loads). Writes ``benchmarks/results/servo_peers.json``,
``docs/figures/servo_peers.png`` and the block ``servo-peers`` of docs/benchmarks.md.
Usage::

    python benchmarks/servo_peers.py               # 10 starts per set, about 35 min
    python benchmarks/servo_peers.py --starts 4    # fewer starts
    python benchmarks/servo_peers.py --quick       # 1 start per set, writes nothing
    python benchmarks/servo_peers.py --report-only # figure and tables from the JSON

Needs pybullet, open3d (the ``bench`` extra) and matplotlib.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import servo_experiment as experiment
from report import BENCHMARKS_DOC, replace_block

from spectral_vs import baselines, sim
from spectral_vs import servo as servo_lib

# Open3D is imported later (baselines.open3d_module); its thread count is fixed then.
os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread, like ours
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "servo_peers.json"
FIGURE = ROOT / "docs" / "figures" / "servo_peers.png"

#: The small set, added here: joint perturbation (rad) and accepted camera displacement.
SMALL = {"joint_range": 0.1, "translation": (0.0, 0.05), "rotation_deg": (0.0, 5.0)}
SETS = ("small", "moderate", "large")
#: Bins of the start rotation (degrees) and translation (mm) for success rates.
ROTATION_BINS = (0.0, 5.0, 10.0, 20.0, 30.0, 40.0, 60.0)
TRANSLATION_BINS = (0.0, 50.0, 100.0, 200.0, 300.0, 450.0)


def _spectral(**fields: Any) -> Callable[..., Any]:
    return lambda cloud, depth, intrinsics: servo_lib.SpectralServo(
        cloud, servo_lib.ServoParams(**fields)
    )


def _registration(**fields: Any) -> Callable[..., Any]:
    return lambda cloud, depth, intrinsics: baselines.RegistrationServo(
        cloud, baselines.RegistrationServoParams(**fields)
    )


#: label -> (factory(reference cloud, reference depth image, intrinsics), uses depth images)
CONTROLLERS: dict[str, tuple[Callable[..., Any], bool]] = {
    "spectral": (_spectral(), False),
    "spectral pose+warm": (_spectral(mode="pose", warm_start=True), False),
    "dense depth": (
        lambda cloud, depth, intrinsics: baselines.DenseDepthServo(depth, intrinsics),
        True,
    ),
    "ICP-PBVS": (_registration(method="icp"), False),
    "ICP-PBVS warm": (_registration(method="icp", warm_start=True), False),
    "FPFH-PBVS": (_registration(method="fpfh"), False),
}


def small_starts(kinematics: Any, count: int, seed: int) -> list[dict]:
    """``count`` seeded starts of the small set (a seed stream apart from the others)."""
    rng = np.random.default_rng([seed, 100])
    out = []
    for _ in range(count):
        q, t, r = servo_lib.random_start(
            kinematics,
            np.asarray(sim.HOME_Q),
            rng,
            joint_range=SMALL["joint_range"],
            translation_range=SMALL["translation"],
            rotation_range=tuple(math.radians(a) for a in SMALL["rotation_deg"]),
        )
        out.append({"q": q.tolist(), "start_mm": 1000 * t, "start_deg": math.degrees(r)})
    return out


def set_starts(kinematics: Any, name: str, count: int, seed: int) -> list[dict]:
    if name == "small":
        return small_starts(kinematics, count, seed)
    return experiment.starts(kinematics, name, count, seed)


def run_one(
    robot: sim.PyBulletRobot,
    references: tuple[Any, np.ndarray],
    T_world_reference: np.ndarray,
    start: dict,
    label: str,
) -> dict:
    factory, uses_depth = CONTROLLERS[label]
    controller = factory(references[0], references[1], robot.params.camera.intrinsics)
    driven = baselines.DepthImageRobot(robot) if uses_depth else None
    row, log = experiment.servo_run(robot, start, controller, T_world_reference, driven)
    return (
        {"controller": label}
        | row
        | {
            "false_convergence": bool(log.reason == "converged" and not row["success"]),
            "step_wall_ms": 1000 * log.wall_seconds / len(log.records),
            "servo_step_ms_median": 1000 * float(np.median(log.array("seconds"))),
        }
    )


# --- Tables ------------------------------------------------------------------------------


def summarize(rows: list[dict], controllers: list[str]) -> list[dict]:
    """Per (set, controller): successes, errors of the successes, steps, times, ends."""
    return [
        {"set": name, "controller": label}
        | experiment.outcomes(cell)
        | {
            "servo_step_ms_median": experiment.median(cell, "servo_step_ms_median"),
            "step_wall_ms_median": experiment.median(cell, "step_wall_ms"),
        }
        for name, label, cell in experiment.groups(rows, SETS, "controller", controllers)
    ]


def binned(rows: list[dict], key: str, edges: tuple[float, ...], label: str) -> list[str]:
    """Successes / runs of one controller per bin of the start displacement ``key``."""
    out = []
    for low, high in itertools.pairwise(edges):
        cell = [r for r in rows if r["controller"] == label and low <= r[key] < high]
        out.append(f"{sum(r['success'] for r in cell)}/{len(cell)}" if cell else "-")
    return out


def markdown(results: dict) -> str:
    fmt = experiment.fmt
    settings = results["settings"]
    lines = [
        f"Machine: {results['machine']['cpu']}, {results['machine']['cores']} cores, "
        f"{results['machine']['system']}; commit {results['machine']['commit']}, core "
        f"{results['machine']['core_sha256']}; {results['date']}; "
        f"{settings['starts_per_set']} starts per set; {results['runtime_s'] / 60:.0f} min.",
        "",
        f"| Set | Controller | Success | {experiment.OUTCOME_HEADER} | Servo step "
        "| Loop step | Ends |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in results["summary"]:
        lines.append(
            f"| {c['set']} | {c['controller']} | {c['successes']}/{c['runs']} | "
            f"{experiment.outcome_cells(c)} | {fmt(c['servo_step_ms_median'], 0)} ms | "
            f"{fmt(c['step_wall_ms_median'], 0)} ms | {experiment.ends(c)} |"
        )
    rows, controllers = results["records"], settings["controllers"]
    for key, edges, unit, title in (
        ("start_deg", ROTATION_BINS, "deg", "start rotation"),
        ("start_mm", TRANSLATION_BINS, "mm", "start translation"),
    ):
        bins = [f"{a:g}-{b:g} {unit}" for a, b in itertools.pairwise(edges)]
        counts = [
            sum(1 for r in rows if r["controller"] == controllers[0] and a <= r[key] < b)
            for a, b in itertools.pairwise(edges)
        ]
        lines += [
            "",
            f"Successes by {title} (all sets; starts per bin: "
            + ", ".join(f"{b} {n}" for b, n in zip(bins, counts, strict=True))
            + "):",
            "",
            "| Controller | " + " | ".join(bins) + " |",
            "|---|" + "---|" * len(bins),
        ]
        for label in controllers:
            lines.append(f"| {label} | " + " | ".join(binned(rows, key, edges, label)) + " |")
    return "\n".join(lines)


# --- Figure ------------------------------------------------------------------------------


def plot(results: dict, path: Path) -> None:
    """Success rate against the start's rotation and translation, one line per controller,
    and the median servo step time."""
    from spectral_vs.plotting import _new_figure

    rows, controllers = results["records"], results["settings"]["controllers"]
    figure = _new_figure(15.0, 4.4)
    axes = figure.subplots(1, 3)
    markers = "osD^vx"
    for axis, (key, edges, xlabel) in zip(
        axes[:2],
        (
            ("start_deg", ROTATION_BINS, "start: camera rotation (deg)"),
            ("start_mm", TRANSLATION_BINS, "start: camera displacement (mm)"),
        ),
        strict=True,
    ):
        centres = [(a + b) / 2 for a, b in itertools.pairwise(edges)]
        for index, label in enumerate(controllers):
            xs, ys = [], []
            for centre, low, high in zip(centres, edges[:-1], edges[1:], strict=True):
                cell = [r for r in rows if r["controller"] == label and low <= r[key] < high]
                if cell:
                    xs.append(centre)
                    ys.append(100 * sum(r["success"] for r in cell) / len(cell))
            axis.plot(xs, ys, marker=markers[index % len(markers)], label=label)
        for edge in edges:
            axis.axvline(edge, color="0.85", linewidth=0.8, zorder=0)
        axis.set_xlabel(xlabel)
        axis.set_ylabel("success (%)")
        axis.set_ylim(-5, 105)
        axis.grid(True, axis="y", alpha=0.3)
    axes[0].set_title("convergence domain: success by start rotation")
    axes[1].set_title("success by start displacement")
    axes[0].legend(fontsize="small", loc="lower left")
    times = [
        float(np.median([r["servo_step_ms_median"] for r in rows if r["controller"] == label]))
        for label in controllers
    ]
    axes[2].barh(range(len(controllers)), times, color="tab:gray")
    axes[2].set_yticks(range(len(controllers)), controllers)
    axes[2].invert_yaxis()
    axes[2].set_xscale("log")
    axes[2].set_xlabel("servo step, median (ms, one thread)")
    axes[2].set_title("processing time per step")
    for y, value in enumerate(times):
        axes[2].text(value, y, f" {value:.0f} ms", va="center", fontsize="small")
    figure.suptitle(
        f"Servoing the simulated iiwa back to the reference view: "
        f"{results['settings']['starts_per_set']} starts per set (small, moderate, large)"
    )
    figure.savefig(path)


# --- Main --------------------------------------------------------------------------------


def main() -> None:
    parser = experiment.new_parser(__doc__.splitlines()[0], 10, SETS, 1, "figure, tables")
    parser.add_argument(
        "--controllers", default=",".join(CONTROLLERS), help="controllers (default: all)"
    )
    args = parser.parse_args()

    if args.report_only:
        results = json.loads(RESULTS.read_text())
        write(results)
        print(markdown(results))
        return
    o3d = baselines.open3d_module()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)

    count = 1 if args.quick else args.starts
    sets = [s for s in args.sets.split(",") if s]
    controllers = [c for c in args.controllers.split(",") if c]
    for name in controllers:
        if name not in CONTROLLERS:
            parser.error(f"unknown controller {name!r}; choose from {list(CONTROLLERS)}")
    started = time.perf_counter()
    load_before = os.getloadavg()[0]
    params = experiment.sim_params()
    rows: list[dict] = []
    results: dict[str, Any] = {}
    with sim.PyBulletRobot(params) as robot:
        references = (robot.capture(), robot.capture_depth())
        T_world_reference = robot.camera_pose()
        for name in sets:
            for index, start in enumerate(set_starts(robot.kinematics, name, count, args.seed)):
                for label in controllers:
                    row = run_one(robot, references, T_world_reference, start, label)
                    row |= {"set": name, "index": index, "q_start": start["q"]}
                    rows.append(row)
                    print(
                        experiment.progress(name, index, label, 18, row)
                        + f", servo {row['servo_step_ms_median']:5.0f} ms",
                        flush=True,
                    )
                results = {
                    "command": "python benchmarks/servo_peers.py " + " ".join(sys.argv[1:]),
                    "date": time.strftime("%Y-%m-%d"),
                    "machine": experiment.machine() | {"load_average_at_start": load_before},
                    "settings": experiment.loop_settings()
                    | {
                        "starts_per_set": count,
                        "sets": {
                            "small": SMALL,
                            **{k: servo_lib.START_SETS[k] for k in sets if k != "small"},
                        },
                        "controllers": controllers,
                        "threads": os.environ.get("OMP_NUM_THREADS"),
                        "registration_params": {
                            k: v
                            for k, v in baselines.RegistrationServoParams().__dict__.items()
                            if k != "method"
                        },
                        "depth_params": dict(baselines.DepthServoParams().__dict__),
                    },
                    "runtime_s": time.perf_counter() - started,
                    "summary": summarize(rows, controllers),
                    "records": rows,
                }
                if not args.quick:  # after every start: a crash keeps what was measured
                    RESULTS.parent.mkdir(parents=True, exist_ok=True)
                    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    print(markdown(results))
    print(f"total {results['runtime_s']:.0f} s")
    if not args.quick:
        write(results)


def write(results: dict) -> None:
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    plot(results, FIGURE)
    text = markdown(results)
    if not replace_block(BENCHMARKS_DOC, "servo-peers", text):
        print(f"no servo-peers block in {BENCHMARKS_DOC}: table not written there")


if __name__ == "__main__":
    main()
