"""3D phase correlation from Python: integer shifts, sub-voxel accuracy, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs


def _translation(t) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def test_integer_shift_of_random_grid_is_exact(rng):
    for _ in range(10):
        a = np.zeros((40, 36, 32), dtype=np.float32)
        a[12:28, 10:26, 10:22] = rng.random((16, 16, 12)) < 0.2
        shift = rng.integers(-8, 9, size=3)
        b = np.roll(a, shift, axis=(0, 1, 2))
        estimate = svs.phase_correlation(a, b)
        np.testing.assert_allclose(estimate.shift_voxels, shift, atol=1e-3)
        assert estimate.peak == pytest.approx(1.0, abs=1e-5)
        assert svs.translation_cost(a, b, shift) == 0.0


@pytest.mark.parametrize(("occupancy", "bound_mm"), [("trilinear", 1.0), ("binary", 1.5)])
def test_subvoxel_translation_of_milk_carton(data_dir, rng, occupancy, bound_mm):
    milk = svs.load_cloud(data_dir / "milk.pcd").points
    errors = []
    for _ in range(10):
        t = rng.uniform(-0.03, 0.03, size=3)
        keep_a = rng.random(len(milk)) > 0.3
        keep_b = rng.random(len(milk)) > 0.3
        moving = svs.PointCloud(milk[keep_a] + rng.normal(0, 0.001, (keep_a.sum(), 3)))
        target = svs.PointCloud(milk[keep_b] + t + rng.normal(0, 0.001, (keep_b.sum(), 3)))
        spec = svs.make_grid_spec(moving, target, 0.008)
        correlation = svs.PhaseCorrelation(spec)
        correlation.set_target(svs.voxelize(target, spec, occupancy=occupancy))
        estimate = correlation.estimate(svs.voxelize(moving, spec, occupancy=occupancy))
        errors.append(1000 * np.linalg.norm(np.asarray(estimate.shift) - t))
    assert max(errors) < bound_mm, errors


def test_subvoxel_translation_of_synthetic_shape(rng):
    points, _ = box_and_sphere(rng, 8000)
    for _ in range(10):
        t = rng.uniform(-0.03, 0.03, size=3)
        moving = svs.PointCloud(points + rng.normal(0, 0.001, points.shape))
        target = svs.PointCloud(points + t + rng.normal(0, 0.001, points.shape))
        spec = svs.make_grid_spec(moving, target, 0.008)
        estimate = svs.PhaseCorrelation(spec)
        estimate.set_target(svs.voxelize(target, spec, occupancy="trilinear"))
        result = estimate.estimate(svs.voxelize(moving, spec, occupancy="trilinear"))
        assert 1000 * np.linalg.norm(np.asarray(result.shift) - t) < 1.0


def test_same_input_gives_the_same_result(rng):
    points, _ = box_and_sphere(rng, 3000)
    a = svs.PointCloud(points)
    b = a.transformed(_translation([0.021, -0.013, 0.008]))
    spec = svs.make_grid_spec(a, b, 0.008)
    runs = {
        tuple(svs.phase_correlation(svs.voxelize(a, spec), svs.voxelize(b, spec)).shift)
        for _ in range(3)
    }
    assert len(runs) == 1


def test_phase_correlation_errors():
    with pytest.raises(ValueError, match="grid_a must be a VoxelGrid or a 3-D array"):
        svs.phase_correlation(np.zeros((4, 4)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="grid_a is empty"):
        svs.phase_correlation(np.zeros((4, 4, 4)), np.ones((4, 4, 4)))
    with pytest.raises(ValueError, match="expected the moving grid's"):
        svs.phase_correlation(np.ones((4, 4, 4)), np.ones((4, 4, 2)))
    with pytest.raises(ValueError, match="subvoxel_band must be in"):
        svs.phase_correlation(np.ones((4, 4, 4)), np.ones((4, 4, 4)), subvoxel_band=2.0)
    with pytest.raises(ValueError, match="has non-finite values"):
        svs.phase_correlation(np.full((4, 4, 4), np.nan), np.ones((4, 4, 4)))


def test_max_shift_bounds_the_search():
    spec = svs.GridSpec(origin=(0.0, 0.0, 0.0), resolution=0.01, dims=(32, 32, 32))
    rng = np.random.default_rng(5)
    points = rng.uniform(0.05, 0.12, size=(400, 3))
    moved = points + np.array([0.06, 0.0, 0.0])  # six voxels along x
    correlation = svs.PhaseCorrelation(spec)
    correlation.set_target(svs.voxelize(svs.PointCloud(moved), spec))
    moving = svs.voxelize(svs.PointCloud(points), spec)
    free = correlation.estimate(moving)
    bounded = correlation.estimate(moving, max_shift_voxels=(3, 3, 3))
    wide = correlation.estimate(moving, max_shift_voxels=(8, 8, 8))
    assert np.allclose(free.shift_voxels, [6, 0, 0], atol=0.5)
    assert np.all(np.abs(bounded.peak_voxels) <= 3)
    np.testing.assert_array_equal(wide.shift_voxels, free.shift_voxels)
    with pytest.raises(TypeError):  # 0.2's max_shift, removed in 0.3
        correlation.estimate(moving, max_shift=(3, 3, 3))
    with pytest.raises(ValueError, match="max_shift_voxels must be >= 0"):
        correlation.estimate(moving, max_shift_voxels=(3, -1, 3))


def _numpy_phase_correlation(moving: np.ndarray, target: np.ndarray):
    """The normalised correlation surface of eq. (7) by numpy's FFT: bins whose cross power
    is under 1e-6 of the DC bin's carry no phase; each kept bin of the full spectrum
    counts once in the normalisation."""
    cross = np.fft.fftn(target) * np.conj(np.fft.fftn(moving))
    power = np.abs(cross)
    kept = power > power.flat[0] * 1e-6
    surface = np.fft.ifftn(np.where(kept, cross / np.where(kept, power, 1.0), 0.0)).real
    return surface * surface.size / kept.sum()


def test_bounded_search_matches_numpy_on_the_feasible_shifts():
    """The inverse transform is computed only at feasible shifts (the bound, and shifts
    that overlap the two occupied boxes); the peak there is numpy's over the same set."""
    rng = np.random.default_rng(21)
    dims = (36, 32, 40)
    spec = svs.GridSpec(origin=(0.0, 0.0, 0.0), resolution=0.01, dims=dims)
    for trial in range(6):
        points = rng.uniform(0.08, 0.2, size=(300, 3))
        shift = rng.integers(-6, 7, size=3)
        target_points = points + 0.01 * shift + rng.normal(0.0, 0.004, size=points.shape)
        moving = svs.voxelize(svs.PointCloud(points), spec, occupancy="binary")
        target = svs.voxelize(svs.PointCloud(target_points), spec, occupancy="binary")
        surface = _numpy_phase_correlation(moving.values, target.values)
        correlation = svs.PhaseCorrelation(spec, subvoxel=False)
        correlation.set_target(target)
        for bound in (2, 5, 40):
            lo = np.maximum(target.occupied_min - moving.occupied_max, -bound)
            hi = np.minimum(target.occupied_max - moving.occupied_min, bound)
            ranges = [np.arange(a, b + 1) for a, b in zip(lo, hi, strict=True)]
            grid = np.meshgrid(*ranges, indexing="ij")
            shifts = np.stack([g.ravel() for g in grid], axis=1)
            values = surface[tuple((shifts % np.asarray(dims)).T)]
            best = shifts[np.argmax(values)]
            estimate = correlation.estimate(moving, max_shift_voxels=(bound, bound, bound))
            np.testing.assert_array_equal(estimate.peak_voxels, best, err_msg=f"{trial} {bound}")
            assert estimate.peak == pytest.approx(values.max(), abs=1e-4)
