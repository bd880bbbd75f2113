"""Soak: the servo held at its goal for many steps, and many alignments in one process.
Resident memory, step time and pose drift over a long run, where a leak, a growing cache
or an accumulating error would show.

Servo (``--steps``, 10^4 by default): the simulation of ``spectral-vs servo-sim``
(kinematic iiwa, 320 x 240 wrist depth camera with the Kinect noise model, so that no two
frames are equal), the reference captured at home and the arm left there: every step
captures a view and runs ``SpectralServo.step_record`` with the default ``ServoParams``;
a running step sends its joint velocities, a converged one (the estimate within the
servo's tolerances, 0.5 mm and 0.1 deg, and then until it has left the re-engage
bounds, 3 mm and 1 deg, for 3 steps in a row) holds the arm still for the step, as a
servo left running at its goal does (``run_servo`` would end the run there). The
camera's true error from the reference pose (from PyBullet) is its error at the goal;
its motion from its pose at step 100, the drift.

Alignments (``--alignments``, 10^4 by default): ``align()`` (default settings but
``hypotheses=8``, ``max_alternatives=0``, 10 mm voxels) of the milk carton of
``../shared/data`` (downsampled to 4 mm, normals) onto a copy moved by a seeded random
motion (any rotation, up to 0.1 m), a new motion every call; every 100th call is the
same fixed pair, whose pose must not change at all.

Reported, for each loop: the resident memory (``VmRSS`` of ``/proc/self/status``) at
steps 100, 1000 and the last, its growth after the warm-up (from step 100 to the last),
malloc's memory in use at the same steps (glibc's ``mallinfo2``: what the program holds,
without the free memory the allocator keeps), the resident memory after ``malloc_trim``
at the end, the median CPU time (``time.process_time``, one thread) of the servo step or the
alignment per block of 1000, and the drift: the servo's true error at the goal
(median and largest after the warm-up), the alignments' errors and the fixed pair's
largest change. Results: ``benchmarks/results/soak.json`` and the table of
``docs/reliability.md`` (between its ``soak`` markers) when run with the defaults.

Usage::

    OMP_NUM_THREADS=1 nice -n 10 python benchmarks/soak_benchmark.py     # 25 min of CPU
    OMP_NUM_THREADS=1 python benchmarks/soak_benchmark.py --steps 300 --alignments 300 \
        --output /tmp/soak.json                                          # a few minutes

Needs pybullet and the scans (``SPECTRAL_VS_DATA``, default ``../shared/data``).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import report as report_lib

import spectral_vs as svs
from spectral_vs import servo as servo_lib
from spectral_vs import sim

RESULTS = report_lib.RESULTS / "soak.json"
DOC = report_lib.ROOT / "docs" / "reliability.md"
#: Steps at which the resident memory is reported; the first is the end of the warm-up.
MARKS = (100, 1000, 10_000)
BLOCK = 1000
#: Steps between the resident-memory samples and the partial results written on the way
#: (a run stopped early still leaves its figures in the results file, "partial": true).
CHECKPOINT = 500
Checkpoint = Callable[[dict[str, Any]], None]
#: The issue's targets: memory growth after the warm-up, and drift at the goal.
MAX_GROWTH_MB = 5.0
MAX_DRIFT_MM = 0.5
MAX_DRIFT_DEG = 0.05


def rss_mb() -> float:
    """Resident memory of this process now (not its peak), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS in /proc/self/status")


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena", "ordblks", "smblks", "hblks", "hblkhd",
            "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost",
        )
    ]  # fmt: skip


def _libc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = _MallInfo2
        return libc
    except (OSError, AttributeError):  # not glibc 2.33 or later
        return None


_LIBC = _libc()


def in_use_mb() -> float:
    """Memory that malloc has handed out and not been given back (glibc's ``mallinfo2``:
    heap chunks in use plus mmapped ones), MB; NaN without glibc. The resident memory
    also holds what the allocator keeps free for later: a growth of the resident memory
    that this does not share is the allocator's, not the program's."""
    if _LIBC is None:
        return math.nan
    info = _LIBC.mallinfo2()
    return (info.uordblks + info.hblkhd) / 2**20


