"""Shared fixtures: the real scans beside the project and seeded random data."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


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


def box_and_sphere(rng: np.random.Generator, samples: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward normals of a 0.25 m box with a sphere beside it (asymmetric)."""
    half = samples // 2
    n_sphere = rng.normal(size=(half, 3))
    n_sphere /= np.linalg.norm(n_sphere, axis=1, keepdims=True)
    p_sphere = np.array([0.10, 0.10, 0.0]) + 0.06 * n_sphere
    u = rng.uniform(-1, 1, size=(samples - half, 3))
    axis = rng.integers(0, 3, samples - half)
    rows = np.arange(samples - half)
    u[rows, axis] = np.sign(u[rows, axis])
    p_box = u * np.array([0.12, 0.06, 0.04])
    n_box = np.zeros_like(u)
    n_box[rows, axis] = u[rows, axis]
    return np.vstack([p_sphere, p_box]), np.vstack([n_sphere, n_box])
