"""``spectral-vs servo-sim``: the paper's robot experiment in the PyBullet simulation."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from spectral_vs.cli.common import (
    MAX_SERVO_ERROR_DEG,
    MAX_SERVO_ERROR_MM,
    InputError,
    _count,
    _plotting,
    _positive_float,
    _positive_int,
    _seed,
)


def add_parser(commands: Any, formatter: Any) -> None:
    """Add the subcommand to ``commands``, the parser's subparsers."""
    servo = commands.add_parser(
        "servo-sim",
        aliases=["servo-demo"],
        help="servo a simulated robot arm's camera back to a reference pose (needs pybullet)",
        description="The paper's robot experiment in PyBullet: capture the reference cloud at "
        "the home pose, move every joint of the arm (--robot) to seeded random starts, then "
        "servo the wrist camera back with spectral_vs.servo, printing every step (one start) "
        "or one line per start, and the final error against the simulation's ground truth. Writes "
        "servo.png (errors over time, camera path, clouds over the reference; servo_<i>.png "
        "for several starts) to --out. Exit code 1 when a final error exceeds "
        f"{MAX_SERVO_ERROR_MM:g} mm or {MAX_SERVO_ERROR_DEG:g} degree.",
    )
    _add_start_arguments(servo)
    _add_servo_arguments(servo)
    _add_output_arguments(servo)
    servo.set_defaults(run=run_servo_sim)


def _add_start_arguments(servo: Any) -> None:
    """The arm and its start poses: --seed to --set."""
    servo.add_argument(
        "--seed", type=_seed, default=0, help="seed of the start poses, in [0, 2**32) (default: 0)"
    )
    servo.add_argument(
        "--starts",
        type=_positive_int,
        default=1,
        metavar="N",
        help="random start poses (default: 1)",
    )
    servo.add_argument(
        "--robot",
        choices=["iiwa", "panda"],  # the keys of sim.ROBOT_MODELS (test_cli checks)
        default="iiwa",
        help="the arm: KUKA LBR iiwa (default) or Franka Emika Panda, both with the camera "
        "0.55 m above the table at home",
    )
    servo.add_argument(
        "--set",
        choices=["moderate", "large", "extreme"],  # the keys of experiment.START_SETS
        default="moderate",
        help="starts under 0.2 m and 30 deg away (moderate, default), beyond that up to "
        "0.45 m and 60 deg (large), or beyond that up to 0.6 m and 90 deg with at least 30%% "
        "of the reference still in view and the camera above the table (extreme)",
    )


def _add_servo_arguments(servo: Any) -> None:
    """The servo and the simulation: --mode to --stop-at-joint-limits."""
    servo.add_argument(
        "--mode",
        choices=["iteration", "pose"],
        default="iteration",
        help="one update of Algorithm 1 per step (the paper, default) or a full "
        "registration per step",
    )
    servo.add_argument(
        "--warm-start",
        action="store_true",
        help="start each registration from the previous estimate moved by the camera's "
        "measured motion (the most robust with --mode pose)",
    )
    servo.add_argument(
        "--sim-mode",
        choices=["kinematic", "dynamic"],
        default="kinematic",
        help="joints integrate the command exactly (default) or PyBullet's torque-limited "
        "velocity motors under gravity",
    )
    servo.add_argument(
        "--noise",
        action="store_true",
        help="Kinect-like depth noise (0.5 mm + 1.9 mm/m^2 z^2, 2%% missing pixels)",
    )
    servo.add_argument(
        "--dt", type=_positive_float, default=0.1, metavar="S", help="control period, s"
    )
    servo.add_argument(
        "--max-steps", type=_positive_int, default=150, metavar="N", help="step budget per start"
    )
    servo.add_argument(
        "--scenario",
        default="clean",
        metavar="NAME",
        help="a fault the camera goes through on the way (spectral_vs.sim.scenarios: clean "
        "(default), box_15cm_1s, box_15cm_3s, box_25cm_1s, box_25cm_3s, hand_20cm, hand_40cm, "
        "tool_left, stray_points, latency_1, latency_2, dropped_frames, burst, stale_frames); "
        "the latency ones add the depth noise",
    )
    servo.add_argument(
        "--stop-at-joint-limits",
        action="store_true",
        help="stop (reason joint_limit) as soon as the joint command has to clamp a joint at "
        "a position limit; by default the clamped command is sent and the other joints go "
        "on (run_servo's stop_at_joint_limit=False; no joint ever crosses its limit): "
        "14-16 of 20 large iiwa starts instead of 12 (docs/kinematics.md)",
    )


def _add_output_arguments(servo: Any) -> None:
    """What is printed and drawn."""
    servo.add_argument(
        "--out",
        "--output",
        dest="out",
        type=Path,
        default=Path("results/servo"),
        metavar="DIR",
        help="folder for the figures (default: results/servo)",
    )
    servo.add_argument(
        "--no-figures", action="store_true", help="do not draw (no matplotlib needed)"
    )
    servo.add_argument(
        "--json",
        action="store_true",
        help="print a machine-readable summary: per start the final translation error (mm), "
        "rotation error (deg), steps, reason and success",
    )
    servo.add_argument(
        "--quiet",
        action="store_true",
        help="print only one line per start and the total (no steps, no set-up line)",
    )


