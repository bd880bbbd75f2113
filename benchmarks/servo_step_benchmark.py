"""Where the time of one servo step goes: the controller's processing per control step
(everything except rendering) of the default ``iteration`` estimate, stage by stage, at
320 x 240 on one core.

The simulated scene of ``spectral-vs servo-sim``: the reference is captured at
``sim.HOME_Q``, then the camera's depth image at a few moderate start poses (the first
starts of ``experiment.start_poses``) and at joints 0.3, 0.1, 0.03 and 0.01 of the way from the
reference to each (``WAY``: a converging run spends most steps near the reference).
Every view is processed ``--repeats`` times; each stage is timed with
``time.process_time`` (CPU time of the process, single thread) and the median over views
and repeats is reported, in ms:

* ``depth -> cloud + normals``: back-projection and normals of the organized depth image
  (``sim.camera.depth_to_cloud``);
* ``crop + downsample``: the ``max_depth`` crop and the voxel downsampling as the servo
  does it (``ServoParams.downsample_size``; half a voxel with ``registration.prepare``
  before it existed);
* ``registration``: the whole registration call of the step, and its parts:

  - ``plain align()`` (the servo before the prepared model): one ``_align`` call, whose
    parts are timed by re-running them with the bound building blocks: the reference's
    EGI coefficients and correlation set-up (``reference side``), the scene's EGI
    coefficients, the translation grid (voxelizing the scene, FFTW plans and the scene's
    spectrum), the FFTs of the one iteration (moving grid, cross-power, inverse, peak), the
    evaluation of the EGI correlation with its Hessian; what is left of the call (the
    scene map for the fitness, the fitness, the copies) is ``rest``;
  - ``ModelAligner`` (the servo now): the reference prepared once, per step only the
    scene's work; its parts as the aligner itself times them
    (``ModelAligner.last_timings``).

* ``plane turn``: the turn about the reference's dominant normal
  (``ServoParams.plane_turn``) from the view's off-plane normals;
* ``ModelAligner.align(), tracking bound``: the registration with
  ``ServoParams.tracking_translation`` instead of ``max_translation``;
* ``servo step``: ``SpectralServo.step`` as the controller runs it (crop, downsample,
  registration, plane turn, control law), from a cloud. One servo runs every view without
  a reset, so each view's repeats see the previous estimate of the same view: the
  tracking bound is used where that estimate qualifies (near the goal; the share of the
  views where it was used is printed, ``tracking_share`` in the JSON).

Closed loop (``--sets``): the servo runs of ``spectral-vs servo-sim`` (kinematic iiwa,
control period 0.1 s, 150 steps at most) from the first ``--set-starts`` starts of each
set, every ``SpectralServo.step_record`` timed with ``time.process_time`` and split into
its stages (the servo's methods and the aligners wrapped by timers; the aligners' own
parts from ``ModelAligner.last_timings``): the median and 95th percentile over all steps
of the set, per stage and for the whole step (``closed_loop`` in the JSON), and the runs'
outcomes.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/servo_step_benchmark.py            # about 2 min
    OMP_NUM_THREADS=1 python benchmarks/servo_step_benchmark.py --write  # + its JSON
    OMP_NUM_THREADS=1 python benchmarks/servo_step_benchmark.py --sets moderate large \
        --set-starts 20 --write                                          # about 6 min

Needs pybullet.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import report as report_lib

import spectral_vs as svs
from spectral_vs import _core, experiment, sim
from spectral_vs import servo as servo_lib
from spectral_vs.registration import prepare

RESULTS = report_lib.RESULTS / "servo_step.json"
#: Views per start: the joints' share of the way from the reference to the start (a
#: converging run spends most of its steps near the reference).
WAY = (1.0, 0.3, 0.1, 0.03, 0.01)


#: Stages that ModelAligner times itself (ModelAlignerTimings), wall clock.
TIMED_PARTS = (
    "scene_coefficients",
    "scene_map",
    "translation_grid",
    "rotation",
    "translation",
    "records",
    "fitness",
)


def cpu_ms(function: Callable[[], Any], repeats: int) -> tuple[list[float], Any]:
    """CPU times (ms) of ``repeats`` calls of ``function`` after one warm-up call, and the
    last call's value."""
    value = function()
    times = []
    for _ in range(repeats):
        start = time.process_time()
        value = function()
        times.append(1000.0 * (time.process_time() - start))
    return times, value


