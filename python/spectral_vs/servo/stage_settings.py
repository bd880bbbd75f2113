"""The settings of each stage of the servo, one small dataclass a stage; every field has
its unit. :class:`~spectral_vs.servo.ServoParams` holds one of each. The scale lengths
default to 0: derived from the reference when the servo is constructed
(:mod:`spectral_vs.servo.scale`)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Literal

from spectral_vs._core import AlignParams, ViewAlignParams

ServoMode = Literal["iteration", "pose"]


def _check_number(params: Any, name: str) -> Any:
    """The setting ``name`` of ``params``, refused unless a real number (TypeError naming
    it): ``lambda_t='2'`` would otherwise fail in a comparison that names nothing."""
    value = getattr(params, name)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    return value


def _check_positive(params: Any, names: tuple[str, ...]) -> None:
    """Refuse settings ``names`` of ``params`` that are not > 0 (ValueError)."""
    for name in names:
        value = _check_number(params, name)
        if not value > 0:  # also refuses NaN; inf turns a limit off
            raise ValueError(f"{name} must be > 0, got {value}")


def _check_lengths(params: Any, names: tuple[str, ...], off: str = "") -> None:
    """Refuse scale lengths ``names`` of ``params`` that are negative or NaN, or infinite
    unless ``off`` says what ``inf`` means (ValueError naming the setting). 0 is valid:
    derived from the reference when the servo is constructed (:mod:`spectral_vs.servo.scale`)."""
    for name in names:
        value = _check_number(params, name)
        if not (value >= 0 and (off or math.isfinite(value))):
            meaning = f"0: derived from the reference{'; inf: ' + off if off else ''}"
            raise ValueError(
                f"{name} must be {'>= 0' if off else 'finite and >= 0'} m ({meaning}), got {value}"
            )


def _check_at_least(params: Any, name: str, low: int, unit: str = "") -> None:
    """Refuse the setting ``name`` of ``params`` under ``low`` (ValueError)."""
    value = _check_number(params, name)
    if not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if not int(value) >= low:
        raise ValueError(f"{name} must be >= {low}{' ' + unit if unit else ''}, got {value}")


def _check_share(params: Any, names: tuple[str, ...]) -> None:
    """Refuse settings ``names`` of ``params`` outside [0, 1] (ValueError)."""
    for name in names:
        value = _check_number(params, name)
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{name} must be in [0, 1], got {value}")


def _check_keys(overrides: dict[str, Any], argument: str, settings: type) -> None:
    """Refuse keys of ``overrides`` that are no field of ``settings`` (TypeError naming the
    key, as the settings' own constructor does)."""
    for name in overrides:
        if name.startswith("_") or not hasattr(settings(), name):
            raise TypeError(f"{argument}: {settings.__name__} has no setting {name!r}")


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
        _check_positive(self, ("max_rotation_step",))
        _check_lengths(self, ("voxel_size", "downsample_size"))
        _check_lengths(self, ("max_translation",), "unbounded")
        _check_lengths(self, ("tracking_translation",), "off")
        _check_lengths(self, ("max_depth",), "keep every point")
        _check_at_least(self, "bandwidth", 2)
        _check_at_least(self, "max_iterations", 1)
        _check_keys(self.align_overrides, "align_overrides", AlignParams)


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
        _check_positive(self, ("lambda_t", "lambda_r", "max_linear_speed", "max_angular_speed"))


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
        _check_positive(self, ("translation_tolerance", "rotation_tolerance"))
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
        _check_share(self, ("min_fitness",))
        _check_at_least(self, "reengage_steps", 1, "step")


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
        _check_lengths(self, ("jump_limit_translation",), "no limit")
        _check_positive(self, ("jump_limit_rotation",))
        if not self.watchdog_fitness >= 0.0:
            raise ValueError(f"watchdog_fitness must be >= 0, got {self.watchdog_fitness}")


@dataclass
class FaultParams:
    """Sensor faults: the holds (:data:`~spectral_vs.servo.HOLDS`) and the outage that stops
    the servo.

    Attributes
    ----------
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
        before the registration; 0 (default): 0.09 extents of the reference (0.05 m on the
        simulated table). It covers the estimate's error in depth and the depth
        noise; a hand 0.25 m from the camera over the simulated table is 0.14-0.2 m nearer
        than the objects' tops. ``inf`` turns the test off.
    occlusion_min_share : float
        An occluder is present when at least this share of the current cloud's points are
        dropped as occluders and they hide at least this share of the reference, in [0,
        1]: near surfaces on none of the reference's rays are dropped and ridden (a camera
        far from the goal sees the near table nearer than the reference's nearest point;
        holding for them held iiwa extreme start 2 of seed 0 until the outage stopped it).
        While one is present the step holds
        (``"occluded"``) if fewer than ``min_points`` points remain, if the estimate would
        trip the watchdog, or if its fitness over the reference's visible part (fitness /
        (1 - hidden share)) is below ``watchdog_fitness``; otherwise the servo moves on the
        registration of the rest.
    occlusion_max_share : float
        An occluder that hides more than this share of the reference (in [0, 1]) is an
        outage, not a new scene: the step holds (``"occluded"``) without registering or
        relocalizing the little left in view. 0.5: the registration of the visible half
        still fits the reference's own surfaces (docs/servoing.md, "What the servo does
        when it cannot see").
    """

    min_points: int = 500
    max_outage: float = 0.5
    occlusion_margin: float = 0.0
    occlusion_min_share: float = 0.01
    occlusion_max_share: float = 0.5

    def __post_init__(self) -> None:
        _check_at_least(self, "min_points", 1)
        if not (self.max_outage >= 0 and math.isfinite(self.max_outage)):
            raise ValueError(
                f"max_outage must be finite and >= 0 s (0: stop at the first fault), "
                f"got {self.max_outage}"
            )
        _check_lengths(self, ("occlusion_margin",), "no occluder test")
        _check_share(self, ("occlusion_min_share", "occlusion_max_share"))


@dataclass
class RelocalizationParams:
    """The global registration when the servo has no trusted estimate.

    Attributes
    ----------
    relocalize : bool
        Register the reference onto the current view globally
        (:func:`spectral_vs.align_views`: any rotation, any translation within the views)
        when the servo has no trusted estimate: at its first step, and after a registration
        whose confidence was below ``relocalize_fitness`` (the view moved far, or the
        estimate slid off), at most every ``relocalize_interval`` steps. The estimate
        tracked so far, if its last relocalization was confirmed, goes in as the global
        search's prior: it is refined beside the search's hypotheses and kept unless a
        searched pose is better supported (an unconfirmed one would be taken again and
        again: docs/servoing.md). The
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
    view_overrides : dict
        :class:`spectral_vs.ViewAlignParams` fields of the relocalization, e.g.
        ``{"hypotheses": 24}`` (by default every length is derived from the views).
    refute_fitness : float
        The arrival check, in [0, 1]: near the goal the reference is in view again, so an
        estimate within ``refute_translation`` and ``refute_rotation`` of it whose fitness
        stays under this for ``refute_steps`` steps in a row is a wrong pose that tracked
        well, not the goal. The servo then forgets it, relocalizes, and never takes a
        global registration near it again (within the watchdog's ``jump_limit_*``, placed
        by the camera's measured motion). The same value as ``watchdog_fitness``: an
        estimate that the registration does not lock on even at the goal. Right estimates
        in that zone fitted at least 0.988 on the tuning starts; the wrong poses that the
        servo drove to and held, 0.81 (docs/servoing.md, "Arrival check"). 0 turns the
        check off.
    refute_translation : float
        The arrival check's zone about the goal, m; 0 (default): 0.054 extents of the
        reference (30 mm on the simulated table) ...
    refute_rotation : float
        ... and rad.
    refute_steps : int
        Steps in a row in the zone under ``refute_fitness`` that refute the estimate, >= 1.
    """

    relocalize: bool = True
    relocalize_fitness: float = 0.8
    relocalize_interval: int = 10
    relocalize_retry: int = 2
    relocalize_backoff: int = 2
    relocalize_score: float = 0.05
    view_overrides: dict[str, Any] = field(default_factory=dict)
    refute_fitness: float = 0.9
    refute_translation: float = 0.0
    refute_rotation: float = math.radians(3.0)
    refute_steps: int = 5

    def __post_init__(self) -> None:
        _check_share(self, ("relocalize_fitness", "relocalize_score", "refute_fitness"))
        _check_lengths(self, ("refute_translation",))
        _check_positive(self, ("refute_rotation",))
        _check_at_least(self, "refute_steps", 1, "step")
        _check_at_least(self, "relocalize_interval", 1, "step")
        if not 1 <= self.relocalize_retry <= self.relocalize_interval:
            raise ValueError(
                f"relocalize_retry must be in [1, relocalize_interval = "
                f"{self.relocalize_interval}] steps, got {self.relocalize_retry}"
            )
        _check_at_least(self, "relocalize_backoff", 1)
        _check_keys(self.view_overrides, "view_overrides", ViewAlignParams)


@dataclass
class RecoveryParams:
    """The recovery from a view the global registration cannot register.

    Attributes
    ----------
    recover_after : int
        Recovery from a view the global registration cannot register (docs/servoing.md,
        "Recovery"): after this many relocalizations in a row under ``relocalize_score``,
        with none taken yet, the servo stops following its local estimate (which, from a
        view that shares little with the reference, drifts farther off) and moves the
        camera to widen the overlap, relocalizing on at ``recover_retry``. When both the
        reference and the current view have a dominant plane (``min_plane_share``, within
        ``plane_cone``; a table top), it levels the camera onto it, in stages
        (``recover_widen``): when the first failed global registration had the support of
        ``recover_score`` (the view nearly registered), first turned in place (the
        rotation that takes the reference's plane normal to where the current view sees
        its own, about the camera's origin); then also at the reference's distance to the
        plane plus ``recover_standoff``, within ``recover_excursion``. Otherwise it backs
        off along its optical axis by ``recover_standoff`` from where the recovery
        started. 0: no recovery.
    recover_standoff : float
        How much farther from the scene than the reference the recovery takes the camera,
        m (> 0): a farther view sees more of the scene. 0 (default): 0.27 extents of the
        reference (0.15 m on the simulated table).
    recover_score : float
        Least support score of a global registration taken during the recovery, in [0, 1]
        (``relocalize_score`` otherwise): the recovery widens the view step by step, so a
        marginal score in its middle is waited out (a pose 17 degrees off scored 0.061
        there; the right ones 0.09-0.19).
    recover_steps : int
        Longest recovery, steps (>= 1): when no relocalization was taken within it, the
        servo stops with ``"lost"``.
    recover_retry : int
        Steps from one relocalization of the recovery to the next (>= 1). A recovery step
        without one costs about 2 ms, with one 40-90 ms (320 x 240): the spacing sets how
        much of a recovering run is global registration.
    recover_widen : int
        Every this many global registrations of the recovery that are not reliable take it
        one stage further: from the turn in place (if taken) to the reference's distance to
        the plane plus one ``recover_standoff``, then two, then three (>= 0; 0: one
        standoff throughout, no turn; the back-off widens the same way). Counted only
        once the camera is within one standoff and 10 degrees of the recovery's target (a
        view far on the way there says nothing of the target's) and when no occluder fills
        a tenth of the view. Since the servo takes only a reliable
        relocalization, a recovery that levels the camera where the view still registers
        only doubtfully must widen it: on the extreme starts of seed 0, 5 of 40 runs
        stopped ``"lost"`` at a fixed 0.15 m and converged at 0.3 m (docs/servoing.md,
        "What the servo does when it cannot see"); widening at every try on the way, a
        moderate start under an 8 cm box went 83 mm beyond its start.
    recover_excursion : float
        How much farther from the reference's distance to the plane than at its start the
        levelling recovery may take the camera, m (>= 0; inf, the default: no bound): the
        standoff is cut to the start's offset from that distance plus this. A move along
        the plane's normal bounded so adds at most this much to the camera's distance from
        the reference pose, whatever its offset along the plane, which the recovery cannot
        know. For a user who would rather stop (``"lost"``) than see the camera move away
        to widen its view: on the tuning starts (seeds 0-1, clean), 0.01 m took every
        excursion away and cost 4 of 80 large starts and 4 of 40 of the iiwa's extreme
        ones (docs/servoing.md, "Recovery from a view the registration cannot register").
    """

    recover_after: int = 1
    recover_standoff: float = 0.0
    recover_score: float = 0.08
    recover_steps: int = 60
    recover_retry: int = 8
    recover_widen: int = 1
    recover_excursion: float = math.inf

    def __post_init__(self) -> None:
        _check_share(self, ("recover_score",))
        if self.recover_after < 0:
            raise ValueError(
                f"recover_after must be >= 0 relocalizations (0: no recovery), "
                f"got {self.recover_after}"
            )
        _check_lengths(self, ("recover_standoff",))
        _check_at_least(self, "recover_steps", 1, "step")
        _check_at_least(self, "recover_retry", 1, "step")
        _check_at_least(self, "recover_widen", 0)
        if not _check_number(self, "recover_excursion") >= 0:
            raise ValueError(
                f"recover_excursion must be >= 0 m (inf: no bound), got {self.recover_excursion}"
            )


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
        _check_share(self, ("min_plane_share",))
        _check_at_least(self, "plane_turn_bandwidth", 2)
        if not 0.0 < self.plane_turn_tilt <= self.plane_cone:
            raise ValueError(
                f"plane_turn_tilt must be in (0, plane_cone] rad, got {self.plane_turn_tilt}"
            )
        _check_at_least(self, "plane_turn_stride", 1)
