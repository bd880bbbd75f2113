"""How often one servo step crosses from Python into the C++ core (issue 35: the fewer, the
more of the step is one C++ stage): every call of a ``spectral_vs._core`` function or method
during ``SpectralServo.step_record``, counted with ``sys.setprofile``, per step of one
simulated run (iiwa, the first moderate start of seed 33, 320 x 240). Attribute reads of
core objects (``cloud.points``) are not calls and are not counted.

Writes the table into docs/architecture.md (block ``servo-crossings``)::

    python benchmarks/servo_crossings.py
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path
from typing import Any

import numpy as np
import report as report_lib

from spectral_vs import experiment, sim
from spectral_vs import servo as servo_lib

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
MAX_STEPS = 60


def _core_name(function: Any) -> str | None:
    """The name of a core function or method, None for any other C function."""
    owner = getattr(function, "__self__", None)
    module = getattr(function, "__module__", None) or type(owner).__module__
    if "spectral_vs._core" not in str(module):
        return None
    return str(getattr(function, "__name__", function))


def crossings_per_step() -> tuple[list[int], collections.Counter, str]:
    """The calls into the core of every step, the calls by name over the run, and how the
    run ended."""
    params = sim.SimParams(mode="kinematic", robot=sim.robot_model("iiwa"))
    with sim.PyBulletRobot(params) as robot:
        reference = robot.capture()
        home = params.robot.home_q
        q = experiment.start_poses(robot.kinematics, "moderate", 1, 33, home)[0][0]
        robot.reset_joint_positions(q)
        servo = servo_lib.SpectralServo(reference)
        step_record = servo.step_record
        per_step: list[int] = []
        by_name: collections.Counter = collections.Counter()

        def counted(*args: Any, **kwargs: Any) -> Any:
            calls: collections.Counter = collections.Counter()

            def profile(frame: Any, event: str, function: Any) -> None:
                name = _core_name(function) if event == "c_call" else None
                if name is not None:
                    calls[name] += 1

            sys.setprofile(profile)
            try:
                return step_record(*args, **kwargs)
            finally:
                sys.setprofile(None)
                per_step.append(sum(calls.values()))
                by_name.update(calls)

        servo.step_record = counted  # type: ignore[method-assign]
        log = servo_lib.run_servo(robot, robot.kinematics, servo, dt=0.1, max_steps=MAX_STEPS)
    return per_step, by_name, log.reason


def main() -> None:
    per_step, by_name, reason = crossings_per_step()
    steps = len(per_step)
    rows = [[name, f"{count / steps:.2f}"] for name, count in by_name.most_common()]
    text = (
        f"Commit `{report_lib.commit()}`; `python benchmarks/servo_crossings.py`: {steps} steps "
        f"(run ended `{reason}`), calls into the core per step: median "
        f"{np.median(per_step):.0f}, at most {max(per_step)}.\n\n"
        + report_lib.markdown(["core function", "calls per step (mean)"], rows)
    )
    print(text)
    if report_lib.replace_block(DOC, "servo-crossings", text):
        print(f"wrote the table into {DOC.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
