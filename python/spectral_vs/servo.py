"""3D spectral visual servoing: the camera is driven to the pose where a reference cloud was
captured (paper, section II-D, eq. 16-18 and Algorithm 1).

At every control step the reference cloud (captured at the desired pose, camera frame) is
registered onto the current cloud (current camera frame): ``T_scene_model`` of
``align(model=reference, scene=current)`` is ``T_current_desired``, the pose of the desired
camera frame in the current one. The decoupled law

    v = lambda_t t,    omega = lambda_r theta u        (T_current_desired = [R(theta u) t])

gives the camera twist, expressed in the current camera frame, that :meth:`Kinematics.
joint_velocities` turns into joint velocities (eq. 18, ``q_dot = J_c^+ X_dot_c``). It is the
classical position-based law: the error ``(t, theta u)`` decays exponentially and the camera
origin moves along a straight line toward the desired one.

Two ways to get the estimate (``ServoParams.mode``):

``"iteration"``
    The paper: one update of Algorithm 1 per control step, from the identity, without the
    global rotation search. The robot's motion plays the role of the iterations.
``"pose"``
    A full registration per step (Algorithm 1 to convergence, with or without the global
    rotation search): a position-based servo on the converged estimate.

With ``ServoParams.warm_start`` each registration starts from the previous estimate carried
along the camera's measured motion instead of the identity (the most robust setting measured,
with ``"pose"``: docs/servoing.md).

:func:`run_servo` closes the loop on any :class:`~spectral_vs.robot.RobotInterface` and stops
the robot safely (zero velocity, with a reason) on a sensor outage longer than
``ServoParams.max_outage``, an implausible jump of the estimate, a joint limit, or a spent
budget. Shorter sensor faults (a dropped or repeated frame, too few points, a hand passing
in front of the camera) hold the robot still and the servo goes on (:data:`HOLDS`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from spectral_vs._core import (
    AlignParams,
    AlignResult,
    AxisRotationStep,
    Kinematics,
    ModelAligner,
    PointCloud,
    So3Correlation,
    VelocityCommandParams,
    ViewAlignParams,
    egi_coefficients,
    rotation_step_about,
    voxel_downsample,
)
from spectral_vs._core import align_views as _align_views
from spectral_vs.poses import pose_error, rotation_matrix, rotation_vector
from spectral_vs.registration import CloudLike, as_cloud, prepare
from spectral_vs.robot import RobotInterface
from spectral_vs.sensor_faults import frame_fingerprint, near_occluders

ServoMode = Literal["iteration", "pose"]
ServoState = Literal["running", "converged", "stopped"]

#: Why a servo run ended (``ServoStatus.reason``, ``ServoLog.reason``).
REASONS = (
    "converged",  # the estimated error is within the tolerances
    "empty_cloud",  # the camera sees nothing (peer servos; SpectralServo holds, HOLDS)
    "too_few_points",  # fewer than min_points (peer servos; SpectralServo holds, HOLDS)
    "sensor_outage",  # no usable frame (HOLDS) for longer than ServoParams.max_outage
    "jump",  # the estimate moved more than ServoParams.jump_limit_* since the last step
    "joint_limit",  # the joint velocity command had to clamp a joint at its position limit
    "max_steps",  # the step budget of run_servo is spent
    "max_time",  # the time budget of run_servo is spent (robot clock)
    "lost",  # the recovery (ServoParams.recover_after) ran recover_steps without a relocalization
)

#: Why :class:`SpectralServo` held the robot still at a step (``ServoRecord.hold``; ``""``
#: when it did not). A held step commands a zero twist, never converges and changes neither
#: the watchdog's nor the warm start's previous estimate; holds that last longer than
#: ``ServoParams.max_outage`` stop the servo with ``"sensor_outage"``.
HOLDS = (
    "empty_cloud",  # the capture has no point within max_depth (a dropped frame)
    "too_few_points",  # fewer than ServoParams.min_points points within max_depth
    "stale_frame",  # the frame of a previous step again (same fingerprint or capture stamp)
    "occluded",  # an occluder hides too much, or the registration without it is poor
)

#: The camera counts as still (a repeated frame is then no stale frame) while it has moved
#: less than this since the frame was first seen, m and rad.
_STILL_TRANSLATION = 1e-6
_STILL_ROTATION = 1e-6

#: Slack of the outage's comparison with max_outage, s: a robot clock adding up periods of
#: 0.1 s reads 0.30000000000000004 after three.
_CLOCK_TOLERANCE = 1e-9

#: Reference points kept for the occluder test (a strided subsample of the reference as
#: captured): its bins (2.9 degrees) then hold about 10 points each at 160 x 120.
_OCCLUSION_REFERENCE_POINTS = 5000

#: Current points that bound the view's field (a strided subsample), and the least depth
#: of a point in front of the camera, m (field_share).
_FIELD_POINTS = 4000
_FIELD_NEAR = 1e-3
#: The confidence of an estimate is its fitness over the share of the reference in the
#: field, but at least over this share (the extreme starts keep 30% in the field).
_MIN_FIELD_SHARE = 0.3


def _rigid_inverse(T: np.ndarray) -> np.ndarray:
    """The inverse of a rigid 4 x 4 transform, ``[R^T | -R^T t]``."""
    inverse = np.eye(4)
    inverse[:3, :3] = T[:3, :3].T
    inverse[:3, 3] = -(T[:3, :3].T @ T[:3, 3])
    return inverse


# --------------------------------------------------------------------------- settings


def _check_positive(params: Any, names: tuple[str, ...]) -> None:
    """Refuse settings ``names`` of ``params`` that are not > 0 (ValueError)."""
    for name in names:
        value = getattr(params, name)
        if not value > 0:  # also refuses NaN; inf turns a limit off
            raise ValueError(f"{name} must be > 0, got {value}")


@dataclass
class ServoParams:
    """Settings of :class:`SpectralServo`.

    Attributes
    ----------
    voxel_size : float
        Voxel edge of the registration, m. Whole-scene servoing over a table seen from about
        0.5 m works at 1-2 cm: coarser voxels are faster and smooth the view changes.
    downsample_size : float
        Both clouds are downsampled to voxels of this edge before the registration, m; 0:
        half of ``voxel_size``, as :func:`spectral_vs.align` does. At a whole voxel (the
        default) a near-goal step's registration took 1.3 ms instead of 2.5 (a quarter of
        the points for the EGI, the grid and the fitness), and the 20 moderate starts of
        ``servo-sim`` converged as at half a voxel, to 0.5-1.7 mm and under 0.15 degree
        (docs/servoing.md).
    bandwidth : int
        EGI bandwidth B: spherical harmonics of degree < B are correlated. A low bandwidth
        widens the basin of the rotation (8 here; at 16 the turn about the table normal
        stalled in the simulation, docs/servoing.md).
    max_rotation_step : float
        Largest rotation of one iteration of Algorithm 1, rad
        (``AlignParams.max_rotation_step``). Where the correlation's Hessian is not negative
        definite the rotation follows the gradient law, whose steps this bounds; 0.05 rad
        kept the servo from oscillating about the table's tilt.
    lambda_t : float
        Translation gain of the law ``v = lambda_t t``, 1/s. The error shrinks by the factor
        ``1 - lambda_t dt`` per control period ``dt``: keep ``lambda_t dt <= 1``.
    lambda_r : float
        Rotation gain of the law ``omega = lambda_r theta u``, 1/s; same bound.
    mode : {"iteration", "pose"}
        ``"iteration"``: the paper's single update of Algorithm 1 per step, from the identity,
        with a full phase-correlation shift and a full Newton rotation step (at most
        ``AlignParams.max_rotation_step``); the servo gains then scale the step.
        ``"pose"``: Algorithm 1 run to convergence (``max_iterations``) every step.
    global_search : bool
        ``"pose"`` mode only: start each registration from the global SO(3) search instead
        of the identity (slower; frees the estimate from the local basin).
    max_iterations : int
        ``"pose"`` mode: iterations of Algorithm 1 per step.
    warm_start : bool
        Start each registration from the previous estimate carried along the camera's
        measured motion (``T_previous_current^-1 T_current_desired``) instead of the identity.
        In ``"iteration"`` mode Algorithm 1's R and T then persist across control steps, as
        in the paper's listing; in ``"pose"`` mode the registration stays in the basin it
        found. Off by default (measured in docs/servoing.md).
    translation_tolerance : float
        Converged when the estimated translation error is below this, m ...
    rotation_tolerance : float
        ... and the estimated rotation error below this, rad (the servo form of eq. 17) ...
        The camera stops within about the tolerance plus the estimate's bias: at 1 mm and
        0.2 degree the iiwa's final errors had a median up to 1.4 mm; at 0.5 mm and 0.1
        degree, 0.6 mm on 6 moderate starts (docs/servoing.md).
    min_fitness : float
        ... and the registration's fitness (share of reference voxels matched) is at least
        this: a wrong local optimum can also have a small step. On a table top the table
        fills most voxels: a view 170 mm and 36 degrees off the goal reached 0.90 with an
        estimate under 1 mm, while views at the goal reach 0.97-1.
    step_tolerance : float
        Also converged when eq. (17) holds for the step itself: the phase-correlation shift
        (voxels) plus the norm of the normalised rotation gradient is below this. 0 turns
        this test off (the default: the pose tolerances are the clearer rule).
    reengage_translation : float
        Hysteresis of the stop rule, m: once converged, the servo stays converged (zero
        twist) until the estimated translation error exceeds this ...
    reengage_rotation : float
        ... or the estimated rotation error exceeds this, rad. At the goal the estimates
        of noisy views scatter wider than the tolerances: with the simulated Kinect noise
        the estimates of a still iiwa camera had a median of 0.54 mm and 0.17 degree, a
        99th percentile of 1.7 mm and 0.54 degree and a largest of 2.1 mm and 0.84 degree
        over 300 steps; a servo that re-engaged at each chased the noise, and the held
        camera wandered 0.8 mm and 0.5 degree (docs/reliability.md). Equal to the
        tolerances: no hysteresis. Only a servo stepped on after converging sees it
        (:func:`run_servo` ends at the first convergence); :meth:`SpectralServo.reset`
        forgets it.
    reengage_steps : int
        ... for this many steps in a row, >= 1: a single noisy view whose estimate leaves
        the bounds does not move the arm, an offset that lasts does. With 1 the soak's
        held camera re-engaged once in 900 steps (an estimate over 1 degree) and settled
        0.5 degree away.
    max_linear_speed : float
        Saturation of ``|v|``, m/s.
    max_angular_speed : float
        Saturation of ``|omega|``, rad/s. A twist over either limit is scaled down as a
        whole, so the camera keeps its direction of motion.
    jump_limit_translation : float
        Watchdog: largest plausible change of the estimated translation from one step to the
        next (after the camera's own measured motion is accounted for), m.
    jump_limit_rotation : float
        Watchdog: same for the rotation, rad.
    watchdog_fitness : float
        The watchdog is armed once an estimate with at least this fitness has been accepted
        (the registration has locked on). Before that the one-iteration estimate may jump
        between phase-correlation peaks as the view changes (measured: up to 0.6 m between
        steps in runs that then converged), and the speed limits bound the motion. Above 1
        the watchdog is never armed.
    max_translation : float
        Largest translation, per axis, that one registration seeks from its initial guess,
        m (``AlignParams.max_translation``): the phase-correlation grid then holds the two
        views grown by this instead of by the reference view's radius (about 0.5 m above
        the table), a grid 3-8 times smaller. Must exceed the displacement of the view's
        centroid, which a camera rotation adds to (30 degrees at 0.55 m: 0.28 m). 0: the
        paper's unbounded grid. Measured in docs/servoing.md.
    tracking_translation : float
        Once the registration has locked on (the watchdog is armed), or from the step after
        a relocalization was taken, the search is bounded
        by this instead of ``max_translation`` while the previous estimate, carried along
        the camera's measured motion, moves the reference's centroid by at most half of it
        from where the registration starts, m: near the goal the phase-correlation grid is
        then about 2 times smaller (measured 4.6 to 2.8 ms per registration with 0.1 m). A
        second prepared reference keeps its own FFT plans. Once locked on, a bounded
        estimate whose fitness is below ``watchdog_fitness`` is redone with
        ``max_translation`` (the answer may lie beyond the bound: a jump that the watchdog
        must see); before, the estimate is the carried one. 0, or not
        below ``max_translation``: always ``max_translation``.
    max_depth : float
        Points farther than this along the optical axis are ignored (both clouds), m. The
        registration grid spans both clouds: a camera turned toward the horizon would
        otherwise add the far floor and walls and slow every step (measured: from 0.1 to
        over 1 s per step). ``inf`` keeps everything.
    min_points : int
        Hold (``"too_few_points"``, :data:`HOLDS`) when the current cloud has fewer points
        (within ``max_depth``).
    max_outage : float
        Longest sensor outage the servo rides, s: while the captures are empty, too small,
        stale or occluded (:data:`HOLDS`) it holds the robot still, and it stops with
        ``"sensor_outage"`` once the time since the last accepted frame (or since the first
        fault, when none was accepted yet) exceeds this. Measured on the ``now`` that
        :meth:`SpectralServo.step` is given (:func:`run_servo`: the robot clock), else on
        the computer's monotonic clock. 0: stop at the first fault (the behaviour before
        the holds).
    occlusion_margin : float
        Occluder test, m: once locked on (the watchdog is armed), current points more than
        this nearer to the camera than any surface of the reference could be (its nearest
        point, the reference placed by the previous estimate carried along the camera's
        measured motion; :func:`spectral_vs.sensor_faults.near_occluders`) are dropped
        before the registration. It covers the estimate's error in depth and the depth
        noise; a hand 0.25 m from the camera over the simulated table is 0.14-0.2 m nearer
        than the objects' tops. ``inf`` turns the test off.
    occlusion_min_share : float
        An occluder is present when at least this share of the current cloud's points are
        dropped as occluders, in [0, 1]. While one is present the step holds
        (``"occluded"``) if fewer than ``min_points`` points remain, if the estimate would
        trip the watchdog, or if its fitness over the reference's visible part (fitness /
        (1 - hidden share)) is below ``watchdog_fitness``; otherwise the servo moves on the
        registration of the rest.
    relocalize : bool
        Register the reference onto the current view globally
        (:func:`spectral_vs.align_views`: any rotation, any translation within the views)
        when the servo has no trusted estimate: at its first step, and after a registration
        whose confidence was below ``relocalize_fitness`` (the view moved far, or the
        estimate slid off), at most every ``relocalize_interval`` steps. The estimate
        tracked so far goes in as the global search's prior: it is refined beside the
        search's hypotheses and kept unless a searched pose is better supported. The
        result, if its support score reaches ``relocalize_score``, becomes the estimate
        the step's cheap registration starts from; from then on every registration starts
        from the last estimate carried along the camera's measured motion (the warm
        start) and seeks only ``tracking_translation``, so the servo tracks it.
    relocalize_fitness : float
        Least confidence of a tracked estimate, in [0, 1]: its fitness over the part of
        the reference that the estimate puts inside the current view's field (the
        fitness counts the whole reference; a view that sees half of it fits at most
        half). Below it the servo relocalizes.
    relocalize_interval : int
        Least number of steps from a confirmed relocalization to the next, >= 1: a global
        registration costs 10-30 steps' worth of tracking. Confirmed: its support score
        reached ``relocalize_score`` and the step's registration from it reached the
        confidence ``relocalize_fitness``.
    relocalize_retry : int
        Least number of steps from an unconfirmed relocalization to the next, in [1,
        ``relocalize_interval``]: from a view the search cannot register (the views share
        too little) the camera moves on, and a later view may do.
    relocalize_backoff : int
        Growth of that spacing while the relocalizations stay unconfirmed, >= 1: after
        ``n`` unconfirmed ones in a row the next waits ``relocalize_retry *
        relocalize_backoff^(n - 1)`` steps, at most ``relocalize_interval`` (2, 4, 8, 10
        steps by default). A global registration costs 0.1-0.35 s, 20-70 steps of
        tracking: a start that stays lost spent a relocalization every other step, and
        their time set the 95th percentile of the step time (docs/servoing.md). 1: a
        fixed ``relocalize_retry``. Counted afresh once an estimate is confident again.
    relocalize_score : float
        Least support score (:class:`spectral_vs.ViewSupport`) of a global registration
        that the servo takes, in [0, 1]; below it the step goes on from its own estimate.
    recover_after : int
        Recovery from a view the global registration cannot register (docs/servoing.md,
        "Recovery"): after this many relocalizations in a row under ``relocalize_score``,
        with none taken yet, the servo stops following its local estimate (which, from a
        view that shares little with the reference, drifts farther off) and moves the
        camera to widen the overlap, relocalizing on at ``relocalize_retry``. When both the
        reference and the current view have a dominant plane (``min_plane_share``, within
        ``plane_cone``; a table top), it levels the camera onto it: the rotation that takes
        the reference's plane normal to where the current view sees its own, about the
        camera's origin, and the distance to the plane of the reference plus
        ``recover_standoff``. Otherwise it backs off along its optical axis by
        ``recover_standoff`` from where the recovery started. 0: no recovery.
    recover_standoff : float
        How much farther from the scene than the reference the recovery takes the camera,
        m (>= 0): a farther view sees more of the scene.
    recover_score : float
        Least support score of a global registration taken during the recovery, in [0, 1]
        (``relocalize_score`` otherwise): the recovery widens the view step by step, so a
        marginal score in its middle is waited out (a pose 17 degrees off scored 0.061
        there; the right ones 0.09-0.19).
    recover_steps : int
        Longest recovery, steps (>= 1): when no relocalization was taken within it, the
        servo stops with ``"lost"``.
    plane_turn : bool
        Turn each estimate about the reference's dominant normal (a table top's) by the
        step that ascends the correlation of the EGIs without that plane: a Newton step
        along the axis (the gradient law where the correlation is not concave along it), at
        most ``max_rotation_step``. The plane fills most of the EGI and leaves the rotation
        about its normal almost unseen: 22 degrees off about the table's normal changed the
        correlation by 2e-4 and the Hessian was not negative definite, so Algorithm 1 fell
        back to the gradient law, which chattered about the table's tilt while the camera
        drifted 100 mm off (moderate starts 3 and 13 failed; docs/servoing.md). Without the
        plane the objects' sides give that rotation a clear peak. Used only when the
        reference has a dominant plane (``min_plane_share``).
    plane_cone : float
        Half-angle of the cone about the dominant normal whose normals count as the plane's
        (left out of the turn's EGIs), rad.
    min_plane_share : float
        The plane turn is used when at least this share of the reference's normals lies in
        the cone, in [0, 1].
    plane_turn_bandwidth : int
        Fine EGI bandwidth of the plane turn: near the goal, where the step at ``bandwidth``
        is an uncapped Newton step, the turn is the Newton step at this bandwidth.
    plane_turn_stride : int
        The plane turn's EGIs take the off-plane normals among every
        ``plane_turn_stride``-th normal of the clouds as captured. Not downsampled:
        downsampling to voxels mixes the normals at the objects' edges differently from
        view to view, which biased the turn by about 0.5 degree near the goal.
    plane_turn_tilt : float
        No plane turn while the current view's plane normal is farther than this from where
        the estimate puts the reference's, rad: the turn would be measured about a wrong
        axis (far from the goal it turned a large start the wrong way).
    align_overrides : dict
        Further :class:`AlignParams` fields, e.g. ``{"threads": 2}``.
    view_overrides : dict
        :class:`spectral_vs.ViewAlignParams` fields of the relocalization, e.g.
        ``{"hypotheses": 24}`` (by default every length is derived from the views).
    """

    voxel_size: float = 0.015
    downsample_size: float = 0.015
    bandwidth: int = 8
    max_rotation_step: float = 0.05
    lambda_t: float = 2.0
    lambda_r: float = 4.0
    mode: ServoMode = "iteration"
    global_search: bool = False
    max_iterations: int = 30
    warm_start: bool = False
    translation_tolerance: float = 0.0005
    rotation_tolerance: float = math.radians(0.1)
    min_fitness: float = 0.95
    step_tolerance: float = 0.0
    reengage_translation: float = 0.003
    reengage_rotation: float = math.radians(1.0)
    reengage_steps: int = 3
    max_linear_speed: float = 0.1
    max_angular_speed: float = math.radians(20.0)
    jump_limit_translation: float = 0.1
    jump_limit_rotation: float = math.radians(10.0)
    watchdog_fitness: float = 0.9
    max_translation: float = 0.3
    tracking_translation: float = 0.1
    max_depth: float = 1.5
    min_points: int = 500
    max_outage: float = 0.5
    occlusion_margin: float = 0.05
    occlusion_min_share: float = 0.01
    relocalize: bool = True
    relocalize_fitness: float = 0.8
    relocalize_interval: int = 10
    relocalize_retry: int = 2
    relocalize_backoff: int = 2
    relocalize_score: float = 0.05
    recover_after: int = 3
    recover_standoff: float = 0.15
    recover_score: float = 0.08
    recover_steps: int = 60
    plane_turn: bool = True
    plane_cone: float = math.radians(20.0)
    min_plane_share: float = 0.3
    plane_turn_bandwidth: int = 16
    plane_turn_stride: int = 4
    plane_turn_tilt: float = math.radians(5.0)
    align_overrides: dict[str, Any] = field(default_factory=dict)
    view_overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in ("iteration", "pose"):
            raise ValueError(f"mode must be 'iteration' or 'pose', got {self.mode!r}")
        _check_positive(
            self,
            (
                "voxel_size",
                "max_rotation_step",
                "lambda_t",
                "lambda_r",
                "translation_tolerance",
                "rotation_tolerance",
                "max_linear_speed",
                "max_angular_speed",
                "jump_limit_translation",
                "jump_limit_rotation",
                "max_depth",
            ),
        )
        if not (self.max_translation >= 0 and math.isfinite(self.max_translation)):
            raise ValueError(
                f"max_translation must be >= 0 m (0: unbounded), got {self.max_translation}"
            )
        if not (self.downsample_size >= 0 and math.isfinite(self.downsample_size)):
            raise ValueError(
                f"downsample_size must be >= 0 m (0: voxel_size / 2), got {self.downsample_size}"
            )
        if not (self.tracking_translation >= 0 and math.isfinite(self.tracking_translation)):
            raise ValueError(
                f"tracking_translation must be >= 0 m (0: off), got {self.tracking_translation}"
            )
        for name, tolerance in (
            ("reengage_translation", "translation_tolerance"),
            ("reengage_rotation", "rotation_tolerance"),
        ):
            if not getattr(self, name) >= getattr(self, tolerance):
                raise ValueError(
                    f"{name} must be >= {tolerance} = {getattr(self, tolerance)}, "
                    f"got {getattr(self, name)}"
                )
        if not self.step_tolerance >= 0:
            raise ValueError(f"step_tolerance must be >= 0, got {self.step_tolerance}")
        if not 0.0 <= self.min_fitness <= 1.0:
            raise ValueError(f"min_fitness must be in [0, 1], got {self.min_fitness}")
        for name in ("relocalize_fitness", "relocalize_score", "recover_score"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        if not 0.0 < self.plane_cone < math.pi / 2:
            raise ValueError(f"plane_cone must be in (0, pi/2) rad, got {self.plane_cone}")
        if not 0.0 <= self.min_plane_share <= 1.0:
            raise ValueError(f"min_plane_share must be in [0, 1], got {self.min_plane_share}")
        if not self.watchdog_fitness >= 0.0:
            raise ValueError(f"watchdog_fitness must be >= 0, got {self.watchdog_fitness}")
        if self.plane_turn_bandwidth < 2:
            raise ValueError(f"plane_turn_bandwidth must be >= 2, got {self.plane_turn_bandwidth}")
        if not 0.0 < self.plane_turn_tilt <= self.plane_cone:
            raise ValueError(
                f"plane_turn_tilt must be in (0, plane_cone] rad, got {self.plane_turn_tilt}"
            )
        if self.plane_turn_stride < 1:
            raise ValueError(f"plane_turn_stride must be >= 1, got {self.plane_turn_stride}")
        if self.bandwidth < 2:
            raise ValueError(f"bandwidth must be >= 2, got {self.bandwidth}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if self.relocalize_interval < 1:
            raise ValueError(
                f"relocalize_interval must be >= 1 step, got {self.relocalize_interval}"
            )
        if not 1 <= self.relocalize_retry <= self.relocalize_interval:
            raise ValueError(
                f"relocalize_retry must be in [1, relocalize_interval = "
                f"{self.relocalize_interval}] steps, got {self.relocalize_retry}"
            )
        if self.relocalize_backoff < 1:
            raise ValueError(f"relocalize_backoff must be >= 1, got {self.relocalize_backoff}")
        if self.recover_after < 0:
            raise ValueError(
                f"recover_after must be >= 0 relocalizations (0: no recovery), "
                f"got {self.recover_after}"
            )
        if not (self.recover_standoff >= 0 and math.isfinite(self.recover_standoff)):
            raise ValueError(
                f"recover_standoff must be finite and >= 0 m, got {self.recover_standoff}"
            )
        if self.recover_steps < 1:
            raise ValueError(f"recover_steps must be >= 1 step, got {self.recover_steps}")
        if self.reengage_steps < 1:
            raise ValueError(f"reengage_steps must be >= 1 step, got {self.reengage_steps}")
        if self.min_points < 1:
            raise ValueError(f"min_points must be >= 1, got {self.min_points}")
        if not (self.max_outage >= 0 and math.isfinite(self.max_outage)):
            raise ValueError(
                f"max_outage must be finite and >= 0 s (0: stop at the first fault), "
                f"got {self.max_outage}"
            )
        if not self.occlusion_margin > 0:
            raise ValueError(
                f"occlusion_margin must be > 0 m (inf: no occluder test), "
                f"got {self.occlusion_margin}"
            )
        if not 0.0 <= self.occlusion_min_share <= 1.0:
            raise ValueError(
                f"occlusion_min_share must be in [0, 1], got {self.occlusion_min_share}"
            )

    def uses_tracking(self) -> bool:
        """True when the locked-on registration uses ``tracking_translation``."""
        bounded = self.align_params().max_translation > 0
        return bounded and 0 < self.tracking_translation < self.max_translation

    def align_params(self) -> AlignParams:
        """The :class:`AlignParams` of one registration in this mode."""
        params = AlignParams()
        params.voxel_size = self.voxel_size
        params.bandwidth = self.bandwidth
        params.max_rotation_step = self.max_rotation_step
        params.initial_guess = np.eye(4)
        # The servo reads only the fitness: no pose verification (2 ms per step).
        params.verify = False
        unbounded = self.mode == "pose" and self.global_search
        params.max_translation = 0.0 if unbounded else self.max_translation
        if self.mode == "iteration":
            params.global_search = False
            params.max_iterations = 1
            params.translation_gain = 1.0
            params.rotation_gain = 1.0
        else:
            params.global_search = self.global_search
            params.max_iterations = self.max_iterations
            params.refinement_iterations = self.max_iterations  # the global search's runs
        for name, value in self.align_overrides.items():
            if not hasattr(params, name) or name.startswith("_"):
                raise ValueError(f"unknown alignment setting {name!r} in align_overrides")
            setattr(params, name, value)
        return params


# --------------------------------------------------------------------------- results


@dataclass
class ServoStatus:
    """Where the servo stands after a step.

    Attributes
    ----------
    state : {"running", "converged", "stopped"}
        ``"stopped"`` means the robot must not move (the twist is zero).
    reason : str
        ``""`` while running, else one of :data:`REASONS`.
    message : str
        Details for a person, e.g. the size of a rejected jump, or why a running step held
        the robot still (``ServoRecord.hold``).
    """

    state: ServoState = "running"
    reason: str = ""
    message: str = ""


@dataclass
class ServoRecord:
    """One control step.

    Attributes
    ----------
    step : int
        Index of the step, from 0.
    time : float
        Robot clock at the capture, s (NaN from :meth:`SpectralServo.step` alone).
    points : int
        Points of the current cloud within ``ServoParams.max_depth``.
    T_current_desired : ndarray, shape (4, 4)
        The estimate: pose of the desired camera frame in the current camera frame (the
        one-iteration step in ``"iteration"`` mode). Identity when no registration ran.
    translation_error : float
        ``|t|`` of the estimate, m.
    rotation_error : float
        Angle of the estimate, rad.
    translation_cost, rotation_cost : float
        J_t (eq. 9, voxel grids) and J_r (eq. 16, normalised EGI coefficients) of the last
        iteration of Algorithm 1.
    translation_step : float
        Phase-correlation shift of the last iteration, voxels.
    rotation_gradient : float
        ``|grad C|`` of the last iteration, normalised correlation per rad.
    iterations : int
        Iterations of Algorithm 1 this step.
    fitness : float
        Share of the reference's voxels matched in the current cloud at the estimate.
    twist : ndarray, shape (6,)
        Commanded camera twist (v in m/s, omega in rad/s), camera frame, after saturation.
    saturation : float
        Factor in (0, 1] the twist was scaled by to meet the speed limits.
    seconds : float
        Wall time of the step (registration and control law), s.
    cpu_seconds : float
        CPU time of the process during the step (``time.process_time``), s: what a busy
        machine does not inflate as it does the wall time.
    status : ServoStatus
        The outcome of the step.
    q, q_dot : ndarray or None
        Joint positions at the capture and the joint velocities sent (:func:`run_servo`).
    T_base_camera : ndarray or None
        Camera pose from the kinematics at ``q`` (:func:`run_servo`).
    velocity_scale : float
        ``VelocityCommand.velocity_scale`` of the joint command (1 when not limited).
    plane_turn : float
        Turn about the reference's dominant normal added to the estimate, rad
        (``ServoParams.plane_turn``; 0 when not used).
    tracking : bool
        The estimate is the registration that sought only
        ``ServoParams.tracking_translation`` (False also when it was redone with
        ``max_translation`` for a poor fitness).
    hold : str
        Why the step held the robot still (zero twist), one of :data:`HOLDS`; ``""`` when
        it did not. A held step never converges and changes neither the watchdog's nor the
        warm start's previous estimate; its ``status`` is ``running`` (the message says
        why) or, after ``ServoParams.max_outage``, ``stopped`` with ``"sensor_outage"``.
        At an ``"occluded"`` hold after a registration, the estimate's fields (
        ``T_current_desired``, the errors, ``fitness``) are those of the rejected one.
    outage : float
        Time without an accepted frame at a held step, s (see ``ServoParams.max_outage``);
        0 when the step was not held.
    occluded_points : int
        Points of the current cloud dropped as nearer to the camera than the reference
        could be (``ServoParams.occlusion_margin``); 0 when the occluder test did not run.
    hidden_share : float
        Share of the reference that those occluders hide, in [0, 1].
    relocalized : bool
        The step started from a global registration (``ServoParams.relocalize``).
    relocalization_score : float
        Support score of the global registration tried this step (NaN when none was).
    relocalization_prior : bool
        The global registration kept the servo's own estimate (its prior, refined) over
        every searched pose.
    confidence : float
        The registration's fitness over the part of the reference that its estimate puts
        inside the current view's field, in [0, 1] (``ServoParams.relocalize_fitness``);
        NaN when no registration ran.
    carried : bool
        The estimate is the last accepted one carried along the camera's measured motion,
        not the registration's: after a relocalization and before lock-on (a fitness of
        ``watchdog_fitness``), where the views share too little for Algorithm 1's step.
    recovery : str
        ``""``, or how the step moved the camera to widen its overlap with the reference
        (``ServoParams.recover_after``): ``"level"`` (onto the reference's plane, at its
        distance plus ``recover_standoff``) or ``"back_off"`` (along the optical axis).
        ``T_current_desired`` and the errors are then those of the recovery's target pose,
        no registration ran (``fitness`` and ``confidence`` NaN), and the step never
        converges.
    """

    step: int
    time: float
    points: int
    T_current_desired: np.ndarray
    translation_error: float
    rotation_error: float
    translation_cost: float
    rotation_cost: float
    translation_step: float
    rotation_gradient: float
    iterations: int
    fitness: float
    twist: np.ndarray
    saturation: float
    seconds: float
    status: ServoStatus
    q: np.ndarray | None = None
    q_dot: np.ndarray | None = None
    T_base_camera: np.ndarray | None = None
    velocity_scale: float = 1.0
    plane_turn: float = 0.0
    tracking: bool = False
    hold: str = ""
    outage: float = 0.0
    occluded_points: int = 0
    hidden_share: float = 0.0
    relocalized: bool = False
    relocalization_score: float = math.nan
    relocalization_prior: bool = False
    confidence: float = math.nan
    carried: bool = False
    recovery: str = ""
    cpu_seconds: float = 0.0


@dataclass
class ServoLog:
    """A servo run: its records, why it ended and in which state.

    Attributes
    ----------
    records : list of ServoRecord
        Every control step, in order.
    status : ServoStatus
        The final status; ``status.reason`` is one of :data:`REASONS`.
    wall_seconds : float
        Wall time of the whole run, s.
    """

    records: list[ServoRecord] = field(default_factory=list)
    status: ServoStatus = field(default_factory=ServoStatus)
    wall_seconds: float = 0.0

    @property
    def reason(self) -> str:
        """Why the run ended (one of :data:`REASONS`)."""
        return self.status.reason

    @property
    def converged(self) -> bool:
        """True when the run ended because the tolerances were met."""
        return self.status.state == "converged"

    def array(self, name: str) -> np.ndarray:
        """One field of every record stacked in an array, e.g. ``log.array("twist")``."""
        return np.array([getattr(record, name) for record in self.records])


# --------------------------------------------------------------------------- controller


def _saturated_twist(
    translation: np.ndarray, rotvec: np.ndarray, law: Any
) -> tuple[np.ndarray, float]:
    """``(lambda_t t, lambda_r theta u)`` scaled down as a whole to the speed limits, and
    the scale; ``law`` has the gains ``lambda_t``, ``lambda_r`` (1/s) and the limits
    ``max_linear_speed`` (m/s), ``max_angular_speed`` (rad/s) (:meth:`SpectralServo.twist`)."""
    v = law.lambda_t * np.asarray(translation, dtype=float)
    omega = law.lambda_r * np.asarray(rotvec, dtype=float)
    scale = 1.0
    speed, turn = float(np.linalg.norm(v)), float(np.linalg.norm(omega))
    if speed > law.max_linear_speed:
        scale = min(scale, law.max_linear_speed / speed)
    if turn > law.max_angular_speed:
        scale = min(scale, law.max_angular_speed / turn)
    return np.concatenate([v, omega]) * scale, scale


def _empty_record(step: int, points: int) -> ServoRecord:
    """The record of a step before anything is measured: no estimate, zero twist."""
    return ServoRecord(
        step=step,
        time=math.nan,
        points=points,
        T_current_desired=np.eye(4),
        translation_error=math.nan,
        rotation_error=math.nan,
        translation_cost=math.nan,
        rotation_cost=math.nan,
        translation_step=math.nan,
        rotation_gradient=math.nan,
        iterations=0,
        fitness=math.nan,
        twist=np.zeros(6),
        saturation=1.0,
        seconds=0.0,
        status=ServoStatus(),
    )


def _too_few_points(count: int, message: str) -> ServoStatus:
    """The stop for an input with ``count`` usable points (or pixels), below the minimum (the
    baselines' servos; :class:`SpectralServo` holds instead, :data:`HOLDS`)."""
    return ServoStatus("stopped", "empty_cloud" if count == 0 else "too_few_points", message)


def _converged_status(translation: float, rotation: float) -> ServoStatus:
    """Converged, with the estimated error (m, rad) in the message."""
    return ServoStatus(
        "converged",
        "converged",
        f"estimated error {1000 * translation:.2f} mm, {math.degrees(rotation):.3f} deg",
    )


def field_share(
    reference_points: np.ndarray,
    T_current_reference: np.ndarray,
    current_points: np.ndarray,
    max_depth: float = math.inf,
) -> float:
    """The share of ``reference_points`` that ``T_current_reference`` puts inside the
    current view's field: in front of the camera, nearer than ``max_depth`` and within the
    bounds of the current points' x/z and y/z (a pinhole camera's image rectangle, as far as
    the view has returns), in [0, 1]. Occlusion is ignored."""
    reference = np.asarray(reference_points, dtype=float)
    current = np.asarray(current_points, dtype=float)
    if len(reference) == 0 or len(current) == 0:
        return 0.0
    current = current[:: max(1, len(current) // _FIELD_POINTS)]
    current = current[current[:, 2] > _FIELD_NEAR]
    if len(current) == 0:
        return 0.0
    u = current[:, 0] / current[:, 2]
    v = current[:, 1] / current[:, 2]
    T = np.asarray(T_current_reference, dtype=float)
    moved = reference @ T[:3, :3].T + T[:3, 3]
    z = moved[:, 2]
    front = (z > _FIELD_NEAR) & (z <= max_depth)
    z = np.where(front, z, 1.0)
    mu, mv = moved[:, 0] / z, moved[:, 1] / z
    inside = front & (mu >= u.min()) & (mu <= u.max()) & (mv >= v.min()) & (mv <= v.max())
    return float(inside.mean())


def dominant_normal(normals: np.ndarray, cone: float) -> tuple[np.ndarray, float]:
    """The dominant direction of unit normals (a table top's normal) and its share.

    Starting from the normals' mean, the direction is replaced a few times by the mean of
    the normals within ``cone`` of it.

    Parameters
    ----------
    normals : ndarray, shape (N, 3)
        Unit normals.
    cone : float
        Half-angle of the cone around the direction, rad.

    Returns
    -------
    axis : ndarray, shape (3,)
        The unit direction (``(0, 0, 1)`` for normals that cancel out).
    share : float
        Share of the normals within ``cone`` of it, in [0, 1].
    """
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    axis = normals.mean(axis=0) if len(normals) else np.zeros(3)
    if not np.linalg.norm(axis) > 1e-9:
        return np.array([0.0, 0.0, 1.0]), 0.0
    axis = axis / np.linalg.norm(axis)
    inside = np.zeros(len(normals), dtype=bool)
    for _ in range(5):
        inside = normals @ axis > math.cos(cone)
        if not inside.any():
            break
        axis = normals[inside].mean(axis=0)
        axis = axis / np.linalg.norm(axis)
    return axis, float(inside.mean())


def dominant_plane(
    points: np.ndarray, normals: np.ndarray, cone: float, min_share: float
) -> tuple[np.ndarray, float] | None:
    """The dominant plane of a view (a table top), camera frame: its unit normal ``n``
    (:func:`dominant_normal`, turned toward the camera) and the camera's distance to it,
    ``d`` = -median(n . p) over the points whose normals lie within ``cone`` of ``n``, m;
    None when fewer than ``min_share`` of the normals do or the camera is not in front of it.
    """
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    axis, share = dominant_normal(normals, cone)
    if share < min_share or share == 0.0:
        return None
    inside = normals @ axis > math.cos(cone)
    distance = -float(np.median(np.asarray(points, dtype=float).reshape(-1, 3)[inside] @ axis))
    return (axis, distance) if distance > 0 else None


def _turn_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the unit vector ``a`` to the unit vector ``b``."""
    axis = np.cross(a, b)
    sine = float(np.linalg.norm(axis))
    if sine < 1e-12:
        return np.eye(3)  # parallel (normals turned toward the camera are never opposite)
    return rotation_matrix(axis / sine * math.atan2(sine, float(a @ b)))


#: Fewest normals off the dominant plane (reference or current view) for the plane turn.
_MIN_OFF_PLANE = 50


@dataclass
class _PlaneTurn:
    """The reference's side of the turn about its dominant normal (``ServoParams.plane_turn``).

    Attributes
    ----------
    axis : ndarray, shape (3,)
        The reference's dominant normal (the table's), reference camera frame.
    centroid : ndarray, shape (3,)
        The reference's centroid, m: the registration turns the reference about it.
    coefficients : ndarray, shape (B**2,)
        EGI coefficients of the reference's normals outside ``plane_cone`` of ``axis``.
    bandwidth : int
        Their bandwidth B (the larger of ``plane_turn_bandwidth`` and ``bandwidth``).
    cos_cone : float
        Cosine of ``ServoParams.plane_cone``.
    law : AlignParams
        The rotation law the turn steps by (:func:`spectral_vs.rotation_step_about`): the
        registration's ``rotation_step`` and ``max_rotation_step`` with a
        ``rotation_gain`` of 1, so that the turn is one whole step, as the
        ``"iteration"`` estimate takes it (in ``"pose"`` mode a half Newton step after
        the converged registration left 0.6 degree about the table's normal).
    params : ServoParams
        The servo's settings (``plane_turn_stride``, ``max_rotation_step``).
    """

    axis: np.ndarray
    centroid: np.ndarray
    coefficients: np.ndarray
    bandwidth: int
    cos_cone: float
    law: AlignParams
    params: ServoParams

    @staticmethod
    def of(
        reference: PointCloud, centroid: np.ndarray, params: ServoParams, law: AlignParams
    ) -> _PlaneTurn | None:
        """The turn's reference side from the reference's normals (the cloud as captured,
        cropped), or None when the reference has no dominant plane."""
        normals = np.asarray(reference.normals)
        axis, share = dominant_normal(normals, params.plane_cone)
        cos_cone = math.cos(params.plane_cone)
        sampled = normals[:: params.plane_turn_stride]
        off = sampled[sampled @ axis <= cos_cone]
        if share < params.min_plane_share or len(off) < _MIN_OFF_PLANE:
            return None
        bandwidth = max(params.plane_turn_bandwidth, params.bandwidth)
        coefficients = np.asarray(egi_coefficients(off, bandwidth))
        law = copy.copy(law)
        law.rotation_gain = 1.0
        return _PlaneTurn(axis, centroid, coefficients, bandwidth, cos_cone, law, params)

    def turn(self, normals: np.ndarray, T_scene_model: np.ndarray) -> float:
        """The turn about ``axis`` (rad, right-multiplied: ``R exp(turn axis)``) that ascends
        the correlation of the off-plane EGIs from the estimate ``T_scene_model``, given the
        current cloud's normals (as captured, cropped); 0 when the current view shows too
        few normals off its plane, or when its plane's normal (the mean of its normals
        within ``plane_cone`` of where the estimate puts it) is more than
        ``plane_turn_tilt`` away from there.

        Coarse to fine: the step at the registration's bandwidth (a Newton step where the
        correlation is concave along the axis, else the gradient law, at most
        ``max_rotation_step``); where that is an uncapped Newton step and the correlation at
        ``plane_turn_bandwidth`` is concave too, its Newton step instead, if also under the
        cap. The wide low-bandwidth peak reaches far; the sharp one is exact near the goal.
        """
        R = T_scene_model[:3, :3]
        expected = R @ self.axis  # where the estimate puts the plane's normal in the view
        sampled = normals[:: self.params.plane_turn_stride]
        off = sampled[sampled @ expected <= self.cos_cone]
        if len(off) < _MIN_OFF_PLANE or len(off) == len(sampled):
            return 0.0
        plane = np.ones(len(sampled)) @ sampled - off.sum(axis=0)  # sum of the in-cone normals
        if plane @ expected < math.cos(self.params.plane_turn_tilt) * np.linalg.norm(plane):
            return 0.0  # the tilt is still off: the turn would be measured about a wrong axis
        fine = egi_coefficients(off, self.bandwidth)
        coarse_count = self.params.bandwidth**2  # degrees < B come first
        coarse = self._step(fine[:coarse_count], self.coefficients[:coarse_count], R)
        if not coarse.newton or coarse.capped:
            return coarse.turn
        if self.bandwidth > self.params.bandwidth:
            sharp = self._step(fine, self.coefficients, R)
            if sharp.newton and not sharp.capped:
                return sharp.turn
        return coarse.turn

    def _step(
        self, scene_coefficients: np.ndarray, model_coefficients: np.ndarray, R: np.ndarray
    ) -> AxisRotationStep:
        """The registration's rotation law along ``axis`` at ``R`` (in the core)."""
        correlation = So3Correlation(scene_coefficients, model_coefficients)
        return rotation_step_about(correlation, R, self.axis, self.law)

    def turned(self, T_scene_model: np.ndarray, turn: float) -> np.ndarray:
        """``T_scene_model`` with its rotation turned by ``turn`` about ``axis`` around the
        reference's centroid (the registration's centre of rotation)."""
        T = np.array(T_scene_model, dtype=float)
        R = T[:3, :3]
        R_turned = R @ rotation_matrix(turn * self.axis)
        T[:3, 3] += (R - R_turned) @ self.centroid
        T[:3, :3] = R_turned
        return T


class SpectralServo:
    """The servo controller: from the current cloud to a camera twist.

    Parameters
    ----------
    reference : PointCloud or ndarray
        Cloud captured at the desired camera pose, in that camera frame, metres; (N, 3) or
        (N, 6) arrays (points, normals) are accepted. Missing normals are estimated and
        turned toward the camera origin.
    params : ServoParams, optional
        Settings; defaults to ``ServoParams()``.

    Raises
    ------
    ValueError
        If the reference is empty or has fewer than ``params.min_points`` points.
    """

    def __init__(self, reference: CloudLike, params: ServoParams | None = None) -> None:
        self.params = params if params is not None else ServoParams()
        cloud = self._crop(as_cloud(reference, "reference"))
        if len(cloud) < self.params.min_points:
            raise ValueError(
                f"reference has {len(cloud)} points, fewer than min_points = "
                f"{self.params.min_points}"
            )
        self._align_params = self.params.align_params()
        self._view_params = ViewAlignParams(**self.params.view_overrides)
        self.reference = self._prepare(cloud, "reference")
        # What the relocalization registers: the reference as captured, with its normals.
        self._reference_view = cloud if cloud.has_normals else self.reference
        # The reference's side of the registration (its EGI coefficients, centred points)
        # is prepared once here; each step adds only the current cloud's work.
        self._aligner = ModelAligner(self.reference, self._align_params)
        self._tracking_aligner: ModelAligner | None = None
        if self.params.uses_tracking():
            tracking = copy.copy(self._align_params)
            tracking.max_translation = self.params.tracking_translation
            self._tracking_aligner = ModelAligner(self.reference, tracking)
        self._centroid = np.asarray(self.reference.centroid())
        self._plane_turn = (
            _PlaneTurn.of(
                cloud if cloud.has_normals else self.reference,
                self._centroid,
                self.params,
                self._align_params,
            )
            if self.params.plane_turn
            else None
        )
        self._last_turn = 0.0
        reference_points = np.asarray(cloud.points)
        stride = max(1, math.ceil(len(reference_points) / _OCCLUSION_REFERENCE_POINTS))
        self._occlusion_reference = np.array(reference_points[::stride], dtype=float)
        self._previous: np.ndarray | None = None
        self._armed = False
        self._steps = 0
        self._anchored = False  # a global registration was taken: registrations warm-start
        self._lost = True  # no trusted estimate: the next step relocalizes
        self._since_relocalization: int | None = None  # steps since the last attempt
        self._confirmed = False  # the last relocalization was taken and confirmed
        self._unconfirmed = 0  # relocalizations in a row not confirmed (the backoff)
        # The recovery's reference side: the plane it levels the camera onto, if any.
        plane_source = cloud if cloud.has_normals else self.reference
        self._reference_plane = dominant_plane(
            np.asarray(plane_source.points),
            np.asarray(plane_source.normals),
            self.params.plane_cone,
            self.params.min_plane_share,
        )
        self._reset_recovery()
        self._settled = False  # converged and not re-engaged since (the hysteresis)
        self._outside = 0  # settled steps in a row whose estimate left the re-engage bounds
        self._reset_faults()

    def _reset_recovery(self) -> None:
        """Forget the recovery: the failed relocalizations in a row, its steps so far and
        where it started backing off from."""
        self._failed_relocalizations = 0
        self._recovery_steps = 0
        self._T_motion_backoff: np.ndarray | None = None  # self._motion at the back-off start

    def _reset_faults(self) -> None:
        """Forget what the fault tests remember: the camera's motion since the last accepted
        step, the last frame's fingerprint and stamp, and the outage's start."""
        self._motion = np.eye(4)  # T_accepted_current: since the last accepted step
        self._frame_key: bytes | None = None  # fingerprint of the last non-empty frame
        self._frame_motion = np.eye(4)  # the camera's motion since that frame came first
        self._last_stamp: float | None = None
        self._outage_start: float | None = None  # the last accepted frame's time

    def _crop(self, cloud: PointCloud) -> PointCloud:
        """The points within ``max_depth`` of the camera (along its optical axis)."""
        if not math.isfinite(self.params.max_depth) or len(cloud) == 0:
            return cloud
        points = np.asarray(cloud.points)
        if points[:, 2].max() <= self.params.max_depth:  # the usual case, without a mask
            return cloud
        return cloud.select(points[:, 2] <= self.params.max_depth)  # copied in the core

    def _prepare(self, cloud: PointCloud, argument: str) -> PointCloud:
        """The cloud downsampled to ``downsample_size``, with normals."""
        size = self.params.downsample_size or self.params.voxel_size / 2
        try:
            cloud = voxel_downsample(cloud, size) if len(cloud) else cloud
        except ValueError as error:
            raise ValueError(f"{argument}: downsampling to {size} m: {error}") from error
        return prepare(cloud, argument, self.params.voxel_size, False, (0, 0, 0))

    def reset(self) -> None:
        """Forget the previous estimate (the watchdog's memory), the step count, whether the
        servo converged (``ServoParams.reengage_translation``) and what the fault tests
        remember (the last frame, the outage's start)."""
        self._previous = None
        self._armed = False
        self._steps = 0
        self._last_turn = 0.0
        self._anchored = False
        self._lost = True
        self._since_relocalization = None
        self._confirmed = False
        self._unconfirmed = 0
        self._reset_recovery()
        self._settled = False
        self._outside = 0
        self._reset_faults()

    @property
    def last_turn(self) -> float:
        """The turn about the reference's dominant normal added to the last estimate, rad
        (0 without ``ServoParams.plane_turn`` or a dominant plane)."""
        return self._last_turn

    @property
    def has_plane_turn(self) -> bool:
        """True when the estimates are turned about the reference's dominant normal
        (``ServoParams.plane_turn`` and a reference with a dominant plane)."""
        return self._plane_turn is not None

    @property
    def previous_estimate(self) -> np.ndarray | None:
        """The last accepted ``T_current_desired`` (None before the first step)."""
        return None if self._previous is None else self._previous.copy()

    def estimate(
        self, current: CloudLike, initial_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, AlignResult]:
        """Register the reference onto ``current``: ``T_current_desired`` and the AlignResult.

        Parameters
        ----------
        current : PointCloud or ndarray
            The cloud of the camera at its current pose, camera frame, metres (not empty
            within ``max_depth``).
        initial_guess : ndarray (4, 4), optional
            ``T_current_desired`` to start Algorithm 1 from; the identity by default.

        Returns
        -------
        T_current_desired : ndarray, shape (4, 4)
            The registration's pose, turned about the reference's dominant normal with
            ``ServoParams.plane_turn`` (the turn is :attr:`last_turn`).
        result : AlignResult
            The registration (its ``T_scene_model`` before the turn).
        """
        cloud = self._crop(as_cloud(current, "current"))
        return self._estimate(cloud, initial_guess, self._aligner)

    def _estimate(
        self, cloud: PointCloud, initial_guess: np.ndarray | None, aligner: ModelAligner
    ) -> tuple[np.ndarray, AlignResult]:
        """:meth:`estimate` of the cropped ``cloud`` with the given prepared reference."""
        scene, result = self._register(cloud, initial_guess, aligner)
        return self._turned(cloud, scene, np.asarray(result.T_scene_model)), result

    def _register(
        self, cloud: PointCloud, initial_guess: np.ndarray | None, aligner: ModelAligner
    ) -> tuple[PointCloud, AlignResult]:
        """The downsampled ``cloud`` and the registration of the reference onto it, without
        the plane turn (a step turns only the estimate it keeps)."""
        scene = self._prepare(cloud, "current")
        return scene, aligner.align(scene, initial_guess)

    def _turned(self, cloud: PointCloud, scene: PointCloud, T: np.ndarray) -> np.ndarray:
        """``T`` turned about the reference's dominant normal (``ServoParams.plane_turn``),
        from the normals of ``cloud`` (those of its downsampled ``scene`` without)."""
        self._last_turn = 0.0
        if self._plane_turn is not None:
            normals = np.asarray((cloud if cloud.has_normals else scene).normals)
            self._last_turn = self._plane_turn.turn(normals, T)
            T = self._plane_turn.turned(T, self._last_turn)
        return T

    def twist(self, T_current_desired: np.ndarray) -> tuple[np.ndarray, float]:
        """The decoupled law and its saturation.

        Parameters
        ----------
        T_current_desired : ndarray, shape (4, 4)
            Pose of the desired camera frame in the current camera frame.

        Returns
        -------
        twist : ndarray, shape (6,)
            ``(v, omega)`` of the camera in the current camera frame, m/s and rad/s:
            ``v = lambda_t t``, ``omega = lambda_r theta u``, scaled down as a whole so that
            ``|v| <= max_linear_speed`` and ``|omega| <= max_angular_speed``.
        scale : float
            The factor in (0, 1] that was applied.
        """
        T = np.asarray(T_current_desired, dtype=float)
        return _saturated_twist(T[:3, 3], rotation_vector(T[:3, :3]), self.params)

    def step(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus]:
        """One control step: the camera twist toward the desired pose, and the status.

        Parameters
        ----------
        current : PointCloud or ndarray
            The current cloud, camera frame, metres.
        T_previous_current : ndarray (4, 4), optional
            The camera's own motion since the previous step (pose of the current camera
            frame in the previous one, e.g. from the forward kinematics). The watchdog then
            compares the new estimate with the previous one carried along this motion
            (over the held steps since, too); without it, with the previous estimate itself,
            and the camera counts as still for the stale-frame test.
        now : float, optional
            Time of the capture, s, on the clock that ``ServoParams.max_outage`` is
            measured on (:func:`run_servo` passes the robot clock). Without it, the
            computer's monotonic clock (:func:`time.monotonic`) at the call.
        stamp : float, optional
            The capture's own time stamp from the sensor driver, s: a stamp not later than
            the last one marks a stale frame. Without it, only the fingerprint tells.

        Returns
        -------
        twist : ndarray, shape (6,)
            ``(v, omega)``, camera frame, m/s and rad/s; zero unless the state is running
            and the step was not held.
        status : ServoStatus
            ``running`` (also at a held step: its message says why, see :data:`HOLDS`),
            ``converged`` (the estimate is within the tolerances and the fitness high
            enough) or ``stopped`` with a reason: ``"sensor_outage"`` (holds for longer
            than ``max_outage``) or ``"jump"`` (the watchdog, armed once the fitness has
            reached ``watchdog_fitness``).
        """
        twist, status, _ = self.step_record(current, T_previous_current, now=now, stamp=stamp)
        return twist, status

    def step_record(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None = None,
        *,
        now: float | None = None,
        stamp: float | None = None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step` with its :class:`ServoRecord`."""
        cpu = time.process_time()
        twist, status, record = self._step_record(current, T_previous_current, now, stamp)
        record.cpu_seconds = time.process_time() - cpu
        return twist, status, record

    def _step_record(
        self,
        current: CloudLike,
        T_previous_current: np.ndarray | None,
        now: float | None,
        stamp: float | None,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """:meth:`step_record` without its CPU time."""
        start = time.perf_counter()
        now = time.monotonic() if now is None else float(now)
        p = self.params
        motion = self._carry(T_previous_current)
        raw = as_cloud(current, "current")
        cloud = self._crop(raw)
        points = len(cloud)
        record = _empty_record(self._steps, points)
        self._steps += 1
        if points == 0 or points < p.min_points:
            hold = "empty_cloud" if points == 0 else "too_few_points"
            message = f"the current cloud has {points} points (min_points {p.min_points})"
            return self._hold(record, hold, message, now, start)
        stale = self._stale(raw, stamp)
        if stale is not None:
            return self._hold(record, "stale_frame", stale, now, start)

        # A hand in front of the camera: surfaces nearer than the reference could be.
        occluded = False
        hidden = 0.0
        if self._armed and self._previous is not None and math.isfinite(p.occlusion_margin):
            mask, hidden = near_occluders(
                np.asarray(cloud.points),
                self._occlusion_reference,
                self._predicted(motion),
                p.occlusion_margin,
            )
            record.occluded_points = int(mask.sum())
            record.hidden_share = hidden
            if record.occluded_points:
                keep = ~mask
                normals = cloud.normals
                cloud = PointCloud(
                    np.asarray(cloud.points)[keep],
                    None if normals is None else np.asarray(normals)[keep],
                )
                occluded = record.occluded_points >= p.occlusion_min_share * points
                if len(cloud) < p.min_points:
                    message = (
                        f"{len(cloud)} points remain without {record.occluded_points} "
                        f"occluding ones (min_points {p.min_points})"
                    )
                    return self._hold(record, "occluded", message, now, start)

        if self._since_relocalization is not None:
            self._since_relocalization += 1
        if p.relocalize and self._lost and self._relocalization_due():
            self._relocalize(cloud, record, motion)
            motion = self._motion
        if self._recovering():
            return self._recover(cloud, record, motion, now, start)
        guess = None
        if (p.warm_start or self._anchored) and self._previous is not None:
            guess = self._predicted(motion)
        # A relocalized step checks the global pose on the full grid once.
        tracking = not record.relocalized and self._can_track(guess, motion)
        if tracking:
            assert self._tracking_aligner is not None
            scene, result = self._register(cloud, guess, self._tracking_aligner)
            # Once locked on, a poor fit may mean the answer lies beyond the tracking bound
            # (the camera or the scene jumped): the full search decides, and the watchdog
            # sees the jump. Before, a poor fit is the relocalization's to judge.
            tracking = not self._armed or result.fitness >= p.watchdog_fitness
        if not tracking:
            scene, result = self._register(cloud, guess, self._aligner)
        record.tracking = tracking
        last = result.history[-1] if len(result.history) else None
        record.fitness = float(result.fitness)
        # Before lock-on the views share too little for Algorithm 1's step: the EGI
        # correlation of two partial views peaks 10-20 degrees off the truth, and steps
        # toward it drift away from a right global estimate. The last good estimate carried
        # along the camera's measured motion is the estimate until the registration locks
        # on (fitness watchdog_fitness).
        record.carried = (
            self._anchored
            and not self._armed
            and guess is not None
            and record.fitness < p.watchdog_fitness
        )
        T = np.asarray(result.T_scene_model)
        # The plane turn is of the estimate the step keeps, and of the confidence's pose
        # under its threshold: a carried step with a confident fit uses neither.
        if not record.carried or record.fitness < p.relocalize_fitness:
            T = self._turned(cloud, scene, T)
        # fitness / share >= fitness: the share is needed only under the threshold.
        record.confidence = (
            min(1.0, record.fitness)
            if record.fitness >= p.relocalize_fitness
            else self._confidence(T, record.fitness, cloud)
        )
        if record.carried:
            assert guess is not None
            T = guess
            self._last_turn = 0.0
        t_err, r_err = pose_error(T)
        record.T_current_desired = T
        record.translation_error, record.rotation_error = t_err, r_err
        record.iterations = int(result.iterations)
        record.plane_turn = 0.0 if record.carried else self._last_turn
        if last is not None:
            record.translation_cost = float(last.translation_cost)
            record.rotation_cost = float(last.rotation_cost)
            record.translation_step = float(last.translation_step)
            record.rotation_gradient = float(last.rotation_gradient)

        jump = self._jump(T, motion)
        if occluded:
            # Ridden only when the registration of the rest is sound: a registration that
            # the occluder corrupted turns into no motion and trips no watchdog.
            visible_fitness = record.fitness / max(1.0 - hidden, 1e-9)
            if jump is not None:
                return self._hold(record, "occluded", f"with an occluder, {jump}", now, start)
            if visible_fitness < p.watchdog_fitness:
                message = (
                    f"with an occluder hiding {100 * hidden:.0f}% of the reference, the "
                    f"fitness over the rest is {visible_fitness:.3f} (watchdog_fitness "
                    f"{p.watchdog_fitness})"
                )
                return self._hold(record, "occluded", message, now, start)
        if jump is not None:
            record.status = ServoStatus("stopped", "jump", jump)
            record.seconds = time.perf_counter() - start
            return record.twist, record.status, record
        self._previous = T
        self._motion = np.eye(4)
        self._outage_start = now
        self._armed = self._armed or record.fitness >= p.watchdog_fitness
        self._lost = not record.confidence >= p.relocalize_fitness
        if record.relocalized:
            self._confirmed = not self._lost
        if not self._lost:
            self._unconfirmed = 0

        converged = self._converged(record)
        if converged:
            self._outside = 0
        self._settled = converged or (self._settled and self._held(record))
        if self._settled:
            record.status = _converged_status(t_err, r_err)
        else:
            record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _relocalization_due(self) -> bool:
        """Whether a relocalization may run now: none was tried yet, or the last was
        ``relocalize_interval`` steps ago (when it was not confirmed, ``relocalize_retry``
        grown by ``relocalize_backoff`` per unconfirmed one in a row before it; while
        recovering, ``relocalize_retry``: the recovery widens the view at every step)."""
        since = self._since_relocalization
        p = self.params
        if since is None:
            return True
        if self._confirmed:
            return since >= p.relocalize_interval
        if self._recovering():
            return since >= p.relocalize_retry
        growth = p.relocalize_backoff ** max(0, self._unconfirmed - 1)
        return since >= min(p.relocalize_interval, p.relocalize_retry * growth)

    def _confidence(self, T: np.ndarray, fitness: float, cloud: PointCloud) -> float:
        """``fitness`` over the share of the reference that ``T`` puts inside the field of
        ``cloud`` (its points' bounds in x/z and y/z, nearer than ``max_depth``; at least
        ``_MIN_FIELD_SHARE``), in [0, 1]."""
        share = field_share(
            self._occlusion_reference, T, np.asarray(cloud.points), self.params.max_depth
        )
        # An estimate that puts the reference out of the field is not trusted for fitting
        # the little it leaves in view.
        return float(min(1.0, fitness / max(share, _MIN_FIELD_SHARE)))

    def _relocalize(
        self, cloud: PointCloud, record: ServoRecord, motion: np.ndarray | None
    ) -> None:
        """The global registration of the reference onto ``cloud`` (cropped, as captured),
        with the estimate carried along ``motion`` as its prior once one was taken: taken as the
        previous estimate when its support reaches ``relocalize_score``."""
        # The estimate carried so far, if a global registration was taken before (an
        # estimate of the local step alone far from the goal is no prior worth refining).
        prior = None if self._previous is None or not self._anchored else self._predicted(motion)
        self._since_relocalization = 0
        self._confirmed = False
        self._unconfirmed += 1  # until the step confirms it
        result = _align_views(self._reference_view, cloud, self._view_params, prior)
        record.relocalization_score = float(result.support.score)
        record.relocalization_prior = prior is not None and result.hypothesis == -1
        # While recovering the view widens step by step: a marginal score in the middle
        # of it is worth waiting out (a 17-degree wrong pose scored 0.061 there).
        least = self.params.recover_score if self._recovering() else self.params.relocalize_score
        if result.support.score < least:
            self._failed_relocalizations += 1
            return
        self._reset_recovery()
        record.relocalized = True
        self._previous = np.asarray(result.T_current_reference)
        self._motion = np.eye(4)
        self._anchored = True
        self._lost = False

    def _recovering(self) -> bool:
        """Whether this step recovers (``ServoParams.recover_after``): no global registration
        was taken yet and the last ``recover_after`` ones stayed under the score."""
        p = self.params
        return (
            p.relocalize
            and p.recover_after > 0
            and not self._anchored
            and self._failed_relocalizations >= p.recover_after
        )

    def _recover(
        self,
        cloud: PointCloud,
        record: ServoRecord,
        motion: np.ndarray,
        now: float,
        start: float,
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """A recovery step: the twist toward the pose that widens the view's overlap with
        the reference (level onto its plane, else back off), or the stop ``"lost"`` once
        ``recover_steps`` were spent; no registration runs."""
        p = self.params
        self._recovery_steps += 1
        self._outage_start = now  # the frame was usable: no sensor outage
        if self._recovery_steps > p.recover_steps:
            record.status = ServoStatus(
                "stopped",
                "lost",
                f"no relocalization reached recover_score {p.recover_score:g} within "
                f"{p.recover_steps} recovery steps (last score "
                f"{record.relocalization_score:.3f})",
            )
            record.seconds = time.perf_counter() - start
            return record.twist, record.status, record
        T = self._level_target(cloud)
        record.recovery = "level"
        if T is None:
            # No plane to level onto: back off along the optical axis from where the
            # recovery started, that pose carried along the camera's measured motion since.
            if self._T_motion_backoff is None:
                self._T_motion_backoff = motion.copy()
            T = np.eye(4)
            T[2, 3] = -p.recover_standoff
            T = _rigid_inverse(motion) @ self._T_motion_backoff @ T
            record.recovery = "back_off"
        record.T_current_desired = T
        record.translation_error, record.rotation_error = pose_error(T)
        record.twist, record.saturation = self.twist(T)
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _level_target(self, cloud: PointCloud) -> np.ndarray | None:
        """``T_current_target`` of the levelling recovery: the camera turned about its origin
        so that the reference's plane normal comes where the current view sees its plane's,
        at the reference's distance to the plane plus ``recover_standoff``; None when the
        reference or the current view has no dominant plane."""
        if self._reference_plane is None:
            return None
        p = self.params
        source = cloud if cloud.has_normals else self._prepare(cloud, "current")
        stride = p.plane_turn_stride
        current = dominant_plane(
            np.asarray(source.points)[::stride],
            np.asarray(source.normals)[::stride],
            p.plane_cone,
            p.min_plane_share,
        )
        if current is None:
            return None
        n_reference, d_reference = self._reference_plane
        n_current, d_current = current
        T = np.eye(4)
        T[:3, :3] = _turn_between(n_reference, n_current)
        # The target origin t lies at n.t + d_current from the plane.
        T[:3, 3] = n_current * (d_reference + p.recover_standoff - d_current)
        return T

    def _carry(self, T_previous_current: np.ndarray | None) -> np.ndarray:
        """Add the camera's motion since the previous step (identity when not given) to the
        motion since the last accepted step and since the last frame came first; return
        the former (``T_accepted_current``)."""
        if T_previous_current is not None:
            step = np.asarray(T_previous_current, dtype=float)
            self._motion = self._motion @ step
            self._frame_motion = self._frame_motion @ step
        return self._motion

    def _stale(self, cloud: PointCloud, stamp: float | None) -> str | None:
        """A message when ``cloud`` is a frame already seen, else None; remembers it.

        A stamp not later than the last one is stale. The same fingerprint is stale once
        the camera has moved since the frame came first: a still camera in a still scene
        may see the very same frame (a noise-free simulation does), and acting on it then
        is right.
        """
        if stamp is not None:
            last = self._last_stamp
            if last is not None and not float(stamp) > last:
                return f"capture stamp {float(stamp):.6f} s is not after the last, {last:.6f} s"
            self._last_stamp = float(stamp)
        key = frame_fingerprint(np.asarray(cloud.points))
        if key != self._frame_key:
            self._frame_key = key
            self._frame_motion = np.eye(4)
            return None
        moved, turned = pose_error(self._frame_motion)
        if moved < _STILL_TRANSLATION and turned < _STILL_ROTATION:
            return None
        return (
            f"the same frame again after the camera moved {1000 * moved:.2f} mm and "
            f"{math.degrees(turned):.3f} deg"
        )

    def _hold(
        self, record: ServoRecord, hold: str, message: str, now: float, start: float
    ) -> tuple[np.ndarray, ServoStatus, ServoRecord]:
        """Finish ``record`` as a held step (zero twist, nothing remembered), or stop with
        ``"sensor_outage"`` when the holds have lasted longer than ``max_outage``."""
        if self._outage_start is None:
            self._outage_start = now  # no frame accepted yet: the outage starts here
        outage = now - self._outage_start
        record.hold, record.outage = hold, outage
        record.twist = np.zeros(6)
        limit = self.params.max_outage
        if limit == 0 or outage > limit + _CLOCK_TOLERANCE:
            record.status = ServoStatus(
                "stopped",
                "sensor_outage",
                f"no usable frame for {outage:.3f} s (max_outage {limit:g} s); "
                f"last fault {hold}: {message}",
            )
        else:
            record.status = ServoStatus("running", "", f"holding ({hold}): {message}")
        record.seconds = time.perf_counter() - start
        return record.twist, record.status, record

    def _can_track(self, guess: np.ndarray | None, motion: np.ndarray | None) -> bool:
        """Whether this registration may seek only ``tracking_translation``: locked on (the
        watchdog armed, or a relocalization taken), and
        the predicted estimate moves the reference's centroid by at most half of it from
        the registration's start ``guess`` (identity when None); ``motion`` as for
        :meth:`_predicted`."""
        locked = self._armed or self._anchored
        if self._tracking_aligner is None or not locked or self._previous is None:
            return False
        predicted = self._predicted(motion)
        start = np.eye(4) if guess is None else np.asarray(guess, dtype=float)
        c = self._centroid
        moved = predicted[:3, :3] @ c + predicted[:3, 3] - (start[:3, :3] @ c + start[:3, 3])
        return bool(np.abs(moved).max() <= 0.5 * self.params.tracking_translation)

    def _converged(self, record: ServoRecord) -> bool:
        p = self.params
        if record.fitness < p.min_fitness:
            return False
        if (
            record.translation_error < p.translation_tolerance
            and record.rotation_error < p.rotation_tolerance
        ):
            return True
        eq17 = record.translation_step + record.rotation_gradient
        return p.step_tolerance > 0 and bool(eq17 < p.step_tolerance)

    def _held(self, record: ServoRecord) -> bool:
        """Whether a converged servo stays so: its estimate has not been outside the
        re-engage bounds for ``reengage_steps`` steps in a row."""
        p = self.params
        inside = (
            record.translation_error <= p.reengage_translation
            and record.rotation_error <= p.reengage_rotation
        )
        self._outside = 0 if inside else self._outside + 1
        return self._outside < p.reengage_steps

    def _predicted(self, motion: np.ndarray | None) -> np.ndarray:
        """The previous (last accepted) estimate carried along the camera's motion since
        that step, ``motion`` = ``T_accepted_current`` (None: the camera is taken as still)."""
        assert self._previous is not None
        if motion is None:
            return self._previous
        return _rigid_inverse(np.asarray(motion, dtype=float)) @ self._previous

    def _jump(self, T: np.ndarray, motion: np.ndarray | None) -> str | None:
        """A message when ``T`` is implausibly far from the previous estimate carried along
        ``motion`` (as for :meth:`_predicted`), else None."""
        if self._previous is None or not self._armed:
            return None
        predicted = self._predicted(motion)
        # |translation| of predicted^-1 T is |t - t_predicted|: the two parts are independent.
        moved, turned = pose_error(_rigid_inverse(predicted) @ T)
        p = self.params
        if moved > p.jump_limit_translation or turned > p.jump_limit_rotation:
            return (
                f"the estimate changed by {1000 * moved:.1f} mm and {math.degrees(turned):.2f} "
                f"deg in one step (limits {1000 * p.jump_limit_translation:.1f} mm, "
                f"{math.degrees(p.jump_limit_rotation):.2f} deg)"
            )
        return None


# --------------------------------------------------------------------------- the loop


def run_servo(
    robot: RobotInterface,
    kinematics: Kinematics,
    servo: SpectralServo,
    *,
    dt: float = 0.1,
    max_steps: int = 200,
    max_time: float = math.inf,
    velocity_params: VelocityCommandParams | None = None,
    stop_at_joint_limit: bool = True,
    callback: Callable[[ServoRecord], None] | None = None,
) -> ServoLog:
    """Servo ``robot`` until the camera reaches the reference pose or a stop condition.

    Each step: read ``q``, capture, :meth:`SpectralServo.step` (with the camera motion since
    the last step from the forward kinematics, for the watchdog, and the robot clock at the
    capture as ``now``), ``q_dot = kinematics.joint_velocities(q, twist, velocity_params)``,
    send it for ``dt`` seconds. A held step (``ServoRecord.hold``, :data:`HOLDS`) sends zero
    joint velocities for ``dt`` and the loop goes on. A robot whose driver stamps its
    captures may offer ``capture_stamp()`` (s, the stamp of the last capture): it is passed
    on as ``stamp``. The robot is stopped (:meth:`RobotInterface.stop`) whatever ends the
    run, an exception included.

    Parameters
    ----------
    robot : RobotInterface
        The arm and its wrist camera.
    kinematics : Kinematics
        Camera kinematics of the robot (its Jacobian maps joint velocities to the camera
        twist in the camera frame).
    servo : SpectralServo
        The controller, built on the reference cloud.
    dt : float
        Control period, s: each command lasts ``dt``.
    max_steps : int
        Step budget; the run stops with reason ``"max_steps"`` when it is spent.
    max_time : float
        Time budget on the robot clock (:meth:`RobotInterface.time`), s; reason ``"max_time"``.
    velocity_params : VelocityCommandParams, optional
        Settings of the joint velocity command; its ``dt`` is set to ``dt``. Defaults to a
        damped pseudo-inverse, a 0.01 rad margin to the position limits and 1 rad/s per joint.
    stop_at_joint_limit : bool
        Stop (reason ``"joint_limit"``) when the command had to clamp a joint at its position
        limit, rather than creeping along the limit with the remaining joints.
    callback : callable, optional
        Called with each :class:`ServoRecord` (progress printing).

    Returns
    -------
    ServoLog
        The records, the final status and its reason.
    """
    if not dt > 0 or not math.isfinite(dt):
        raise ValueError(f"dt must be finite and > 0, got {dt}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    params = (
        copy.copy(velocity_params)
        if velocity_params is not None
        else VelocityCommandParams(dt=dt, max_joint_speed=1.0)
    )
    params.dt = dt
    log = ServoLog()
    start_wall = time.perf_counter()
    start_time = robot.time()
    previous_pose: np.ndarray | None = None
    servo.reset()
    try:
        while True:
            if len(log.records) >= max_steps:
                log.status = ServoStatus("stopped", "max_steps", f"{max_steps} steps")
                break
            if robot.time() - start_time >= max_time:
                log.status = ServoStatus("stopped", "max_time", f"{max_time:g} s")
                break
            q = np.asarray(robot.joint_positions(), dtype=float)
            pose = np.asarray(kinematics.forward(q))
            motion = None if previous_pose is None else np.linalg.inv(previous_pose) @ pose
            cloud = robot.capture()
            now = robot.time()
            stamp_of = getattr(robot, "capture_stamp", None)
            stamp = float(stamp_of()) if callable(stamp_of) else None
            twist, status, record = servo.step_record(cloud, motion, now=now, stamp=stamp)
            record.time = now - start_time
            record.q, record.T_base_camera = q, pose
            previous_pose = pose
            log.records.append(record)
            if status.state != "running":
                record.q_dot = np.zeros_like(q)
                if callback is not None:
                    callback(record)
                log.status = status
                break
            if record.hold:  # held still: zero joint velocities, whatever the kinematics say
                record.q_dot = np.zeros_like(q)
                if callback is not None:
                    callback(record)
                robot.send_joint_velocities(record.q_dot, dt)
                continue
            command = kinematics.joint_velocities(q, twist, params)
            record.q_dot = np.asarray(command.q_dot)
            record.velocity_scale = float(command.velocity_scale)
            limited = list(command.position_limited)
            if limited and stop_at_joint_limit:
                names = [kinematics.joint_names[i] for i in limited]
                record.status = ServoStatus(
                    "stopped", "joint_limit", f"joints at their position limits: {names}"
                )
                record.q_dot = np.zeros_like(q)
                if callback is not None:
                    callback(record)
                log.status = record.status
                break
            if callback is not None:
                callback(record)
            robot.send_joint_velocities(record.q_dot, dt)
    finally:
        robot.stop()
        log.wall_seconds = time.perf_counter() - start_wall
    return log


#: The start-pose sets of the servo experiment (benchmarks/servo_experiment.py) and of
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
        from spectral_vs.sim.robot import HOME_Q

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


def view_share(
    points: np.ndarray,
    T_camera_points: np.ndarray,
    K: np.ndarray,
    image_size: tuple[int, int],
    depth_range: tuple[float, float] = (0.0, math.inf),
) -> float:
    """Share of ``points`` that a pinhole camera has in its field of view.

    A point counts when, moved into the camera frame, it lies between the depth limits and
    projects inside the image. Occlusion is ignored: a point hidden behind another one
    counts.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        The points in their own frame (e.g. the reference cloud, reference camera frame), m.
    T_camera_points : ndarray, shape (4, 4)
        Pose of the points' frame in the camera frame (Z forward, X right, Y down).
    K : ndarray, shape (3, 3)
        Camera matrix (fx, fy, cx, cy in pixels); pixel (u, v) covers [u - 0.5, u + 0.5).
    image_size : (int, int)
        Width and height, pixels.
    depth_range : (float, float)
        Depths seen, ``(near, far)``, m.

    Returns
    -------
    float
        The share in view, in [0, 1]; 0 for no points.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(points) == 0:
        return 0.0
    T = np.asarray(T_camera_points, dtype=float)
    p = points @ T[:3, :3].T + T[:3, 3]
    z = p[:, 2]
    near, far = depth_range
    in_depth = (z > max(near, 1e-9)) & (z < far)
    z_safe = np.where(in_depth, z, 1.0)
    u = K[0, 0] * p[:, 0] / z_safe + K[0, 2]
    v = K[1, 1] * p[:, 1] / z_safe + K[1, 2]
    width, height = image_size
    inside = (u >= -0.5) & (u < width - 0.5) & (v >= -0.5) & (v < height - 0.5)
    return float(np.count_nonzero(in_depth & inside)) / len(points)


class ViewCheck:
    """The start check of the sets with ``min_view_share``: a start configuration is
    accepted when its camera is at least ``min_camera_height`` above the base frame's
    z = 0 plane (the table top of the simulation: not inside or under the table) and sees
    at least ``min_share`` of the reference's points (:func:`view_share`: the reference
    cloud moved into the start camera frame by the kinematics, projected with the
    intrinsics, occlusion ignored).

    Parameters
    ----------
    kinematics : Kinematics
        Camera kinematics of the robot.
    q_reference : array_like, shape (n,)
        Configuration where the reference was captured, rad.
    reference_points : ndarray, shape (N, 3)
        The reference cloud's points, reference camera frame, m.
    K : ndarray, shape (3, 3)
        Camera matrix, pixels.
    image_size : (int, int)
        Width and height, pixels.
    depth_range : (float, float)
        Depths the camera sees, ``(near, far)``, m.
    min_share : float
        Share of the reference in view to accept a start, in (0, 1].
    min_camera_height : float
        Lowest accepted camera height above z = 0 of the base frame, m.
    """

    def __init__(
        self,
        kinematics: Kinematics,
        q_reference: Any,
        reference_points: np.ndarray,
        K: np.ndarray,
        image_size: tuple[int, int],
        *,
        depth_range: tuple[float, float] = (0.0, math.inf),
        min_share: float = 0.3,
        min_camera_height: float = 0.05,
    ) -> None:
        if not 0.0 < min_share <= 1.0:
            raise ValueError(f"min_share must be in (0, 1], got {min_share}")
        points = np.asarray(reference_points, dtype=float).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        if len(points) == 0:
            raise ValueError("reference_points must hold at least one finite point")
        self.kinematics = kinematics
        self.q_reference = np.asarray(q_reference, dtype=float)
        self.reference_points = points
        self.K = np.asarray(K, dtype=float)
        self.image_size = image_size
        self.depth_range = depth_range
        self.min_share = min_share
        self.min_camera_height = min_camera_height
        self._T_base_reference = np.asarray(kinematics.forward(self.q_reference))

    def share(self, q: np.ndarray) -> float:
        """Share of the reference's points in view of the camera at ``q`` (rad)."""
        T_base_camera = np.asarray(self.kinematics.forward(q))
        return view_share(
            self.reference_points,
            np.linalg.inv(T_base_camera) @ self._T_base_reference,
            self.K,
            self.image_size,
            self.depth_range,
        )

    def __call__(self, q: np.ndarray) -> bool:
        """Whether a start at ``q`` (rad) passes: camera above the table, view shared."""
        if np.asarray(self.kinematics.forward(q))[2, 3] < self.min_camera_height:
            return False
        return self.share(q) >= self.min_share


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


# --------------------------------------------------------------------------- figures


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


def plot_servo(
    log: ServoLog,
    T_base_reference: np.ndarray,
    path: Any,
    *,
    reference: PointCloud | np.ndarray | None = None,
    clouds: dict[int, np.ndarray] | None = None,
    title: str | None = None,
    max_points: int = 4000,
) -> None:
    """A servo run in the layout of the paper's Fig. 6.

    Top row (with ``reference`` and ``clouds``): the current clouds at three steps (start,
    middle, end) over the reference cloud, both in their own camera frames as the camera
    sees them (image plane, X right, Y down). Bottom row: the camera pose error over time
    (true, from the kinematics, and the servo's estimate: in ``"iteration"`` mode the
    one-iteration step, whose rotation is capped at ``max_rotation_step``) and the 3D
    trajectory of the camera in the base frame.

    Parameters
    ----------
    log : ServoLog
        A run of :func:`run_servo`.
    T_base_reference : ndarray (4, 4)
        The camera pose where the reference was captured.
    path : str or PathLike
        Image file to write (``.png``, ``.pdf``, ``.svg``).
    reference : PointCloud or ndarray (N, 3), optional
        The reference cloud, camera frame.
    clouds : dict of int to ndarray (N, 3), optional
        Current clouds by step index; the first, a middle and the last one are drawn.
    title : str, optional
        Title above the panels.
    max_points : int
        Points drawn per cloud (a seeded subsample).
    """
    from spectral_vs.plotting import _new_figure

    rng = np.random.default_rng(0)

    def subsample(points: Any) -> np.ndarray:
        points = np.asarray(points.points if isinstance(points, PointCloud) else points)
        if len(points) > max_points:
            points = points[rng.choice(len(points), max_points, replace=False)]
        return points

    show_clouds = reference is not None and bool(clouds)
    figure = _new_figure(13.0, 8.0 if show_clouds else 4.5)
    grid = figure.add_gridspec(2 if show_clouds else 1, 3)
    row = 0
    if show_clouds and clouds is not None:
        ref_points = subsample(reference)
        steps = sorted(clouds)
        chosen = [steps[0], steps[len(steps) // 2], steps[-1]] if len(steps) >= 3 else steps
        names = ["initial", "intermediate", "final"]
        # Depth shades the points so that the objects stand out from the table.
        low, high = np.percentile(ref_points[:, 2], [1, 99])
        for column, (step, name) in enumerate(zip(chosen, names, strict=False)):
            axis = figure.add_subplot(grid[0, column])
            axis.scatter(
                ref_points[:, 0],
                ref_points[:, 1],
                s=0.4,
                c=ref_points[:, 2],
                cmap="Greys_r",
                vmin=low - 0.1,
                vmax=high + 0.1,
                label="reference",
            )
            current = subsample(clouds[step])
            axis.scatter(
                current[:, 0],
                current[:, 1],
                s=0.4,
                c=current[:, 2],
                cmap="autumn",
                vmin=low,
                vmax=high,
                label=f"current, step {step}",
            )
            axis.set_title(f"{name} cloud (step {step}) over the reference")
            axis.set_xlabel("x (m, camera frame; colour: depth)")
            axis.set_ylabel("y (m)")
            axis.set_aspect("equal")
            axis.invert_yaxis()
            axis.legend(loc="upper right", fontsize="small", markerscale=10)
        row = 1
    time_s = log.array("time")
    errors = true_errors(log, T_base_reference)
    estimated_t = 1000.0 * log.array("translation_error")
    estimated_r = np.degrees(log.array("rotation_error"))
    trans = figure.add_subplot(grid[row, 0])
    trans.plot(time_s, errors[:, 0], "-", color="tab:blue", label="true")
    trans.plot(
        time_s,
        estimated_t,
        ".",
        color="tab:blue",
        alpha=0.5,
        markersize=4,
        label="servo's estimate",
    )
    trans.set_yscale("log")
    trans.set_xlabel("time (s)")
    trans.set_ylabel("translation error (mm)")
    trans.set_title("camera translation error")
    trans.legend(fontsize="small")
    rot = figure.add_subplot(grid[row, 1])
    rot.plot(time_s, errors[:, 1], "-", color="tab:purple", label="true")
    rot.plot(
        time_s,
        estimated_r,
        ".",
        color="tab:purple",
        alpha=0.5,
        markersize=4,
        label="servo's estimate",
    )
    rot.set_yscale("log")
    rot.set_xlabel("time (s)")
    rot.set_ylabel("rotation error (degrees)")
    rot.set_title("camera rotation error")
    rot.legend(fontsize="small")
    for axis in (trans, rot):
        axis.grid(True, which="both", alpha=0.3)
    path3d = figure.add_subplot(grid[row, 2], projection="3d")
    positions = np.array([record.T_base_camera[:3, 3] for record in log.records])  # type: ignore[index]
    path3d.plot(positions[:, 0], positions[:, 1], positions[:, 2], "-", color="black", linewidth=1)
    path3d.scatter(*positions[0], color="tab:red", s=30, label="start")
    path3d.scatter(*positions[-1], color="tab:green", s=30, label="end")
    goal = np.asarray(T_base_reference)[:3, 3]
    path3d.scatter(*goal, color="tab:blue", marker="*", s=80, label="reference pose")
    for T, color in ((log.records[0].T_base_camera, "tab:red"), (T_base_reference, "tab:blue")):
        axis_end = np.asarray(T)[:3, 3] + 0.05 * np.asarray(T)[:3, 2]
        start = np.asarray(T)[:3, 3]
        path3d.plot(*zip(start, axis_end, strict=True), color=color, linewidth=2)
    path3d.set_xlabel("x (m)")
    path3d.set_ylabel("y (m)")
    path3d.set_zlabel("z (m)")
    path3d.set_title("camera trajectory (base frame)")
    path3d.legend(fontsize="small", loc="upper left")
    extent = np.vstack([positions, goal])
    span = max(float(np.ptp(extent, axis=0).max()), 0.02)
    centre = (extent.max(axis=0) + extent.min(axis=0)) / 2
    for setter, c in zip((path3d.set_xlim, path3d.set_ylim, path3d.set_zlim), centre, strict=True):
        setter(c - 0.6 * span, c + 0.6 * span)
    if title:
        figure.suptitle(title)
    figure.savefig(path)


__all__ = [
    "HOLDS",
    "REASONS",
    "START_SETS",
    "CloudRecorder",
    "ServoLog",
    "ServoParams",
    "ServoRecord",
    "ServoStatus",
    "SpectralServo",
    "ViewCheck",
    "dominant_normal",
    "dominant_plane",
    "plot_servo",
    "pose_error",
    "random_start",
    "record_dict",
    "rotation_matrix",
    "rotation_vector",
    "run_servo",
    "start_poses",
    "true_errors",
    "view_share",
]
