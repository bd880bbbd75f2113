"""Bit-for-bit fingerprints of the aligner's poses and verdicts, to check that a change of structure
changes no result.

Runs ``align`` in its two modes (the global search with the scan's viewpoint, and the
paper's gradient ascent) and the servo's prepared reference (``ModelAligner`` with a
bounded translation) on seeded cases of every family of ``benchmarks/cases.py``, and
``align_views`` on seeded view pairs of the real scans (``spectral_vs.data.view_pairs``
of ``../shared/data``, 320 x 240, searched and from a prior pose), and writes each
returned pose as the hexadecimal form of its 16 doubles, with the fitness (views: the
support's score), the verdict's score and confidence, and the status; and, with
``--servo-starts``, every step of short servo runs in the simulation (both arms, moderate
and large starts of seed 33, a clean view, a box in front of the camera and stray points):
the estimate, the twist, the score, the confidence, the hold, the recovery and the status
of each step::

    python benchmarks/pose_fingerprint.py --output before.json      # on the old code
    python benchmarks/pose_fingerprint.py --compare before.json     # on the new code

``--compare`` exits with 1 and names the cases whose poses differ in any bit.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import spectral_vs as svs
from spectral_vs import data
from spectral_vs._core import ModelAligner

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cases as case_lib

ANGLES = (30.0, 120.0)
#: The scans whose view pairs ``align_views`` registers.
VIEW_SCANS = ("table", "room")


def fingerprint(T: np.ndarray) -> list[str]:
    return [float(v).hex() for v in np.asarray(T, dtype=float).ravel()]


def verdict(result) -> list[str]:
    """The pose and what the verification said of it: its fitness, score, confidence and
    status (a result of ``align`` or ``align_views``)."""
    T = getattr(result, "T_scene_model", None)
    if T is None:
        T = result.T_current_reference
    fitness = getattr(result, "fitness", None)
    if fitness is None:
        fitness = result.support.score
    figures = [float(v).hex() for v in (fitness, result.score, result.confidence)]
    return fingerprint(T) + figures + [str(result.status)]


def poses(cases_per_cell: int) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for spec in case_lib.case_specs(case_lib.FAMILIES, ANGLES, cases_per_cell):
        case = case_lib.make_case(spec)
        model, scene = case.model_cloud(), case.scene_cloud()
        single_view = bool(np.all(np.isfinite(case.viewpoint)))
        ours = {"sensor_origin": case.viewpoint, "scene_view": "single_view"} if single_view else {}
        out[f"{spec.case_id}/ours"] = verdict(svs.align(model, scene, **ours))
        paper = svs.align(model, scene, global_search=False, max_iterations=30)
        out[f"{spec.case_id}/paper"] = verdict(paper)
        # The servo's registration: the reference prepared once, a bounded translation.
        params = svs.AlignParams()
        params.global_search = False
        params.max_translation = 0.1
        params.max_iterations = 10
        aligner = ModelAligner(svs.voxel_downsample(model, 0.004), params)
        bounded = aligner.align(svs.voxel_downsample(scene, 0.004), case.T_true)
        out[f"{spec.case_id}/bounded"] = verdict(bounded)
    return out


def view_poses(pairs_per_scan: int) -> dict[str, list[str]]:
    """``align_views`` on seeded view pairs: the global search, and the refinement of a
    prior pose (the true one) with a bounded budget of hypotheses."""
    out: dict[str, list[str]] = {}
    for scan in VIEW_SCANS:
        pairs = data.view_pairs(data.scan_path(scan), pairs_per_scan, seed=0, downscale=2)
        for index, pair in enumerate(pairs):
            key = f"views/{scan}-{index}"
            searched = svs.align_views(
                pair.reference, pair.current, sensor_origin=pair.current_viewpoint
            )
            out[f"{key}/search"] = verdict(searched)
            prior = svs.align_views(
                pair.reference,
                pair.current,
                sensor_origin=pair.current_viewpoint,
                hypotheses=4,
                refinements=2,
                prior=pair.T_current_reference,
            )
            out[f"{key}/prior"] = verdict(prior)
    return out


#: The servo's runs: every scenario on both arms, at most SERVO_STEPS steps each.
SERVO_ROBOTS = ("iiwa", "panda")
SERVO_SCENARIOS = ("clean", "box_25cm_1s", "stray_points")
SERVO_STEPS = 60


def servo_steps(starts: int) -> dict[str, list[str]]:
    """Every step of the servo's runs from the first ``starts`` moderate and large starts of
    seed 33 (the large ones relocalize, recover and carry): the estimate, twist, score,
    confidence, hold, recovery and status."""
    from spectral_vs import experiment, sim
    from spectral_vs.sim import scenarios

    out: dict[str, list[str]] = {}
    for robot_name in SERVO_ROBOTS:
        params = sim.SimParams(mode="kinematic", robot=sim.robot_model(robot_name))
        with sim.PyBulletRobot(params) as robot:
            T_reference, reference = robot.camera_pose(), robot.capture()
            home = params.robot.home_q
            chosen = [
                (f"{name}{index}", q)
                for name in ("moderate", "large")
                for index, (q, _, _) in enumerate(
                    experiment.start_poses(robot.kinematics, name, starts, 33, home)
                )
            ]
            for scenario in SERVO_SCENARIOS:
                for index, q in chosen:
                    _, log = scenarios.run_scenario(
                        robot, scenario, q, reference, T_reference, max_steps=SERVO_STEPS
                    )
                    for r in log.records:
                        figures = [float(v).hex() for v in (r.score, r.confidence)]
                        out[f"servo/{robot_name}-{scenario}-{index}/{r.step}"] = (
                            fingerprint(r.T_current_desired)
                            + fingerprint(r.twist)
                            + figures
                            + [r.hold, r.recovery, r.status.reason]
                        )
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases-per-cell", type=int, default=2)
    parser.add_argument(
        "--view-pairs", type=int, default=2, help="view pairs per scan for align_views (0: none)"
    )
    parser.add_argument(
        "--servo-starts", type=int, default=0, help="servo starts per arm and scenario (0: none)"
    )
    parser.add_argument("--output", type=Path, help="write the fingerprints here")
    parser.add_argument("--compare", type=Path, help="compare with fingerprints written before")
    args = parser.parse_args()
    current = poses(args.cases_per_cell)
    if args.view_pairs > 0:
        current |= view_poses(args.view_pairs)
    if args.servo_starts > 0:
        current |= servo_steps(args.servo_starts)
    if args.output:
        args.output.write_text(json.dumps(current, indent=1))
    print(f"{len(current)} poses")
    if args.compare:
        before = json.loads(args.compare.read_text())
        changed = sorted(k for k in before if before[k] != current.get(k))
        missing = sorted(set(before) ^ set(current))
        for key in changed:
            print(f"differs: {key}")
        if missing:
            print(f"not in both: {missing}")
        print(f"{len(before) - len(changed)} of {len(before)} poses bit-identical")
        return 1 if changed or missing else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
