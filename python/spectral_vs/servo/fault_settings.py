"""The settings of the stages that run when the servo cannot trust what it sees, one small
dataclass a stage, every field with its unit: the sensor faults and the holds
(:class:`FaultParams`), the relocalization (:class:`RelocalizationParams`) and the recovery
(:class:`RecoveryParams`). :class:`~spectral_vs.servo.ServoParams` holds one of each."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from spectral_vs._core import ViewAlignParams
from spectral_vs.servo.setting_checks import (
    check_at_least,
    check_keys,
    check_lengths,
    check_number,
    check_positive,
    check_share,
)


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
        check_at_least(self, "min_points", 1)
        if not (self.max_outage >= 0 and math.isfinite(self.max_outage)):
            raise ValueError(
                f"max_outage must be finite and >= 0 s (0: stop at the first fault), "
                f"got {self.max_outage}"
            )
        check_lengths(self, ("occlusion_margin",), "no occluder test")
        check_share(self, ("occlusion_min_share", "occlusion_max_share"))


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
        check_share(self, ("relocalize_fitness", "relocalize_score", "refute_fitness"))
        check_lengths(self, ("refute_translation",))
        check_positive(self, ("refute_rotation",))
        check_at_least(self, "refute_steps", 1, "step")
        check_at_least(self, "relocalize_interval", 1, "step")
        if not 1 <= self.relocalize_retry <= self.relocalize_interval:
            raise ValueError(
                f"relocalize_retry must be in [1, relocalize_interval = "
                f"{self.relocalize_interval}] steps, got {self.relocalize_retry}"
            )
        check_at_least(self, "relocalize_backoff", 1)
        check_keys(self.view_overrides, "view_overrides", ViewAlignParams)


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
        check_share(self, ("recover_score",))
        if self.recover_after < 0:
            raise ValueError(
                f"recover_after must be >= 0 relocalizations (0: no recovery), "
                f"got {self.recover_after}"
            )
        check_lengths(self, ("recover_standoff",))
        check_at_least(self, "recover_steps", 1, "step")
        check_at_least(self, "recover_retry", 1, "step")
        check_at_least(self, "recover_widen", 0)
        if not check_number(self, "recover_excursion") >= 0:
            raise ValueError(
                f"recover_excursion must be >= 0 m (inf: no bound), got {self.recover_excursion}"
            )