def trimmed_rss_mb() -> float:
    """Resident memory after ``malloc_trim(0)`` has given the allocator's free pages back, MB."""
    if _LIBC is not None:
        _LIBC.malloc_trim(0)
    return rss_mb()


def marks(count: int) -> list[int]:
    return [m for m in MARKS if m < count] + [count]


def block_medians(seconds: list[float]) -> list[float]:
    return [
        1000.0 * statistics.median(seconds[i : i + BLOCK]) for i in range(0, len(seconds), BLOCK)
    ]


class _Memory:
    """The resident memory and malloc's memory in use, sampled at the same steps."""

    def __init__(self) -> None:
        self.rss: dict[int, float] = {}
        self.in_use: dict[int, float] = {}
        self.trimmed: float | None = None  # at the end, after malloc_trim

    def sample(self, step: int) -> float:
        self.rss[step] = rss_mb()
        self.in_use[step] = in_use_mb()
        return self.rss[step]

    def __contains__(self, step: int) -> bool:
        return step in self.rss

    def __getitem__(self, step: int) -> float:
        return self.rss[step]

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.rss)


def memory_summary(memory: _Memory) -> dict[str, Any]:
    steps = sorted(memory.rss)
    warm = MARKS[0] if MARKS[0] in memory.rss else steps[0]
    summary = {
        "rss_mb": {str(s): memory.rss[s] for s in steps},
        "growth_after_warmup_mb": memory.rss[steps[-1]] - memory.rss[warm],
        # What the program holds (malloc's chunks in use), beside what is resident.
        "in_use_mb": {str(s): memory.in_use[s] for s in steps},
        "in_use_growth_after_warmup_mb": memory.in_use[steps[-1]] - memory.in_use[warm],
    }
    if memory.trimmed is not None:
        summary["rss_after_trim_mb"] = memory.trimmed
    return summary


class _Series:
    """A preallocated float series: the soak's own per-step figures cost no memory after
    the start (a growing list of them grew the resident memory by about 0.35 kB a step,
    half of what the soak of commit 3f8d3e1 measured)."""

    def __init__(self, capacity: int) -> None:
        self._values = np.full(capacity, np.nan)
        self._count = 0

    def append(self, value: float) -> None:
        self._values[self._count] = value
        self._count += 1

    def values(self) -> np.ndarray:
        return self._values[: self._count]

    def __len__(self) -> int:
        return self._count


class _Drift:
    """The largest motion of the held camera from its pose at the end of the warm-up,
    kept as it goes rather than from a list of every pose."""

    def __init__(self) -> None:
        self.settled: np.ndarray | None = None
        self.mm = 0.0
        self.deg = 0.0

    def add(self, step: int, T_world_camera: np.ndarray) -> None:
        if step <= MARKS[0] or self.settled is None:
            self.settled = T_world_camera  # the pose at step 100 (or the last so far)
            return
        t, r = servo_lib.pose_error(np.linalg.inv(self.settled) @ T_world_camera)
        self.mm = max(self.mm, 1000.0 * t)
        self.deg = max(self.deg, math.degrees(r))