def _servo_step_line(record: Any, T_world_reference: np.ndarray, servo_lib: Any) -> str:
    true_t, true_r = servo_lib.pose_error(
        np.linalg.inv(np.asarray(record.T_base_camera)) @ T_world_reference
    )
    return (
        f"step {record.step:3d}  t {record.time:5.1f} s  error {1000 * true_t:7.1f} mm "
        f"{np.degrees(true_r):6.2f} deg  (estimate {1000 * record.translation_error:7.1f}"
        f" mm {np.degrees(record.rotation_error):5.2f} deg)  fitness "
        f"{record.fitness:4.2f}  |v| {1000 * np.linalg.norm(record.twist[:3]):5.1f} mm/s"
        f"  {1000 * record.seconds:4.0f} ms"
        + (f"  relocalized (score {record.relocalization_score:.2f})" if record.relocalized else "")
        + (f"  held: {record.hold}" if record.hold else "")
        + (f"  recovering: {record.recovery}" if record.recovery else "")
    )


def run_servo_sim(args: argparse.Namespace) -> int:
    """Servo the simulated arm (--robot) from seeded starts back to the reference pose."""
    from spectral_vs import experiment
    from spectral_vs import servo as servo_lib

    try:
        from spectral_vs import sim
    except ImportError as error:
        raise InputError(f"servo-sim: {error}") from error
    from spectral_vs.sim import scenarios

    if args.scenario not in scenarios.SCENARIOS:
        raise InputError(
            f"--scenario must be one of {', '.join(scenarios.SCENARIOS)}, got {args.scenario!r}"
        )
    scenario = scenarios.SCENARIOS[args.scenario]
    plotting = None if args.no_figures else _plotting("--out")
    noisy = args.noise or scenario.noise
    noise = sim.DepthNoise.kinect(seed=args.seed) if noisy else sim.DepthNoise()
    sim_params = sim.SimParams(
        mode=args.sim_mode,
        robot=sim.robot_model(args.robot),
        camera=sim.CameraParams(noise=noise),
    )
    params = servo_lib.ServoParams(mode=args.mode, warm_start=args.warm_start)
    talk = not (args.json or args.quiet)
    lines = not args.json  # one line per start and the total, also with --quiet
    runs: list[dict[str, Any]] = []
    with sim.PyBulletRobot(sim_params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        spec = experiment.START_SETS[args.set]
        accept = robot.view_check(spec["min_view_share"]) if "min_view_share" in spec else None
        starts = experiment.start_poses(
            robot.kinematics,
            args.set,
            args.starts,
            args.seed,
            q_reference=sim_params.robot.home_q,
            accept=accept,
        )
        if talk:
            _print_setup(args, len(reference))
        for index, (q, t, r) in enumerate(starts):
            log, recorder = _servo_start(
                args, robot, reference, T_world_reference, params, index, (q, t, r), scenario
            )
            run = _run_summary(args, robot, log, T_world_reference, index, t, r)
            runs.append(run)
            if lines:
                _print_run(run, log)
            if plotting is not None:
                _plot_run(args, plotting, log, T_world_reference, reference, recorder, index)
    return _report(args, runs, lines)


def _print_setup(args: argparse.Namespace, points: int) -> None:
    """The run's first line: robot, reference, starts, estimate, simulation, budget."""
    warm = ", warm-started" if args.warm_start else ""
    print(
        f"{args.robot}: reference captured at home ({points} points); "
        f"{_count(args.starts, 'start')} of the {args.set} set (seed {args.seed}); "
        f"'{args.mode}' estimate{warm}, {args.sim_mode} simulation"
        f"{', depth noise' if _noisy_run(args) else ''}"
        f"{', scenario ' + args.scenario if args.scenario != 'clean' else ''}, "
        f"control period {args.dt:g} s, "
        f"{args.max_steps} steps max"
    )


def _servo_start(
    args: argparse.Namespace,
    robot: Any,
    reference: Any,
    T_world_reference: np.ndarray,
    params: Any,
    index: int,
    start: tuple[np.ndarray, float, float],
    scenario: Any,
) -> tuple[Any, Any]:
    """Servo back from start ``index`` (``q``, ``t`` m and ``r`` rad away from the
    reference pose), printing every step when there is one start: the log and the cloud
    recorder."""
    from spectral_vs import experiment
    from spectral_vs import servo as servo_lib

    q, t, r = start
    per_step = not (args.json or args.quiet) and args.starts == 1
    if per_step:
        print(f"start {index}: camera {1000 * t:.0f} mm and {np.degrees(r):.1f} deg away")

    def progress(record: servo_lib.ServoRecord) -> None:
        print(_servo_step_line(record, T_world_reference, servo_lib), flush=True)

    log, recorder = experiment.servo_from(
        robot,
        q,
        reference,
        params,
        wrap=lambda driven: experiment.CloudRecorder(scenario.wrap(driven)),
        dt=args.dt,
        max_steps=args.max_steps,
        stop_at_joint_limit=args.stop_at_joint_limits,
        callback=progress if per_step else None,
    )
    remove = getattr(recorder.robot, "remove", None)
    if callable(remove):
        remove()  # a box the scenario put in the simulation
    return log, recorder


def _run_summary(
    args: argparse.Namespace,
    robot: Any,
    log: Any,
    T_world_reference: np.ndarray,
    index: int,
    t: float,
    r: float,
) -> dict[str, Any]:
    """The JSON entry of one start: its distance, final error, steps, reason, success,
    worst excursion, held steps and step times."""
    from spectral_vs.sim.scenarios import summarize

    run = summarize(log, T_world_reference, robot.camera_pose())
    return {
        "index": index,
        "start_mm": 1000 * t,
        "start_deg": float(np.degrees(r)),
        "final_mm": run.final_mm,
        "final_deg": run.final_deg,
        "steps": run.steps,
        "reason": run.reason,
        "success": bool(run.final_mm < MAX_SERVO_ERROR_MM and run.final_deg < MAX_SERVO_ERROR_DEG),
        "servo_step_ms_median": 1000 * float(np.median(log.array("seconds"))),
        "servo_step_cpu_ms": [round(1000 * float(ms), 3) for ms in log.array("cpu_seconds")],
        "wall_s": log.wall_seconds,
        "worst_excursion_mm": run.worst_excursion_mm,
        "worst_excursion_deg": run.worst_excursion_deg,
        "held_steps": run.held_steps,
        "recovery_steps": int(sum(bool(record.recovery) for record in log.records)),
        "relocalizations": int(sum(record.relocalized for record in log.records)),
    }


def _print_run(run: dict[str, Any], log: Any) -> None:
    """One line per start: where it started, how it ended, the final error."""
    print(
        f"start {run['index']}: {run['start_mm']:.0f} mm {run['start_deg']:.1f} deg -> "
        f"{log.reason} after {_count(run['steps'], 'step')}; final error "
        f"{run['final_mm']:.2f} mm, {run['final_deg']:.3f} deg "
        f"({'ok' if run['success'] else 'TOO LARGE'}); worst excursion "
        f"{run['worst_excursion_mm']:.1f} mm, {run['worst_excursion_deg']:.1f} deg; "
        f"{_count(run['held_steps'], 'held step')}; {log.wall_seconds:.1f} s wall",
        flush=True,
    )


def _plot_run(
    args: argparse.Namespace,
    plotting: Any,
    log: Any,
    T_world_reference: np.ndarray,
    reference: Any,
    recorder: Any,
    index: int,
) -> None:
    """``servo.png`` (``servo_<index>.png`` for several starts) in ``--out``."""
    name = "servo.png" if args.starts == 1 else f"servo_{index}.png"
    path = args.out / name
    path.parent.mkdir(parents=True, exist_ok=True)
    plotting.plot_servo(
        log,
        T_world_reference,
        path,
        reference=reference,
        clouds=dict(enumerate(recorder.clouds)),
        title=f"servo-sim: {args.robot}, {args.set} start {index}, seed {args.seed}, "
        f"'{args.mode}' estimate",
    )
    if not (args.json or args.quiet):
        print(f"wrote {path}")


def _noisy_run(args: argparse.Namespace) -> bool:
    """Whether the run had the depth noise: ``--noise``, or a scenario that needs it."""
    from spectral_vs.sim.scenarios import SCENARIOS

    return bool(args.noise or SCENARIOS[args.scenario].noise)


def _report(args: argparse.Namespace, runs: list[dict[str, Any]], talk: bool) -> int:
    """The summary (JSON or a line) and the exit code: 1 when a start ended too far."""
    successes = sum(run["success"] for run in runs)
    if args.json:
        summary = {
            "robot": args.robot,
            "set": args.set,
            "seed": args.seed,
            "mode": args.mode,
            "warm_start": args.warm_start,
            "sim_mode": args.sim_mode,
            "noise": _noisy_run(args),
            "scenario": args.scenario,
            "stop_at_joint_limits": args.stop_at_joint_limits,
            "success_mm": MAX_SERVO_ERROR_MM,
            "success_deg": MAX_SERVO_ERROR_DEG,
            "successes": successes,
            "starts": runs,
        }
        print(json.dumps(summary, indent=1))
    elif talk:
        print(
            f"{successes}/{len(runs)} within {MAX_SERVO_ERROR_MM:g} mm and "
            f"{MAX_SERVO_ERROR_DEG:g} deg of the reference pose"
        )
    return 0 if successes == len(runs) else 1
