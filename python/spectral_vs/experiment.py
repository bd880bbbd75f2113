"""The servo experiment's harness, shared by ``spectral-vs servo-sim`` and the benchmarks:
the seeded start poses (:data:`START_SETS`, :func:`start_poses`, :func:`random_start`), the
start check of the sets far from the goal (:class:`ViewCheck`, :func:`view_share`, from
:mod:`spectral_vs.field_of_view`), a robot wrapper that keeps the captured clouds for
figures (:class:`CloudRecorder`), a record as JSON (:func:`record_dict`) and the true camera
error of a run (:func:`true_errors`).

Nothing here needs PyBullet (the simulation, :mod:`spectral_vs.sim`, is one robot it runs
on); :func:`start_poses` reads the iiwa's home configuration from
:mod:`spectral_vs.sim.robots` only when none is given.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from spectral_vs._core import Kinematics, PointCloud
from spectral_vs.field_of_view import ViewCheck, view_share
from spectral_vs.poses import pose_error
from spectral_vs.robot import RobotInterface
from spectral_vs.servo.records import ServoLog, ServoRecord, ServoStatus
from spectral_vs.servo.settings import ServoParams

#: The start-pose sets of the servo experiment (benchmarks/servo_episodes.py) and of
#: ``spectral-vs servo-sim``: joint perturbation (rad) and the accepted camera displacement
#: from the reference pose (``random_start``'s ranges, m and degrees). A set with
#: ``min_view_share`` also needs a start check (``start_poses``'s ``accept``, a
#: :class:`ViewCheck`): at least that share of the reference's points in view, and the camera
#: above the table. "extreme" (0.45-0.6 m or 60-90 degrees): 7.5% of its draws pass for the
#: iiwa and 8.9% for the Panda (joint range 0.8 rad; 1.0 rad passed fewer, 6.7% and 6.1%).
START_SETS: dict[str, dict[str, Any]] = {
    "moderate": {"joint_range": 0.35, "translation": (0.0, 0.2), "rotation_deg": (0.0, 30.0)},
    "large": {"joint_range": 0.6, "translation": (0.2, 0.45), "rotation_deg": (30.0, 60.0)},
    "extreme": {
        "joint_range": 0.8,
        "translation": (0.45, 0.6),
        "rotation_deg": (60.0, 90.0),
        "min_view_share": 0.3,
    },
}


class CloudRecorder:
    """A :class:`RobotInterface` wrapper that keeps a subsample of every captured cloud.

    Parameters
    ----------
    robot : RobotInterface
        The robot to forward every call to.
    max_points : int
        Points kept per capture (a seeded random subsample), for figures.
    """

    def __init__(self, robot: RobotInterface, max_points: int = 3000) -> None:
        self.robot = robot
        self.max_points = max_points
        #: The kept clouds, (N, 3) float32 arrays in the camera frame, one per capture.
        self.clouds: list[np.ndarray] = []
        self._rng = np.random.default_rng(0)

    def joint_positions(self) -> np.ndarray:
        return self.robot.joint_positions()

    def send_joint_velocities(self, q_dot: np.ndarray, dt: float) -> None:
        self.robot.send_joint_velocities(q_dot, dt)

    def capture(self) -> PointCloud:
        cloud = self.robot.capture()
        points = np.asarray(cloud.points)
        if len(points) > self.max_points:
            points = points[self._rng.choice(len(points), self.max_points, replace=False)]
        self.clouds.append(points.astype(np.float32))
        return cloud

    def stop(self) -> None:
        self.robot.stop()

    def time(self) -> float:
        return self.robot.time()


def random_start(
    kinematics: Kinematics,
    q_reference: np.ndarray,
    rng: np.random.Generator,
    *,
    joint_range: float,
    translation_range: tuple[float, float] = (0.0, math.inf),
    rotation_range: tuple[float, float] = (0.0, math.inf),
    max_tries: int = 10000,
    accept: Callable[[np.ndarray], bool] | None = None,
) -> tuple[np.ndarray, float, float]:
    """A start configuration with every joint perturbed, for servoing back to ``q_reference``.

    Joints are drawn uniformly in ``q_reference +- joint_range`` (inside the position limits
    with a 0.05 rad margin) until the camera's displacement from the reference pose lies in
    the given ranges (and ``accept`` takes it): a seeded, reproducible set of start poses.

    Parameters
    ----------
    kinematics : Kinematics
        Camera kinematics of the robot.
    q_reference : ndarray, shape (n,)
        Configuration where the reference cloud is captured, rad.
    rng : numpy.random.Generator
        Source of the draws.
    joint_range : float
        Largest perturbation of each joint, rad.
    translation_range : (float, float)
        Accepted camera displacement ``[low, high)``, m.
    rotation_range : (float, float)
        Accepted camera rotation ``[low, high)``, rad. A start is accepted when it is below
        both upper bounds and, if a lower bound is not 0, at or beyond one of them (e.g.
        "0.2 m or 30 degrees and more, but under 0.4 m and 60 degrees").
    max_tries : int
        Draws before giving up.
    accept : callable, optional
        ``accept(q) -> bool``, asked about a draw in the ranges (e.g. a :class:`ViewCheck`);
        a draw it refuses is drawn again.

    Returns
    -------
    q : ndarray, shape (n,)
        The start configuration, rad.
    translation, rotation : float
        Its camera displacement from the reference pose, m and rad.

    Raises
    ------
    RuntimeError
        If no draw falls in the ranges.
    """
    q_reference = np.asarray(q_reference, dtype=float)
    lower = np.asarray(kinematics.lower_limits) + 0.05
    upper = np.asarray(kinematics.upper_limits) - 0.05
    T_reference = np.asarray(kinematics.forward(q_reference))
    for _ in range(max_tries):
        q = np.clip(
            q_reference + rng.uniform(-joint_range, joint_range, q_reference.size), lower, upper
        )
        t, r = pose_error(np.linalg.inv(np.asarray(kinematics.forward(q))) @ T_reference)
        (low_t, high_t), (low_r, high_r) = translation_range, rotation_range
        within = t < high_t and r < high_r
        beyond = (
            (low_t <= 0 and low_r <= 0) or (low_t > 0 and t >= low_t) or (low_r > 0 and r >= low_r)
        )
        if within and beyond and (accept is None or accept(q)):
            return q, t, r
    raise RuntimeError(f"no start pose in the ranges after {max_tries} draws")


def start_poses(
    kinematics: Kinematics,
    set_name: str,
    count: int,
    seed: int = 0,
    q_reference: Any = None,
    accept: Callable[[np.ndarray], bool] | None = None,
) -> list[tuple[np.ndarray, float, float]]:
    """The ``count`` seeded start configurations of one of :data:`START_SETS`.

    The same ``(set_name, seed, q_reference, accept)`` always gives the same sequence, and
    the first ``k`` of ``count`` starts are the ``k`` starts of a shorter request: the
    experiment, the command line and the benchmarks share their start poses.

    Parameters
    ----------
    kinematics : Kinematics
        Camera kinematics of the robot.
    set_name : str
        A key of :data:`START_SETS` (``"moderate"``, ``"large"`` or ``"extreme"``).
    count : int
        Number of starts, >= 1.
    seed : int
        Seed of the draws.
    q_reference : array_like, optional
        Configuration of the reference pose (the robot's home), rad; the iiwa's
        ``sim.HOME_Q`` by default.
    accept : callable, optional
        ``accept(q) -> bool``, the start check of :func:`random_start`. Needed by the sets
        with ``min_view_share`` ("extreme"): a :class:`ViewCheck` with that share, e.g.
        ``sim.PyBulletRobot.view_check``.

    Returns
    -------
    list of (q, translation, rotation)
        Start configuration (rad) and its camera displacement from the reference pose
        (m, rad), as :func:`random_start` returns them.

    Raises
    ------
    ValueError
        If ``set_name`` is not a set, ``count < 1``, or the set needs ``accept`` and it is
        not given.
    """
    if set_name not in START_SETS:
        raise ValueError(f"set_name must be one of {sorted(START_SETS)}, got {set_name!r}")
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    if "min_view_share" in START_SETS[set_name] and accept is None:
        share = START_SETS[set_name]["min_view_share"]
        raise ValueError(
            f"accept must be given for set_name {set_name!r}: its starts keep at least "
            f"{share:.0%} of the reference in view (a ViewCheck, e.g. "
            "sim.PyBulletRobot.view_check())"
        )
    if q_reference is None:
        from spectral_vs.sim.robots import HOME_Q

        q_reference = HOME_Q
    spec = START_SETS[set_name]
    rng = np.random.default_rng([seed, list(START_SETS).index(set_name)])
    return [
        random_start(
            kinematics,
            np.asarray(q_reference, dtype=float),
            rng,
            joint_range=spec["joint_range"],
            translation_range=spec["translation"],
            rotation_range=(
                math.radians(spec["rotation_deg"][0]),
                math.radians(spec["rotation_deg"][1]),
            ),
            accept=accept,
        )
        for _ in range(count)
    ]


def record_dict(record: ServoRecord) -> dict[str, Any]:
    """A JSON-ready dict of a record (arrays as lists, the status flattened)."""
    out: dict[str, Any] = {}
    for item in dataclasses.fields(record):
        value = getattr(record, item.name)
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, ServoStatus):
            value = dataclasses.asdict(value)
        out[item.name] = value
    return out


def true_errors(log: ServoLog, T_base_reference: np.ndarray) -> np.ndarray:
    """Camera pose error of every step against the reference pose: (steps, 2), mm and degrees.

    Uses ``ServoRecord.T_base_camera`` (filled by :func:`run_servo`), so it is the error
    that the robot's kinematics measure: the ground truth in a simulation.
    """
    T_ref = np.asarray(T_base_reference, dtype=float)
    out = []
    for record in log.records:
        if record.T_base_camera is None:
            raise ValueError("the log has no camera poses: it was not made by run_servo")
        t, r = pose_error(np.linalg.inv(record.T_base_camera) @ T_ref)
        out.append((1000.0 * t, math.degrees(r)))
    return np.array(out).reshape(-1, 2)


def servo_from(
    robot: Any,
    q: np.ndarray,
    reference: PointCloud,
    params: ServoParams | None = None,
    *,
    wrap: Callable[[Any], Any] | None = None,
    **run_options: Any,
) -> tuple[ServoLog, Any]:
    """One episode of the experiment: put the simulated ``robot`` at the start ``q`` (rad;
    ``robot.reset_joint_positions``, no motion) and servo its camera back to ``reference``
    with a fresh :class:`~spectral_vs.servo.SpectralServo` (``params``).

    ``wrap(robot)``, made after the reset, is what the servo drives (a
    :class:`CloudRecorder`, a fault of :mod:`spectral_vs.sim.faults`); ``run_options`` go
    to :func:`~spectral_vs.servo.run_servo` (``dt``, ``max_steps``, ...). Returns the log
    and the driven robot (the wrapper, or ``robot`` itself).
    """
    from spectral_vs.servo import SpectralServo, run_servo

    robot.reset_joint_positions(q)
    driven = robot if wrap is None else wrap(robot)
    log = run_servo(driven, robot.kinematics, SpectralServo(reference, params), **run_options)
    return log, driven


__all__ = [
    "START_SETS",
    "CloudRecorder",
    "ViewCheck",
    "random_start",
    "record_dict",
    "servo_from",
    "start_poses",
    "true_errors",
    "view_share",
]
