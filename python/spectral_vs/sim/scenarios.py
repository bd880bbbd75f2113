"""The scenarios the servo is tested and benchmarked under (docs/servoing.md, "What the servo
does when it cannot see"): what a wrist camera on a real arm goes through, each a wrapper
of :mod:`spectral_vs.sim.faults` around the simulated robot, set :data:`FAULT_AT` seconds
into the run (the servo is still on its way to the goal then).

- ``clean``: nothing;
- ``box_15cm_1s``, ``box_15cm_3s``: an 8 cm box 15 cm in front of the camera, following it,
  for 1 s and 3 s;
- ``box_25cm_1s``, ``box_25cm_3s``: a 12 cm box 25 cm in front, the same;
- ``hand_20cm``, ``hand_40cm``: a 10 x 20 cm box crossing the view at 0.25 m/s, 20 and 40 cm
  in front of the camera (a hand passing by);
- ``tool_left``: a 12 cm box appearing 25 cm in front of the camera and left there in the
  world for good (a tool left in view): the servo converges or stops with a reason;
- ``stray_points``: in every capture one point 10 km off, 1% of the pixels at random depths
  (0.1-5 m) and 5 non-finite rows;
- ``latency_1``, ``latency_2``: every capture one or two control periods late;
- ``dropped_frames``: captures 10, 15 and 20 empty;
- ``burst``: every capture empty for 0.3 s;
- ``stale_frames``: captures 10, 15 and 20 repeat the one before.

The latency scenarios run with the Kinect noise model (:meth:`DepthNoise.kinect`): a
noise-free renderer returns the very same frame for the same pose, so a late frame after a
held step would repeat the frame before it and be held as stale; a real sensor's frames
differ by their noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from spectral_vs.experiment import true_errors
from spectral_vs.poses import pose_error
from spectral_vs.servo.records import ServoLog
from spectral_vs.sim import faults

#: When each fault begins, s of robot clock since the run started.
FAULT_AT = 1.0
#: Capture indices of the single-frame faults (1.0, 1.5 and 2.0 s at 0.1 s a step).
FAULT_CAPTURES = (10, 15, 20)

#: How far the camera may go beyond its start error at any step of a scenario: mm, degrees.
EXCURSION_MM = 20.0
EXCURSION_DEG = 5.0


@dataclass(frozen=True)
class Scenario:
    """A fault a run goes through.

    Attributes
    ----------
    name : str
        Its key in :data:`SCENARIOS`.
    description : str
        What happens, for tables and figures.
    wrap : callable
        ``wrap(robot)``: the :class:`~spectral_vs.robot.RobotInterface` the servo drives,
        made right before the run (a :class:`~spectral_vs.sim.PyBulletRobot`).
    noise : bool
        Runs with the Kinect noise model.
    must_converge : bool
        The run must converge; False: converging or stopping with a reason are both right
        (a fault that never ends).
    """

    name: str
    description: str
    wrap: Callable[[Any], Any]
    noise: bool = False
    must_converge: bool = True


def _box(distance: float, size: float, duration: float) -> Callable[[Any], Any]:
    return lambda robot: faults.HandOccluder(
        robot, FAULT_AT, duration, distance=distance, size=size
    )


def _hand(distance: float) -> Callable[[Any], Any]:
    return lambda robot: faults.HandOccluder(
        robot, FAULT_AT, 2.0, distance=distance, size=(0.1, 0.2, 0.05), sweep=0.25
    )


_LIST = (
    Scenario("clean", "no fault", lambda robot: robot),
    Scenario("box_15cm_1s", "8 cm box 15 cm in front for 1 s", _box(0.15, 0.08, 1.0)),
    Scenario("box_15cm_3s", "8 cm box 15 cm in front for 3 s", _box(0.15, 0.08, 3.0)),
    Scenario("box_25cm_1s", "12 cm box 25 cm in front for 1 s", _box(0.25, 0.12, 1.0)),
    Scenario("box_25cm_3s", "12 cm box 25 cm in front for 3 s", _box(0.25, 0.12, 3.0)),
    Scenario("hand_20cm", "10 x 20 cm hand crossing the view 20 cm in front", _hand(0.2)),
    Scenario("hand_40cm", "10 x 20 cm hand crossing the view 40 cm in front", _hand(0.4)),
    Scenario(
        "tool_left",
        "12 cm box left in the world 25 cm in front of where the camera was",
        lambda robot: faults.HandOccluder(
            robot, FAULT_AT, math.inf, distance=0.25, size=0.12, follow=False
        ),
        must_converge=False,
    ),
    Scenario(
        "stray_points",
        "a point 10 km off, 1% of pixels at random depths, 5 non-finite rows, every frame",
        lambda robot: faults.StrayPoints(robot, far=1, random_share=0.01, non_finite=5),
    ),
    Scenario(
        "latency_1", "every frame 1 period late", lambda robot: faults.Latency(robot, 1), True
    ),
    Scenario(
        "latency_2", "every frame 2 periods late", lambda robot: faults.Latency(robot, 2), True
    ),
    Scenario(
        "dropped_frames",
        "captures 10, 15, 20 empty",
        lambda robot: faults.DroppedFrames(robot, FAULT_CAPTURES),
    ),
    Scenario(
        "burst", "every capture empty for 0.3 s", lambda robot: faults.Outage(robot, FAULT_AT, 0.3)
    ),
    Scenario(
        "stale_frames",
        "captures 10, 15, 20 repeat the one before",
        lambda robot: faults.RepeatedFrames(robot, FAULT_CAPTURES),
    ),
)

#: Every scenario, by name.
SCENARIOS: dict[str, Scenario] = {scenario.name: scenario for scenario in _LIST}


@dataclass
class ScenarioRun:
    """How one run through a scenario went, against the simulation's ground truth.

    Attributes
    ----------
    reason : str
        Why it ended (:data:`~spectral_vs.servo.REASONS`).
    final_mm, final_deg : float
        Camera error at the end, mm and degrees.
    worst_excursion_mm, worst_excursion_deg : float
        The largest camera error over the run minus the start's, mm and degrees (<= 0:
        never farther than at the start).
    held_steps : int
        Steps that held the robot still (``ServoRecord.hold``).
    steps : int
        Steps run.
    """

    reason: str
    final_mm: float
    final_deg: float
    worst_excursion_mm: float
    worst_excursion_deg: float
    held_steps: int
    steps: int

    def wandered(self) -> bool:
        """Whether the camera went farther than :data:`EXCURSION_MM` and
        :data:`EXCURSION_DEG` beyond its start error at some step."""
        return self.worst_excursion_mm > EXCURSION_MM or self.worst_excursion_deg > EXCURSION_DEG


def excursion(
    log: ServoLog, T_base_reference: np.ndarray, T_base_final: np.ndarray
) -> tuple[float, float]:
    """The largest camera error of a run (every step's capture pose, and ``T_base_final``,
    where it ended) minus the error at its first step: mm and degrees."""
    errors = true_errors(log, T_base_reference)
    t, r = pose_error(np.linalg.inv(np.asarray(T_base_final)) @ np.asarray(T_base_reference))
    worst_mm = max(float(errors[:, 0].max()), 1000.0 * t)
    worst_deg = max(float(errors[:, 1].max()), math.degrees(r))
    return worst_mm - float(errors[0, 0]), worst_deg - float(errors[0, 1])


def summarize(log: ServoLog, T_base_reference: np.ndarray, T_base_final: np.ndarray) -> ScenarioRun:
    """The :class:`ScenarioRun` of a run that ended at ``T_base_final``."""
    T_ref = np.asarray(T_base_reference, dtype=float)
    t, r = pose_error(np.linalg.inv(np.asarray(T_base_final)) @ T_ref)
    worst_mm, worst_deg = excursion(log, T_ref, T_base_final)
    return ScenarioRun(
        reason=log.reason,
        final_mm=1000.0 * t,
        final_deg=math.degrees(r),
        worst_excursion_mm=worst_mm,
        worst_excursion_deg=worst_deg,
        held_steps=sum(bool(record.hold) for record in log.records),
        steps=len(log.records),
    )


def run_scenario(
    robot: Any,
    scenario: Scenario | str,
    q_start: np.ndarray,
    reference: Any,
    T_base_reference: np.ndarray,
    params: Any = None,
    **run_options: Any,
) -> tuple[ScenarioRun, ServoLog]:
    """One run of :func:`spectral_vs.experiment.servo_from` through ``scenario`` from
    ``q_start`` (rad), back to ``reference`` captured at ``T_base_reference``; any box the
    scenario put in the simulation is removed afterwards. ``run_options`` go to
    :func:`~spectral_vs.servo.run_servo`. The robot's camera noise must be the scenario's
    (``Scenario.noise``)."""
    from spectral_vs.experiment import servo_from

    chosen = SCENARIOS[scenario] if isinstance(scenario, str) else scenario
    log, driven = servo_from(robot, q_start, reference, params, wrap=chosen.wrap, **run_options)
    remove = getattr(driven, "remove", None)
    if callable(remove):
        remove()
    return summarize(log, T_base_reference, robot.camera_pose()), log


__all__ = [
    "EXCURSION_DEG",
    "EXCURSION_MM",
    "FAULT_AT",
    "FAULT_CAPTURES",
    "SCENARIOS",
    "Scenario",
    "ScenarioRun",
    "excursion",
    "run_scenario",
    "summarize",
]
