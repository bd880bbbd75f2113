"""Where the time of one servo step goes: the controller's processing per control step
(everything except rendering) of the default ``iteration`` estimate, stage by stage, at
320 x 240 on one core.

The simulated scene of ``spectral-vs servo-sim``: the reference is captured at
``sim.HOME_Q``, then the camera's depth image at a few moderate start poses (the first
starts of ``servo.start_poses``) and at joints 0.3, 0.1, 0.03 and 0.01 of the way from the
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

Usage::

    OMP_NUM_THREADS=1 python benchmarks/servo_step_benchmark.py            # about 2 min
    OMP_NUM_THREADS=1 python benchmarks/servo_step_benchmark.py --write  # + its JSON

Needs pybullet.
"""

from __future__ import annotations

import argparse
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
from spectral_vs import _core, sim
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
    cropped = servo._crop(cloud)
    if hasattr(servo, "_prepare"):
        return servo._prepare(cropped, "current")
    return prepare(cropped, "current", params.voxel_size, True, (0, 0, 0))


def median(values: list[float]) -> float:
    return float(statistics.median(values)) if values else math.nan


def run(args: argparse.Namespace) -> dict[str, Any]:
    params = servo_lib.ServoParams()
    settings = params.align_params()
    settings.threads = 1
    views: list[tuple[str, np.ndarray]] = []
    with sim.PyBulletRobot(sim.SimParams()) as robot:
        reference_depth = robot.capture_depth()
        starts = servo_lib.start_poses(robot.kinematics, "moderate", args.starts, args.seed)
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
            normals = np.asarray(servo._crop(cloud).normals)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=3, help="moderate starts (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per view")
    parser.add_argument("--write", action="store_true", help="write results/servo_step.json")
    args = parser.parse_args()
    results = run(args)
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