def soak_servo(
    steps: int, seed: int, talk: bool, checkpoint: Checkpoint | None = None
) -> dict[str, Any]:
    noise = sim.DepthNoise.kinect(seed=seed)
    sim_params = sim.SimParams(camera=sim.CameraParams(noise=noise))
    params = servo_lib.ServoParams()
    velocity = svs.VelocityCommandParams(dt=0.1, max_joint_speed=1.0)
    errors_mm, errors_deg, seconds = _Series(steps), _Series(steps), _Series(steps)
    memory = _Memory()
    counts = {"holds": 0, "converged": 0, "moving": 0, "relocalized": 0}
    drift = _Drift()
    stopped = None
    mark_at = set(marks(steps))
    with sim.PyBulletRobot(sim_params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        servo = servo_lib.SpectralServo(reference, params)
        kinematics = robot.kinematics
        previous = None

        def summary() -> dict[str, Any]:
            return servo_summary(errors_mm, errors_deg, drift, seconds, memory, counts, stopped)

        for step in range(1, steps + 1):
            q = robot.joint_positions()
            pose = np.asarray(kinematics.forward(q))
            motion = None if previous is None else np.linalg.inv(previous) @ pose
            previous = pose
            cloud = robot.capture()
            start = time.process_time()
            twist, status, record = servo.step_record(cloud, motion, now=robot.time())
            q_dot = np.zeros_like(q)
            if status.state == "running" and not record.hold:
                q_dot = np.asarray(kinematics.joint_velocities(q, twist, velocity).q_dot)
                counts["moving"] += step > MARKS[0]
            seconds.append(time.process_time() - start)
            counts["holds"] += bool(record.hold)
            counts["converged"] += status.state == "converged"
            counts["relocalized"] += bool(record.relocalized)
            if status.state == "stopped":
                stopped = f"step {step}: {status.reason} ({status.message})"
                break
            robot.send_joint_velocities(q_dot, 0.1)
            T_world_camera = robot.camera_pose()
            t_err, r_err = servo_lib.pose_error(np.linalg.inv(T_world_camera) @ T_world_reference)
            errors_mm.append(1000.0 * t_err)
            errors_deg.append(math.degrees(r_err))
            drift.add(step, T_world_camera)
            if step in mark_at or step % CHECKPOINT == 0:
                memory.sample(step)
                if talk:
                    median_ms = 1000 * statistics.median(seconds.values()[-100:])
                    print(
                        f"servo step {step}: {memory[step]:.1f} MB "
                        f"({memory.in_use[step]:.1f} in use), error {t_err * 1000:.3f} mm "
                        f"{math.degrees(r_err):.4f} deg, step {median_ms:.1f} ms",
                        flush=True,
                    )
            if checkpoint is not None and step % CHECKPOINT == 0 and step < steps:
                checkpoint(summary())
        memory.trimmed = trimmed_rss_mb()  # with the simulation still loaded
    return summary()


def servo_summary(
    errors_mm: _Series,
    errors_deg: _Series,
    drift: _Drift,
    seconds: _Series,
    memory: _Memory,
    counts: dict[str, int],
    stopped: str | None,
) -> dict[str, Any]:
    mm, deg = errors_mm.values(), errors_deg.values()
    after = slice(MARKS[0], None) if len(mm) > MARKS[0] else slice(0, None)
    return {
        # Drift: how far the held camera moved from where it was at the end of the warm-up.
        "drift_mm_max": drift.mm,
        "drift_deg_max": drift.deg,
        "steps": len(seconds),
        "stopped": stopped,
        "holds": counts["holds"],
        "converged_steps": counts["converged"],
        "moving_steps_after_warmup": counts["moving"],
        "relocalizations": counts["relocalized"],
        **memory_summary(memory),
        "step_ms_median_per_1000": block_medians(list(seconds.values())),
        "error_mm_median": float(np.median(mm[after])),
        "error_mm_max": float(mm[after].max()),
        "error_deg_median": float(np.median(deg[after])),
        "error_deg_max": float(deg[after].max()),
        "error_mm_at": {str(s): float(mm[s - 1]) for s in sorted(memory)},
        "error_deg_at": {str(s): float(deg[s - 1]) for s in sorted(memory)},
    }


def random_motion(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = rng.uniform(-0.1, 0.1, size=3)
    return T


def soak_align(
    count: int, seed: int, data: Path, talk: bool, checkpoint: Checkpoint | None = None
) -> dict[str, Any]:
    model = svs.load_cloud(str(data / "milk.pcd"))
    model = svs.estimate_normals(svs.voxel_downsample(model, 0.004), radius=0.012)
    c = np.asarray(model.points).mean(axis=0)
    centred = np.eye(4)
    centred[:3, 3] = -c
    model = model.transformed(centred)  # about the origin: the motions turn it in place
    params = svs.AlignParams()
    params.voxel_size = 0.01
    params.hypotheses = 8
    # No search for alternative poses: it is most of a global alignment's time (0.4 s of
    # the 0.45 s per call at commit 3f8d3e1) and leaves the pose as it is.
    params.max_alternatives = 0
    rng = np.random.default_rng(seed)
    fixed_T = random_motion(np.random.default_rng(seed + 1))
    fixed_scene = model.transformed(fixed_T)
    fixed_first = None
    fixed_change = 0.0
    errors_mm, errors_deg, seconds = _Series(count), _Series(count), _Series(count)
    memory = _Memory()
    mark_at = set(marks(count))
    for i in range(1, count + 1):
        fixed = i % 100 == 0
        T = fixed_T if fixed else random_motion(rng)
        scene = fixed_scene if fixed else model.transformed(T)
        start = time.process_time()
        result = svs.align(model, scene, params, downsample=False)
        seconds.append(time.process_time() - start)
        E = np.linalg.inv(T) @ np.asarray(result.T_scene_model)
        t_err, r_err = servo_lib.pose_error(E)
        errors_mm.append(1000.0 * t_err)
        errors_deg.append(math.degrees(r_err))
        if fixed:
            pose = np.asarray(result.T_scene_model)
            if fixed_first is None:
                fixed_first = pose
            fixed_change = max(fixed_change, float(np.abs(pose - fixed_first).max()))
        if i in mark_at or i % CHECKPOINT == 0:
            memory.sample(i)
            if talk:
                print(
                    f"alignment {i}: {memory[i]:.1f} MB ({memory.in_use[i]:.1f} in use), "
                    f"{1000 * statistics.median(seconds.values()[-100:]):.1f} ms",
                    flush=True,
                )
        if checkpoint is not None and i % CHECKPOINT == 0 and i < count:
            checkpoint(align_summary(errors_mm, errors_deg, seconds, memory, fixed_change))
    memory.trimmed = trimmed_rss_mb()
    return align_summary(errors_mm, errors_deg, seconds, memory, fixed_change)


def align_summary(
    errors_mm: _Series,
    errors_deg: _Series,
    seconds: _Series,
    memory: _Memory,
    fixed_change: float,
) -> dict[str, Any]:
    mm, deg = errors_mm.values(), errors_deg.values()
    return {
        "alignments": len(seconds),
        **memory_summary(memory),
        "align_ms_median_per_1000": block_medians(list(seconds.values())),
        "success_rate": float(np.mean((mm < 10.0) & (deg < 5.0))),
        "error_mm_median": float(np.median(mm)),
        "error_deg_median": float(np.median(deg)),
        "fixed_pair_max_change": fixed_change,
    }


def table(results: dict[str, Any]) -> str:
    s, a = results["servo"], results["align"]
    rows = []
    for name, loop, unit in (("servo held at the goal", s, "steps"), ("align()", a, "alignments")):
        rss = loop["rss_mb"]
        last = list(rss)[-1]
        shown = [k for k in rss if int(k) in MARKS or k == last]
        rows.append(
            [
                f"{name}, {loop[unit]} {unit}",
                ", ".join(f"{rss[k]:.1f} MB at {k}" for k in shown),
                f"{loop['growth_after_warmup_mb']:+.1f} MB",
                f"{loop['in_use_growth_after_warmup_mb']:+.1f} MB"
                + (
                    f"; {loop['rss_after_trim_mb']:.1f} MB resident after malloc_trim"
                    if "rss_after_trim_mb" in loop
                    else ""
                ),
                ", ".join(
                    f"{v:.1f}"
                    for v in loop[
                        "step_ms_median_per_1000" if loop is s else "align_ms_median_per_1000"
                    ]
                ),
            ]
        )
    head = report_lib.markdown(
        [
            "loop",
            "resident memory",
            "growth after step 100",
            "malloc's memory in use: growth after step 100",
            "median ms per 1000 steps",
        ],
        rows,
    )
    drift = (
        f"Servo at the goal after step 100: the true camera error from the reference pose "
        f"median {s['error_mm_median']:.3f} mm / {s['error_deg_median']:.4f} deg, largest "
        f"{s['error_mm_max']:.3f} mm / {s['error_deg_max']:.4f} deg; the camera's drift from "
        f"its pose at step 100 at most {s['drift_mm_max']:.3f} mm / {s['drift_deg_max']:.4f} "
        f"deg (targets {MAX_DRIFT_MM} mm, {MAX_DRIFT_DEG} deg); {s['converged_steps']} converged "
        f"steps (held still), {s['holds']} held for the sensor"
        f"{'; stopped at ' + s['stopped'] if s['stopped'] else ', never stopped'}. "
        f"Alignments: {100 * a['success_rate']:.1f}% within 10 mm and 5 deg (median error "
        f"{a['error_mm_median']:.2f} mm, {a['error_deg_median']:.3f} deg); the fixed pair, "
        f"aligned every 100th call, changed by {a['fixed_pair_max_change']:.3g} at most."
    )
    return (
        f"{head}\n\n{drift}\n\n`{results['command']}` at commit {results['commit']} on "
        f"{results['machine']} (shared with other jobs), {results['wall_minutes']:.0f} min"
        + (
            " (stopped before the end: the figures of the steps run)."
            if results["partial"]
            else "."
        )
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=MARKS[-1], help="servo steps (10^4)")
    parser.add_argument("--alignments", type=int, default=MARKS[-1], help="alignments (10^4)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--data", type=Path, default=Path(os.environ.get("SPECTRAL_VS_DATA", "../shared/data"))
    )
    parser.add_argument("--output", type=Path, default=RESULTS)
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument(
        "--loops",
        nargs="+",
        choices=("servo", "align"),
        default=["servo", "align"],
        help="the loops to run (two processes can run one each, then --merge)",
    )
    parser.add_argument(
        "--merge",
        nargs="+",
        type=Path,
        help="combine the results files of separate runs into --output and report them",
    )
    args = parser.parse_args()
    if args.merge:
        return merge(args.merge, args.output)
    if args.steps < 1 or args.alignments < 1:
        parser.error("--steps and --alignments must be >= 1")
    started = time.perf_counter()
    talk = not args.quiet
    results: dict[str, Any] = {
        "command": " ".join(
            ["OMP_NUM_THREADS=1 python benchmarks/soak_benchmark.py", *sys.argv[1:]]
        ),
        "commit": report_lib.commit(),
        "core_sha256": report_lib.core_sha256(),
        "machine": report_lib.machine(),
    }

    def partial(name: str) -> Checkpoint:
        def write(summary: dict[str, Any]) -> None:
            args.output.parent.mkdir(parents=True, exist_ok=True)
            wall = (time.perf_counter() - started) / 60.0
            part = {**results, name: summary, "partial": True, "wall_minutes": wall}
            args.output.write_text(report_lib.to_json({**part, "records": []}))

        return write

    if "servo" in args.loops:
        results["servo"] = soak_servo(args.steps, args.seed, talk, partial("servo"))
    if "align" in args.loops:
        results["align"] = soak_align(args.alignments, args.seed, args.data, talk, partial("align"))
    results["partial"] = False
    results["wall_minutes"] = (time.perf_counter() - started) / 60.0
    results["records"] = []
    report_lib.write_results(results, args.output, RESULTS, report)
    if "servo" in results and "align" in results:
        print(table(results))
    return 0


def report(results: dict[str, Any]) -> None:
    if not report_lib.replace_block(DOC, "soak", table(results)):
        print(f"no soak markers in {DOC}", file=sys.stderr)


def merge(paths: list[Path], output: Path) -> int:
    """One results file (and the docs table) from runs of one loop each, run at once."""
    parts = [json.loads(path.read_text()) for path in paths]
    results: dict[str, Any] = {}
    for part in parts:
        results.update({k: v for k, v in part.items() if k not in ("command", "wall_minutes")})
    results["partial"] = any(part.get("partial", False) for part in parts)
    results["command"] = " & ".join(part["command"] for part in parts)
    results["wall_minutes"] = max(part["wall_minutes"] for part in parts)
    report_lib.write_results(results, output, RESULTS, report)
    print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