def bounded_grid(scene: Any, model: Any, voxel: float, max_translation: float) -> Any:
    """The translation grid of ``AlignParams.max_translation`` (the aligner's own rule): the
    scene's box and the model's at the identity with ``max_translation`` of room, a voxel
    of margin, FFT-friendly sizes. Cores with ``ModelAligner`` leave that room once (the
    grid is circular), older ones on both sides."""
    points = np.vstack([np.asarray(scene.points), np.asarray(model.points)])
    once = hasattr(_core, "ModelAligner")
    low = points.min(axis=0) - (0.0 if once else max_translation)
    high = points.max(axis=0) + max_translation
    shifts = 2 * math.ceil(max_translation / voxel) + 2 if once else 2
    origin = (np.floor(low / voxel) - 1.0) * voxel
    dims = [
        svs.fft_friendly_size(max(shifts, math.ceil((high[a] - origin[a]) / voxel) + 2))
        for a in range(3)
    ]
    return _core.GridSpec(origin, voxel, dims)


def plain_parts(
    reference: Any, scene: Any, settings: Any, repeats: int
) -> tuple[dict[str, list[float]], float]:
    """The parts of one plain ``align`` call in local mode, re-run with the bound blocks, and
    the voxels of its translation grid."""
    B = settings.bandwidth
    parts: dict[str, list[float]] = {}

    def reference_side() -> Any:
        coefficients = svs.egi_coefficients(reference, B)
        points = np.asarray(reference.points)
        points - points.mean(axis=0)  # the centred copy of MovingModel
        return coefficients

    parts["reference side"], model_coefficients = cpu_ms(reference_side, repeats)
    parts["scene EGI coefficients"], scene_coefficients = cpu_ms(
        lambda: svs.egi_coefficients(scene, B), repeats
    )
    parts["correlation set-up"], _ = cpu_ms(
        lambda: _core.So3Correlation(scene_coefficients, model_coefficients), repeats
    )
    correlation = _core.So3Correlation(scene_coefficients, model_coefficients)
    parts["correlation evaluation"], _ = cpu_ms(
        lambda: correlation.evaluate(np.eye(3), True), repeats
    )
    spec = bounded_grid(scene, reference, settings.voxel_size, settings.max_translation)
    max_shift = [math.ceil(settings.max_translation / settings.voxel_size)] * 3

    def grid() -> Any:
        target = svs.voxelize(scene, spec, "trilinear")
        phase = _core.PhaseCorrelation(spec, subvoxel=True, threads=1)
        phase.set_target(target)
        return phase

    parts["translation grid"], phase = cpu_ms(grid, repeats)
    moving = svs.voxelize(reference, spec, "trilinear")
    parts["voxelize reference"], _ = cpu_ms(
        lambda: svs.voxelize(reference, spec, "trilinear"), repeats
    )
    parts["FFTs (estimate)"], _ = cpu_ms(lambda: phase.estimate(moving, max_shift), repeats)
    parts["rotation cost"], _ = cpu_ms(
        lambda: svs.rotation_cost(scene_coefficients, model_coefficients, np.eye(3)), repeats
    )
    return parts, float(np.prod(spec.dims))


def prepare_scene(servo: Any, cloud: Any, params: Any) -> Any:
    """The current cloud cropped and downsampled as the servo does it (to
    ``ServoParams.downsample_size`` where the servo has it, else to half a voxel)."""
    cropped = servo._reference.crop(cloud)
    if hasattr(servo, "_prepare"):
        return servo._reference.prepare(cropped, "current")
    return prepare(cropped, "current", params.voxel_size, True, (0, 0, 0))


def median(values: list[float]) -> float:
    return float(statistics.median(values)) if values else math.nan


