"""The servo soak's loop taken apart: each component alone for many steps, its resident
memory and its Python allocations, to find where a growth of the whole loop comes from.

Components (``which``): ``render`` (PyBullet's ``getCameraImage`` at the home pose),
``depth`` (the Kinect noise model and ``cloud_from_depth`` on one rendered image),
``servo`` (``SpectralServo.step_record`` on 20 captured clouds in turn), ``joints`` (the
joint command: ``joint_positions``, the kinematics, ``send_joint_velocities``) and
``loop`` (the soak's loop keeping nothing per step). Printed: the resident memory at
step 100 and every fifth of the run, its growth after step 100, and the resident memory
after ``malloc_trim`` (memory that the allocator kept but the program no longer uses is
given back: a growth that it removes is no leak). ``--tracemalloc`` adds the net Python
allocations from step 100 on.

Usage::

    OMP_NUM_THREADS=1 nice -n 10 python benchmarks/soak_components.py render --steps 2000
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import time
import tracemalloc
from collections.abc import Callable

import numpy as np
from soak_benchmark import rss_mb

import spectral_vs as svs
from spectral_vs import servo as servo_lib
from spectral_vs import sim
from spectral_vs.sim import camera

WHICH = ("render", "depth", "servo", "joints", "loop")


def component(which: str, robot: sim.PyBulletRobot) -> Callable[[int], None]:
    """One step of ``which``, given the step's index."""
    intrinsics = robot.params.camera.intrinsics
    noise = robot.params.camera.noise
    servo = servo_lib.SpectralServo(robot.capture())
    clouds = [robot.capture() for _ in range(20)]
    depth = robot.capture_depth()
    kinematics = robot.kinematics
    velocity = svs.VelocityCommandParams(dt=0.1, max_joint_speed=1.0)
    rng = np.random.default_rng(0)
    previous: list[np.ndarray] = []

    def render(_: int) -> None:
        camera.render_depth(robot.client, robot.camera_pose(), intrinsics)

    def depth_to_cloud(_: int) -> None:
        camera.depth_to_cloud(noise.apply(depth, rng), intrinsics, robot.params.camera.normals)

    def servo_step(i: int) -> None:
        servo.step_record(clouds[i % len(clouds)], None, now=0.1 * i)

    def joints(_: int) -> None:
        q = robot.joint_positions()
        kinematics.forward(q)
        q_dot = np.asarray(kinematics.joint_velocities(q, np.zeros(6), velocity).q_dot)
        robot.send_joint_velocities(q_dot, 0.1)
        robot.camera_pose()

    def loop(_: int) -> None:
        q = robot.joint_positions()
        pose = np.asarray(kinematics.forward(q))
        motion = np.linalg.inv(previous[0]) @ pose if previous else None
        previous[:] = [pose]
        twist, status, record = servo.step_record(robot.capture(), motion, now=robot.time())
        q_dot = np.zeros_like(q)
        if status.state == "running" and not record.hold:
            q_dot = np.asarray(kinematics.joint_velocities(q, twist, velocity).q_dot)
        robot.send_joint_velocities(q_dot, 0.1)

    steps = {
        "render": render,
        "depth": depth_to_cloud,
        "servo": servo_step,
        "joints": joints,
        "loop": loop,
    }
    return steps[which]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("which", choices=WHICH)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--tracemalloc", action="store_true")
    args = parser.parse_args()
    if args.steps < 200:
        parser.error("--steps must be >= 200")
    noise = sim.DepthNoise.kinect(seed=0)
    with sim.PyBulletRobot(sim.SimParams(camera=sim.CameraParams(noise=noise))) as robot:
        step = component(args.which, robot)
        cpu = time.process_time()
        memory: dict[int, float] = {}
        traced = 0
        for i in range(1, args.steps + 1):
            step(i)
            if i == 100:
                gc.collect()
                if args.tracemalloc:
                    tracemalloc.start()
                    traced = tracemalloc.get_traced_memory()[0]
            if i == 100 or i % (args.steps // 5) == 0:
                memory[i] = rss_mb()
        gc.collect()
        python_kb = None
        if args.tracemalloc:
            python_kb = (tracemalloc.get_traced_memory()[0] - traced) / 1024
        end = rss_mb()
        ctypes.CDLL("libc.so.6").malloc_trim(0)
        trimmed = rss_mb()
    growth = end - memory[100]
    print(
        f"{args.which}, {args.steps} steps: "
        + ", ".join(f"{m:.1f} MB at {s}" for s, m in memory.items())
        + f"; growth after step 100 {growth:+.2f} MB "
        f"({1024 * growth / (args.steps - 100):.3f} kB a step); "
        f"after malloc_trim {trimmed:.1f} MB ({trimmed - memory[100]:+.2f}); "
        f"{time.process_time() - cpu:.0f} s CPU"
        + ("" if python_kb is None else f"; Python allocations {python_kb:+.1f} kB")
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
