"""Fixtures of both test trees (tests/python, the library's; benchmarks/tests, the
benchmarks'): the real scans beside the project, seeded random data and the simulated iiwa
moved off its reference pose."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spectral_vs.data.scenes import BoxWithBall, box_with_ball

ROOT = Path(__file__).resolve().parent


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """Folder of the PCL test scans (env SPECTRAL_VS_DATA, else ../shared/data)."""
    folder = Path(os.environ.get("SPECTRAL_VS_DATA", ROOT.parent / "shared" / "data"))
    if not (folder / "milk.pcd").is_file():
        pytest.fail(f"test scans not found in {folder}: set SPECTRAL_VS_DATA")
    return folder


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(2024)


#: The tests' object: a 24 x 12 x 8 cm box with a 6 cm ball beside it, both whole
#: (asymmetric); the same as tests/cpp/test_support.hpp's.
BOX_AND_SPHERE = BoxWithBall(
    half=(0.12, 0.06, 0.04),
    ball_centre=(0.10, 0.10, 0.0),
    ball_radius=0.06,
    offset=(0.0, 0.0, 0.0),
    bottom=True,
    hidden_dropped=False,
)


def box_and_sphere(rng: np.random.Generator, samples: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    """``samples`` points and outward normals of BOX_AND_SPHERE, half on the sphere."""
    return box_with_ball(rng, samples=samples, shape=BOX_AND_SPHERE)


@contextmanager
def iiwa_small_start(capture: Callable[[Any], Any]) -> Iterator[tuple[Any, Any, np.ndarray]]:
    """The simulated iiwa (kinematic mode, 160 x 120 images) with every joint moved from
    HOME_Q by up to 0.05 rad, seeded (32 mm and 3.9 degrees of camera displacement).

    Yields ``(robot, reference, T_world_reference)``: ``capture(robot)`` and the camera
    pose, both taken at HOME_Q before the move. Skips without pybullet.
    """
    pytest.importorskip("pybullet")
    from spectral_vs import sim

    params = sim.SimParams(
        mode="kinematic", camera=sim.CameraParams(intrinsics=sim.CameraIntrinsics(160, 120))
    )
    with sim.PyBulletRobot(params) as robot:
        reference = capture(robot)
        T_world_reference = robot.camera_pose()
        q = np.asarray(sim.HOME_Q) + np.random.default_rng(1).uniform(-0.05, 0.05, 7)
        robot.reset_joint_positions(q)
        yield robot, reference, T_world_reference
