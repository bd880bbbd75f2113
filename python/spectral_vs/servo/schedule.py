"""The relocalizations' schedule, a part of the servo that owns its state: how many steps
since the last global registration, whether it was confirmed, and how many in a row were
not, which spaces them out (``relocalize_interval``, ``relocalize_retry``,
``relocalize_backoff``, ``recover_retry``; docs/servoing.md, "Relocalization")."""

from __future__ import annotations

from spectral_vs.servo.settings import ServoParams


class RelocalizationSchedule:
    """When the next global registration may run. ``params`` is the servo's (read at each
    call)."""

    def __init__(self, params: ServoParams) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        """None tried: the next step may relocalize."""
        self._since: int | None = None  # steps since the last attempt
        self.confirmed = False  #: the last relocalization was taken and confirmed
        self._unconfirmed = 0  # relocalizations in a row not confirmed (the backoff)

    def step(self) -> None:
        """One more step since the last attempt."""
        if self._since is not None:
            self._since += 1

    def tried(self) -> None:
        """A global registration ran this step; unconfirmed until a step confirms it."""
        self._since = 0
        self.confirmed = False
        self._unconfirmed += 1

    def accepted(self, relocalized: bool, trusted: bool) -> None:
        """A step's estimate was accepted, ``trusted`` (its score over ``relocalize_fitness``)
        or not; ``relocalized``: it came from this step's global registration."""
        if relocalized:
            self.confirmed = trusted
        if trusted:
            self._unconfirmed = 0

    def due(self, recovering: bool) -> bool:
        """Whether a relocalization may run now: none was tried yet, or the last was
        ``relocalize_interval`` steps ago (when it was not confirmed, ``relocalize_retry``
        grown by ``relocalize_backoff`` per unconfirmed one in a row before it; while
        ``recovering``, ``recover_retry``: the recovery widens the view at every step)."""
        since = self._since
        p = self.params
        if since is None:
            return True
        if self.confirmed:
            return since >= p.relocalization.relocalize_interval
        if recovering:
            return since >= p.recovery.recover_retry
        growth = p.relocalization.relocalize_backoff ** max(0, self._unconfirmed - 1)
        return since >= min(
            p.relocalization.relocalize_interval, p.relocalization.relocalize_retry * growth
        )