def run(args: argparse.Namespace) -> dict[str, Any]:
    params = servo_lib.ServoParams()
    views: list[tuple[str, np.ndarray]] = []
    with sim.PyBulletRobot(sim.SimParams()) as robot:
        reference_depth = robot.capture_depth()
        starts = experiment.start_poses(robot.kinematics, "moderate", args.starts, args.seed)
        home = np.asarray(sim.HOME_Q)
        for index, (q, _, _) in enumerate(starts):
            # The start, then the joints part of the way back (WAY).
            for share in WAY:
                robot.reset_joint_positions(home + share * (np.asarray(q) - home))
                views.append((f"start {index} x {share:g}", robot.capture_depth()))
        intrinsics = robot.params.camera.intrinsics
        normal_params = robot.params.camera.normals
    reference_cloud = sim.depth_to_cloud(reference_depth, intrinsics, normal_params)
    servo = servo_lib.SpectralServo(reference_cloud, params)
    params = servo.params  # its scale lengths resolved from the reference
    settings = params.align_params()
    settings.threads = 1
    reference = servo.reference
    stages: dict[str, list[float]] = {}
    per_view = []
    tracked: list[bool] = []
    # Parts of the servo step that older cores' servos do not have (None then).
    tracking_aligner = getattr(servo, "_tracking_aligner", None)
    plane_turn = getattr(servo, "_plane_turn", None)
    # One aligner for every view, as the servo keeps one (None on cores without it).
    aligner = _core.ModelAligner(reference, settings) if hasattr(_core, "ModelAligner") else None

    def add(name: str, values: list[float]) -> None:
        stages.setdefault(name, []).extend(values)

    for name, depth in views:
        times, cloud = cpu_ms(
            lambda depth=depth: sim.depth_to_cloud(depth, intrinsics, normal_params),
            args.repeats,
        )
        add("depth -> cloud + normals", times)
        times, scene = cpu_ms(lambda cloud=cloud: prepare_scene(servo, cloud, params), args.repeats)
        add("crop + downsample", times)
        plain, result = cpu_ms(
            lambda scene=scene: _core._align(reference, scene, settings), args.repeats
        )
        add("plain align()", plain)
        parts, voxels = plain_parts(reference, scene, settings, args.repeats)
        for part, values in parts.items():
            add(f"plain: {part}", values)
        if aligner is not None:
            times, prepared = cpu_ms(lambda scene=scene: aligner.align(scene), args.repeats)
            add("ModelAligner.align()", times)
            same = np.allclose(
                np.asarray(prepared.T_scene_model), np.asarray(result.T_scene_model), atol=1e-9
            )
            if not same:
                raise RuntimeError(f"{name}: ModelAligner and align() disagree")
            for part in TIMED_PARTS:
                values = []
                for _ in range(args.repeats):
                    aligner.align(scene)
                    values.append(1000.0 * getattr(aligner.last_timings, part))
                add(f"ModelAligner: {part}", values)
        if tracking_aligner is not None:
            times, _ = cpu_ms(lambda scene=scene: tracking_aligner.align(scene), args.repeats)
            add("ModelAligner.align(), tracking bound", times)
        if plane_turn is not None:
            normals = np.asarray(servo._reference.crop(cloud).normals)
            T = np.asarray(result.T_scene_model)
            times, _ = cpu_ms(lambda n=normals, T=T: plane_turn.turn(n, T), args.repeats)
            add("plane turn", times)
        step_times, _ = cpu_ms(lambda cloud=cloud: servo.step(cloud), args.repeats)
        add("servo step", step_times)
        tracked.append(bool(servo.step_record(cloud)[2].tracking))
        per_view.append(
            {
                "view": name,
                "points": len(cloud),
                "downsampled": len(scene),
                "grid_voxels": voxels,
                "plain_align_ms": median(plain),
                "servo_step_ms": median(step_times),
                "T_scene_model": np.asarray(result.T_scene_model).tolist(),
            }
        )
    return {
        "machine": report_lib.machine(),
        "commit": report_lib.commit(),
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS", "unset"),
        "repeats": args.repeats,
        "reference_points": len(reference_cloud),
        "reference_downsampled": len(reference),
        "stages_ms": {name: median(values) for name, values in stages.items()},
        "tracking_share": sum(tracked) / len(tracked) if tracked else 0.0,
        "views": per_view,
    }


