"""The arrival check, a part of the servo that owns its state: an estimate that brings the
camera to its goal while fitting the view poorly is refuted, and remembered, so that no
later relocalization takes it again (``ServoParams.refute_fitness``, ``refute_steps``;
docs/servoing.md, "Arrival check")."""

from __future__ import annotations

import numpy as np

from spectral_vs.poses import pose_error
from spectral_vs.servo.law import _rigid_inverse
from spectral_vs.servo.records import ServoRecord
from spectral_vs.servo.settings import ServoParams


class ArrivalCheck:
    """The refuted estimates (``T_first_desired``: the goal each put in the first step's
    camera frame) and the poor arrivals in a row. ``params`` is the servo's (read at each
    call)."""

    def __init__(self, params: ServoParams) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        """A new run: nothing refuted."""
        self._refuted: list[np.ndarray] = []
        self._poor_arrivals = 0  # steps in a row at the goal under refute_fitness

    def refutes(self, T: np.ndarray, record: ServoRecord, odometry: np.ndarray) -> bool:
        """Whether the estimate ``T`` (of ``record``) is refuted now: near the goal with a
        fitness under ``refute_fitness`` for ``refute_steps`` steps; then it is remembered
        and ``record.refuted`` set. ``odometry`` is T_first_current."""
        p = self.params.relocalization
        at_goal = (
            record.translation_error <= p.refute_translation
            and record.rotation_error <= p.refute_rotation
        )
        poor = at_goal and record.visible_fitness < p.refute_fitness
        self._poor_arrivals = self._poor_arrivals + 1 if poor else 0
        if self._poor_arrivals < p.refute_steps:
            return False
        record.refuted = True
        self._refuted.append(odometry @ T)
        self._poor_arrivals = 0
        return True

    def near_refuted(self, T_current_desired: np.ndarray, odometry: np.ndarray) -> bool:
        """Whether ``T_current_desired`` puts the goal within the watchdog's jump limits of
        a refuted estimate's (both placed by the camera's measured motion, ``odometry``)."""
        T_first_desired = odometry @ T_current_desired
        limits = self.params.watchdog
        for refuted in self._refuted:
            moved, turned = pose_error(_rigid_inverse(refuted) @ T_first_desired)
            if moved <= limits.jump_limit_translation and turned <= limits.jump_limit_rotation:
                return True
        return False
