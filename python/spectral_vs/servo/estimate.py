"""The estimate the servo holds, a part that owns its state: the last accepted
``T_current_desired`` and how far the servo trusts it (the watchdog's lock-on, the global
registration it descends from, whether it is lost). Every change of that trust is one of
this part's methods."""

from __future__ import annotations

import numpy as np

from spectral_vs.servo.law import _rigid_inverse


class TrackedEstimate:
    """The last accepted estimate and the servo's trust in it."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """A new run: no estimate, none ever taken."""
        self.forget()
        #: A global registration was taken in this run (``anchored`` implies it).
        self.ever_anchored = False

    def forget(self) -> None:
        """No estimate: the next step relocalizes."""
        self.previous: np.ndarray | None = None  #: the last accepted T_current_desired
        self.armed = False  #: the watchdog is armed (a fitness of watchdog_fitness was reached)
        self.anchored = False  #: a global registration was taken: registrations warm-start
        self.lost = True  #: no trusted estimate: the next step relocalizes

    def take(self, T_current_desired: np.ndarray) -> None:
        """A global registration the verdict vouched for becomes the estimate."""
        self.previous = T_current_desired
        self.anchored = True
        self.ever_anchored = True
        self.lost = False

    def accept(self, T_current_desired: np.ndarray, arms: bool, trusted: bool) -> None:
        """A step's estimate is kept: it ``arms`` the watchdog (its fitness reached
        ``watchdog_fitness``) or not, and is ``trusted`` (its score reached
        ``relocalize_fitness``) or lost."""
        self.previous = T_current_desired
        self.armed = self.armed or arms
        self.lost = not trusted

    @property
    def locked(self) -> bool:
        """The servo vouches for the estimate: the watchdog armed or a global registration
        taken."""
        return self.armed or self.anchored

    def predicted(self, motion: np.ndarray | None) -> np.ndarray:
        """The estimate carried along the camera's motion since it was accepted, ``motion``
        = ``T_accepted_current`` (None: the camera is taken as still)."""
        assert self.previous is not None
        if motion is None:
            return self.previous
        return _rigid_inverse(np.asarray(motion, dtype=float)) @ self.previous