#: Methods of SpectralServo timed in the closed loop, and their stage names.
#: The servo's parts timed in the closed loop: (part, method, stage).
SERVO_STAGES = (
    ("_reference", "crop", "crop (max_depth)"),
    ("_reference", "prepare", "voxel downsampling"),
    ("_gate", "drop_occluders", "occluder test"),
    ("_relocalizer", "relocalize", "relocalization (align_views)"),
    (None, "twist", "control law"),
)


class _TimedAligner:
    """A ModelAligner whose ``align`` adds its CPU time and parts to ``times``."""

    def __init__(self, aligner: Any, name: str, times: dict[str, float]) -> None:
        self._aligner, self._name, self._times = aligner, name, times

    def align(self, *args: Any) -> Any:
        start = time.process_time()
        result = self._aligner.align(*args)
        self._times[self._name] = self._times.get(self._name, 0.0) + time.process_time() - start
        for part in TIMED_PARTS:
            key = f"  {part}"
            self._times[key] = self._times.get(key, 0.0) + getattr(self._aligner.last_timings, part)
        return result

    def __getattr__(self, name: str) -> Any:
        return getattr(self._aligner, name)


def _timed(owner: Any, name: str, stage: str, times: dict[str, float]) -> None:
    """Wrap ``owner.name`` so that each call adds its CPU time to ``times[stage]``."""
    function = getattr(owner, name)

    def timed(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            times[stage] = times.get(stage, 0.0) + time.process_time() - start

    setattr(owner, name, timed)


def closed_loop(set_name: str, count: int, seed: int) -> dict[str, Any]:
    """The servo-sim runs of one start set with every step's stages timed (CPU, ms)."""
    steps: list[dict[str, float]] = []
    runs = []
    with sim.PyBulletRobot(sim.SimParams()) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        starts = experiment.start_poses(robot.kinematics, set_name, count, seed)
        for q, _, _ in starts:
            robot.reset_joint_positions(q)
            servo = servo_lib.SpectralServo(reference, servo_lib.ServoParams())
            times: dict[str, float] = {}
            for part, method, stage in SERVO_STAGES:
                _timed(getattr(servo, part) if part else servo, method, stage, times)
            _timed(servo._gate.stale_frames, "check", "stale-frame test (fingerprint)", times)
            if servo._tracker.plane_turn is not None:
                _timed(servo._tracker.plane_turn, "turn", "plane turn", times)
            prepared = servo._reference
            prepared.aligner = _TimedAligner(prepared.aligner, "registration", times)
            if prepared.tracking_aligner is not None:
                prepared.tracking_aligner = _TimedAligner(
                    prepared.tracking_aligner, "registration, tracking bound", times
                )
            step_record = servo.step_record

            def timed_step(*args: Any, _step: Any = step_record, _t: Any = times, **kw: Any) -> Any:
                _t.clear()
                start = time.process_time()
                out = _step(*args, **kw)
                total = time.process_time() - start
                steps.append({**_t, "servo step (step_record)": total})
                return out

            servo.step_record = timed_step
            log = servo_lib.run_servo(robot, robot.kinematics, servo, dt=0.1, max_steps=150)
            servo_lib.pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
            final_t, final_r = servo_lib.pose_error(
                np.linalg.inv(robot.camera_pose()) @ T_world_reference
            )
            runs.append(
                {
                    "reason": log.reason,
                    "steps": len(log.records),
                    "final_mm": 1000 * final_t,
                    "final_deg": math.degrees(final_r),
                }
            )
    names = sorted({name for step in steps for name in step})
    stages = {}
    for name in names:
        values = np.array([1000.0 * step.get(name, 0.0) for step in steps])
        used = values[values > 0]
        stages[name] = {
            "median": float(np.median(values)),
            "p95": float(np.percentile(values, 95)),
            "median_when_run": float(np.median(used)) if len(used) else 0.0,
            "share_run": float(len(used) / len(values)),
        }
    converged = [r for r in runs if r["reason"] == "converged"]
    return {"steps": len(steps), "stages_ms": stages, "runs": runs, "converged": len(converged)}


def verification_cost(calls: int = 60) -> dict[str, float]:
    """Median CPU time (ms) of the servo's tracking registration with and without the pose
    verification (``AlignParams.verify``) on two near-goal views (3% of the way to moderate
    starts 0 and 1), the two aligners called in turn so that both see the same load."""
    with sim.PyBulletRobot(sim.SimParams()) as robot:
        reference = robot.capture()
        home = np.asarray(robot.joint_positions())
        views = []
        for q, _, _ in experiment.start_poses(robot.kinematics, "moderate", 2, 0):
            robot.reset_joint_positions(home + 0.03 * (np.asarray(q) - home))
            views.append(robot.capture())
    servo = servo_lib.SpectralServo(reference, servo_lib.ServoParams())
    assert servo._reference.tracking_aligner is not None
    off = servo._reference.tracking_aligner.params
    on = copy.copy(off)
    on.verify = True
    aligners = {
        "verify off": _core.ModelAligner(servo.reference, off),
        "verify on": _core.ModelAligner(servo.reference, on),
    }
    scenes = [servo._reference.prepare(servo._reference.crop(view), "current") for view in views]
    times: dict[str, list[float]] = {name: [] for name in aligners}
    for _ in range(calls):
        for scene in scenes:
            for name, aligner in aligners.items():
                start = time.process_time()
                aligner.align(scene)
                times[name].append(1000.0 * (time.process_time() - start))
    return {name: median(values) for name, values in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=3, help="moderate starts (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per view")
    parser.add_argument("--write", action="store_true", help="write results/servo_step.json")
    parser.add_argument(
        "--sets",
        nargs="*",
        default=[],
        choices=["moderate", "large", "extreme"],
        help="also time the closed-loop servo-sim runs of these start sets",
    )
    parser.add_argument("--set-starts", type=int, default=20, help="starts per set (20)")
    parser.add_argument("--skip-views", action="store_true", help="only the closed loop")
    parser.add_argument(
        "--verification", action="store_true", help="only the pose verification's cost"
    )
    args = parser.parse_args()
    if args.verification:
        for name, value in verification_cost().items():
            print(f"tracking registration, {name}: {value:.2f} ms (median CPU)")
        return
    results = {} if args.skip_views else run(args)
    if args.sets:
        results.setdefault("machine", report_lib.machine())
        results.setdefault("commit", report_lib.commit())
        results["closed_loop"] = {}
        for set_name in args.sets:
            loop = closed_loop(set_name, args.set_starts, args.seed)
            results["closed_loop"][set_name] = loop
            print(
                f"{set_name}: {loop['steps']} steps, {loop['converged']} of "
                f"{len(loop['runs'])} runs converged; CPU ms per step (median / p95):"
            )
            for name, value in loop["stages_ms"].items():
                print(
                    f"  {name:<34} {value['median']:7.2f} {value['p95']:7.2f}"
                    f"   (run in {100 * value['share_run']:.0f}% of steps)"
                )
        if args.skip_views:
            if args.write:
                path = RESULTS.with_name("servo_step_closed_loop.json")
                path.write_text(json.dumps(report_lib.rounded(results), indent=1) + "\n")
                print(f"wrote {path}")
            return
    print(f"{results['machine']}, commit {results['commit']}")
    print(
        f"reference: {results['reference_points']} points, "
        f"{results['reference_downsampled']} after downsampling"
    )
    for view in results["views"]:
        print(
            f"  {view['view']:<22} {view['points']:6d} points, {view['downsampled']:5d} "
            f"downsampled, grid {view['grid_voxels']:.0f} voxels: plain align "
            f"{view['plain_align_ms']:.1f} ms, servo step {view['servo_step_ms']:.1f} ms"
        )
    for name, value in results["stages_ms"].items():
        print(f"{name:<40} {value:8.2f} ms")
    print(f"servo step with the tracking bound in {100 * results['tracking_share']:.0f}% of views")
    if args.write:
        RESULTS.write_text(json.dumps(report_lib.rounded(results), indent=1) + "\n")
        print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
