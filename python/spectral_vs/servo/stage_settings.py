"""The settings of the stages of the servo's registration and control, one small dataclass
a stage; every field has its unit: the registration, the law, the stop rule, the watchdog
and the plane turn (those of the faults, the relocalization and the recovery are in
:mod:`spectral_vs.servo.fault_settings`). :class:`~spectral_vs.servo.ServoParams` holds one
of each. The scale lengths default to 0: derived from the reference when the servo is
constructed (:mod:`spectral_vs.servo.scale`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from spectral_vs._core import AlignParams
from spectral_vs.servo.setting_checks import (
    check_at_least,
    check_keys,
    check_lengths,
    check_positive,
    check_share,
)

ServoMode = Literal["iteration", "pose"]


@dataclass
class RegistrationParams:
    """The registration of each step (Algorithm 1 on the reference, prepared once).

    Attributes
    ----------
    voxel_size : float
        Voxel edge of the registration, m; 0 (default): derived from the reference,
        ``max(extent / 37, 3 extent / sqrt(N))`` (:mod:`spectral_vs.servo.scale`; 15 mm on
        the simulated table seen from 0.55 m). Whole-scene servoing over a table seen from
        about 0.5 m works at 1-2 cm: coarser voxels are faster and smooth the view changes.
    downsample_size : float
        Both clouds are downsampled to voxels of this edge before the registration, m; 0
        (default): one ``voxel_size``. At a whole voxel a near-goal step's registration
        took 1.3 ms instead of 2.5 at half a voxel (a quarter of
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
    max_translation : float
        Largest translation, per axis, that one registration seeks from its initial guess,
        m (``AlignParams.max_translation``); 0 (default): 0.54 extents of the reference
        (0.3 m on the simulated table). The phase-correlation grid then holds the two
        views grown by this instead of by the reference view's radius (about 0.5 m above
        the table), a grid 3-8 times smaller. Must exceed the displacement of the view's
        centroid, which a camera rotation adds to (30 degrees at 0.55 m: 0.28 m). ``inf``:
        the paper's unbounded grid. Measured in docs/servoing.md.
    tracking_translation : float
        Once the registration has locked on (the watchdog is armed), or from the step after
        a relocalization was taken, the search is bounded
        by this instead of ``max_translation`` while the previous estimate, carried along
        the camera's measured motion, moves the reference's centroid by at most half of it
        from where the registration starts, m; 0 (default): 0.18 extents of the reference
        (0.1 m on the simulated table). Near the goal the phase-correlation grid is
        then about 2 times smaller (measured 4.6 to 2.8 ms per registration with 0.1 m). A
        second prepared reference keeps its own FFT plans. Once locked on, a bounded
        estimate whose fitness is below ``watchdog_fitness`` is redone with
        ``max_translation`` (the answer may lie beyond the bound: a jump that the watchdog
        must see); before, the estimate is the carried one. ``inf``, or not below
        ``max_translation``: always ``max_translation``.
    tracking_icp : bool
        On those bounded steps, the point-to-plane ICP after Algorithm 1
        (``AlignParams.local_icp``: pairs within a voxel, then 0.4 of one; kept unless it
        lowers the fitness by more than 0.05). Algorithm 1's estimate from a view with
        geometry the reference lacks is pulled by it: a tool left on the table took a
        Panda start to a convergence 11 mm and 8.3 degrees off with a fitness of 0.975,
        and the ICP from that estimate, whose pairs leave the tool out, ends 0.1-0.3 mm
        and 0.04 degree from the truth (docs/servoing.md, "What the servo does when it
        cannot see").
    max_depth : float
        Points farther than this along the optical axis are ignored (both clouds), m; 0
        (default): the reference's farthest point plus 1.7 extents of it (1.5 m on the
        simulated table; the reference itself is never cropped). The
        registration grid spans both clouds: a camera turned toward the horizon would
        otherwise add the far floor and walls and slow every step (measured: from 0.1 to
        over 1 s per step). ``inf`` keeps everything.
    align_overrides : dict
        Further :class:`AlignParams` fields, e.g. ``{"threads": 2}``.
    """

    voxel_size: float = 0.0
    downsample_size: float = 0.0
    bandwidth: int = 8
    max_rotation_step: float = 0.05
    mode: ServoMode = "iteration"
    global_search: bool = False
    max_iterations: int = 30
    warm_start: bool = False
    max_translation: float = 0.0
    tracking_translation: float = 0.0
    tracking_icp: bool = True
    max_depth: float = 0.0
    align_overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in ("iteration", "pose"):
            raise ValueError(f"mode must be 'iteration' or 'pose', got {self.mode!r}")
        check_positive(self, ("max_rotation_step",))
        check_lengths(self, ("voxel_size", "downsample_size"))
        check_lengths(self, ("max_translation",), "unbounded")
        check_lengths(self, ("tracking_translation",), "off")
        check_lengths(self, ("max_depth",), "keep every point")
        check_at_least(self, "bandwidth", 2)
        check_at_least(self, "max_iterations", 1)
        check_keys(self.align_overrides, "align_overrides", AlignParams)


@dataclass
class LawParams:
    """The decoupled control law and its saturation.

    Attributes
    ----------
    lambda_t : float
        Translation gain of the law ``v = lambda_t t``, 1/s. The error shrinks by the factor
        ``1 - lambda_t dt`` per control period ``dt``: keep ``lambda_t dt <= 1``.
    lambda_r : float
        Rotation gain of the law ``omega = lambda_r theta u``, 1/s; same bound.
    max_linear_speed : float
        Saturation of ``|v|``, m/s.
    max_angular_speed : float
        Saturation of ``|omega|``, rad/s. A twist over either limit is scaled down as a
        whole, so the camera keeps its direction of motion.
    """

    lambda_t: float = 2.0
    lambda_r: float = 4.0
    max_linear_speed: float = 0.1
    max_angular_speed: float = math.radians(20.0)

    def __post_init__(self) -> None:
        check_positive(self, ("lambda_t", "lambda_r", "max_linear_speed", "max_angular_speed"))


@dataclass
class StopParams:
    """The stop rule (the servo form of eq. 17) and its hysteresis.

    Attributes
    ----------
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
    """

    translation_tolerance: float = 0.0005
    rotation_tolerance: float = math.radians(0.1)
    min_fitness: float = 0.95
    step_tolerance: float = 0.0
    reengage_translation: float = 0.003
    reengage_rotation: float = math.radians(1.0)
    reengage_steps: int = 3

    def __post_init__(self) -> None:
        check_positive(self, ("translation_tolerance", "rotation_tolerance"))
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
        check_share(self, ("min_fitness",))
        check_at_least(self, "reengage_steps", 1, "step")


@dataclass
class WatchdogParams:
    """The watchdog on implausible jumps of the estimate.

    Attributes
    ----------
    jump_limit_translation : float
        Watchdog: largest plausible change of the estimated translation from one step to the
        next (after the camera's own measured motion is accounted for), m; 0 (default): 0.18
        extents of the reference (0.1 m on the simulated table); ``inf``: no limit.
    jump_limit_rotation : float
        Watchdog: same for the rotation, rad.
    watchdog_fitness : float
        The watchdog is armed once an estimate with at least this fitness has been accepted
        (the registration has locked on). Before that the one-iteration estimate may jump
        between phase-correlation peaks as the view changes (measured: up to 0.6 m between
        steps in runs that then converged), and the speed limits bound the motion. Above 1
        the watchdog is never armed.
    """

    jump_limit_translation: float = 0.0
    jump_limit_rotation: float = math.radians(10.0)
    watchdog_fitness: float = 0.9

    def __post_init__(self) -> None:
        check_lengths(self, ("jump_limit_translation",), "no limit")
        check_positive(self, ("jump_limit_rotation",))
        if not self.watchdog_fitness >= 0.0:
            raise ValueError(f"watchdog_fitness must be >= 0, got {self.watchdog_fitness}")


@dataclass
class PlaneTurnParams:
    """The plane turn about the reference's dominant normal, and the dominant plane.

    Attributes
    ----------
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
    """

    plane_turn: bool = True
    plane_cone: float = math.radians(20.0)
    min_plane_share: float = 0.3
    plane_turn_bandwidth: int = 16
    plane_turn_stride: int = 4
    plane_turn_tilt: float = math.radians(5.0)

    def __post_init__(self) -> None:
        if not 0.0 < self.plane_cone < math.pi / 2:
            raise ValueError(f"plane_cone must be in (0, pi/2) rad, got {self.plane_cone}")
        check_share(self, ("min_plane_share",))
        check_at_least(self, "plane_turn_bandwidth", 2)
        if not 0.0 < self.plane_turn_tilt <= self.plane_cone:
            raise ValueError(
                f"plane_turn_tilt must be in (0, plane_cone] rad, got {self.plane_turn_tilt}"
            )
        check_at_least(self, "plane_turn_stride", 1)
