"""Three parts of the servo that own their state, what it knows of its camera between
frames: the clock of its steps, with the outage it measures (how long since the last usable
frame); the camera's measured motion (its odometry); and the memory of the last frame, which
tells a stale frame from a still camera's."""

from __future__ import annotations

import math
import time

import numpy as np

from spectral_vs._core import PointCloud
from spectral_vs.poses import pose_error
from spectral_vs.sensor_faults import frame_fingerprint
from spectral_vs.servo.records import ServoRecord, ServoStatus

#: The camera counts as still (a repeated frame is then no stale frame) while it has moved
#: less than this since the frame was first seen, m and rad.
_STILL_TRANSLATION = 1e-6
_STILL_ROTATION = 1e-6

#: Slack of the outage's comparison with max_outage, s: a robot clock adding up periods of
#: 0.1 s reads 0.30000000000000004 after three.
_CLOCK_TOLERANCE = 1e-9


class StepClock:
    """The time of each step and the outage: the time since the last usable frame, and the
    stop once held steps have lasted longer than ``max_outage``."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """A new run: no step and no usable frame yet."""
        self._last_now: float | None = None
        self._last_usable: float | None = None

    def tick(self, now: float | None) -> float:
        """The step's time, s: ``now``, checked to be finite and not before the last step's
        (ValueError naming ``now``), or the monotonic clock."""
        if now is None:
            return time.monotonic()
        value = float(now)
        if not math.isfinite(value):
            raise ValueError(f"now must be a finite time in s, got {now}")
        if self._last_now is not None and value < self._last_now:
            raise ValueError(
                f"now must not go backwards: got {value} s after {self._last_now} s "
                "(the same clock at every step; reset() starts a new run)"
            )
        self._last_now = value
        return value

    def usable(self, now: float) -> None:
        """The frame of the step at ``now`` was used: no outage up to then."""
        self._last_usable = now

    def hold(
        self, record: ServoRecord, hold: str, message: str, now: float, max_outage: float
    ) -> None:
        """Fill ``record`` as a held step at ``now`` (zero twist; ``hold`` and ``message``
        say why), or as the stop ``"sensor_outage"`` (``"unreliable"`` for the hold of that
        name) when the holds have lasted longer than ``max_outage`` (s; 0: at once)."""
        if self._last_usable is None:
            self._last_usable = now  # no frame used yet: the outage starts here
        outage = now - self._last_usable
        record.hold, record.outage = hold, outage
        record.twist = np.zeros(6)
        limit = max_outage
        if limit == 0 or outage > limit + _CLOCK_TOLERANCE:
            unreliable = hold == "unreliable"
            record.status = ServoStatus(
                "stopped",
                "unreliable" if unreliable else "sensor_outage",
                f"no {'reliable estimate' if unreliable else 'usable frame'} for "
                f"{outage:.3f} s (max_outage {limit:g} s); last hold {hold}: {message}",
            )
        else:
            record.status = ServoStatus("running", "", f"holding ({hold}): {message}")


class Odometry:
    """The camera's measured motion (the robot's forward kinematics, step by step): since
    the last accepted estimate, ``T_accepted_current``, which carries that estimate to the
    current frame; and since the run's first step, ``T_first_current``, the frame in which
    the recovery's plane and the refuted goals are kept."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """A new run: no motion."""
        self.since_accepted = np.eye(4)  #: T_accepted_current
        self.since_first = np.eye(4)  #: T_first_current

    def carry(self, step: np.ndarray) -> None:
        """The camera moved by ``step`` (T_previous_current) since the last step."""
        self.since_accepted = self.since_accepted @ step
        self.since_first = self.since_first @ step

    def accepted(self) -> None:
        """This step's estimate was accepted: the motion since it starts afresh."""
        self.since_accepted = np.eye(4)


class StaleFrames:
    """The memory of the last frame: its fingerprint, the camera's motion since it came
    first, and the last capture stamp."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the last frame and stamp."""
        self._key: bytes | None = None
        self._motion = np.eye(4)
        self._last_stamp: float | None = None

    def moved(self, step: np.ndarray) -> None:
        """The camera moved by ``step`` (T_previous_current) since the last step."""
        self._motion = self._motion @ step

    def check(self, cloud: PointCloud, stamp: float | None) -> str | None:
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
        if key != self._key:
            self._key = key
            self._motion = np.eye(4)
            return None
        moved, turned = pose_error(self._motion)
        if moved < _STILL_TRANSLATION and turned < _STILL_ROTATION:
            return None
        return (
            f"the same frame again after the camera moved {1000 * moved:.2f} mm and "
            f"{math.degrees(turned):.3f} deg"
        )
