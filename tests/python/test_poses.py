"""Units in Python: one pose distance (metres, radians, with mm and degree views) and the
phase correlation's shift in metres, against closed forms; the old names still work, with
a DeprecationWarning."""

from __future__ import annotations

import math

import numpy as np
import pytest

import spectral_vs as svs
from spectral_vs import plotting, servo
from spectral_vs.poses import rotation_matrix


def pose(rotvec, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation_matrix(np.asarray(rotvec, dtype=float))
    T[:3, 3] = t
    return T


def test_a_relative_pose_in_metres_and_radians():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    error = svs.pose_error(pose(math.radians(30.0) * axis, [0.01, 0.02, -0.02]))
    assert isinstance(error, svs.PoseError)
    translation, rotation = error  # the order of the names
    assert translation == pytest.approx(0.03, abs=1e-12)
    assert rotation == pytest.approx(math.radians(30.0), abs=1e-12)
    assert error.translation_mm == pytest.approx(30.0, abs=1e-9)
    assert error.rotation_deg == pytest.approx(30.0, abs=1e-9)
    assert error == (error.translation_m, error.rotation_rad)


def test_an_estimate_against_the_truth_at_a_center():
    T_true = pose([0.3, -0.2, 0.5], [0.4, 0.1, 0.9])
    # The estimate turned by 4 degrees about z through the model's origin: a point 0.1 m
    # from the axis moves by the chord 2 (0.1) sin(2 degrees).
    T_estimate = T_true @ pose([0.0, 0.0, math.radians(4.0)], [0.0, 0.0, 0.0])
    center = np.array([0.1, 0.0, 0.05])
    error = svs.pose_error(T_estimate, T_true, center=center)
    assert error.rotation_deg == pytest.approx(4.0, abs=1e-9)
    assert error.translation_m == pytest.approx(2 * 0.1 * math.sin(math.radians(2.0)), abs=1e-12)
    assert svs.pose_error(T_estimate, T_true).translation_m == pytest.approx(0.0, abs=1e-15)
    # Two poses or their relative pose: the same distance.
    relative = svs.pose_error(np.linalg.inv(T_true) @ T_estimate, center=center)
    np.testing.assert_allclose(relative, error, rtol=0, atol=1e-12)


def test_rotations_near_half_a_turn_and_near_zero():
    # The angle comes from the trace: near a half turn its cosine is within 5e-15 of -1,
    # which leaves about 1e-9 rad (6e-8 degree) of rounding.
    assert svs.pose_error(pose([0.0, math.pi - 1e-7, 0.0], [0, 0, 0])).rotation_rad == (
        pytest.approx(math.pi - 1e-7, abs=1e-8)
    )
    assert svs.pose_error(pose([1e-9, 0.0, 0.0], [0, 0, 0])).rotation_rad == pytest.approx(
        1e-9, rel=1e-6
    )


def test_bad_poses_are_refused():
    with pytest.raises(ValueError, match=r"T must be a 4x4 transform, got shape \(3, 3\)"):
        svs.pose_error(np.eye(3))
    with pytest.raises(ValueError, match="T_true must be a 4x4"):
        svs.pose_error(np.eye(4), np.eye(3))
    with pytest.raises(ValueError, match="center must be 3 numbers"):
        svs.pose_error(np.eye(4), np.eye(4), center=[1.0, 2.0])


def test_the_servo_and_the_plots_use_the_one_function():
    assert servo.pose_error is svs.pose_error
    T_true = pose([0.1, 0.2, 0.3], [0.1, 0.2, 0.3])
    T_estimate = T_true @ pose([0.0, math.radians(3.0), 0.0], [0.002, 0.0, 0.0])
    with pytest.warns(DeprecationWarning, match=r"spectral_vs\.pose_error"):
        rotation_deg, translation_mm = plotting.pose_errors(T_estimate, T_true)
    error = svs.pose_error(T_estimate, T_true)
    assert (rotation_deg, translation_mm) == (error.rotation_deg, error.translation_mm)
    assert rotation_deg == pytest.approx(3.0, abs=1e-9) and translation_mm == pytest.approx(2.0)


def test_phase_correlation_gives_metres_and_names_voxels():
    # A box of points moved by (3, -2, 5) voxels of 4 mm.
    rng = np.random.default_rng(3)
    points = rng.uniform([0.0, 0.0, 0.0], [0.08, 0.06, 0.05], size=(3000, 3))
    moved = points + np.array([0.012, -0.008, 0.02])
    a, b = svs.PointCloud(points), svs.PointCloud(moved)
    spec = svs.make_grid_spec(a, b, 0.004)
    estimate = svs.phase_correlation(svs.voxelize(a, spec), svs.voxelize(b, spec), subvoxel=False)
    assert isinstance(estimate, svs.TranslationEstimate)
    np.testing.assert_array_equal(estimate.peak_voxels, [3, -2, 5])
    np.testing.assert_allclose(estimate.shift_voxels, [3, -2, 5], atol=1e-12)
    np.testing.assert_allclose(estimate.shift, [0.012, -0.008, 0.02], atol=1e-12)
    # The class's own estimate, on the same grids, says the same.
    correlation = svs.PhaseCorrelation(spec, subvoxel=False)
    correlation.set_target(svs.voxelize(b, spec))
    np.testing.assert_array_equal(correlation.estimate(svs.voxelize(a, spec)).shift, estimate.shift)


def test_the_old_tuple_of_phase_correlation_still_unpacks_with_a_warning():
    a = np.zeros((8, 8, 8))
    a[2:4, 2:5, 3:6] = 1.0
    b = np.roll(a, (1, 2, -1), axis=(0, 1, 2))
    with pytest.warns(DeprecationWarning, match="unpacking or indexing"):
        shift, peak = svs.phase_correlation(a, b, subvoxel=False)
    np.testing.assert_array_equal(shift, [1, 2, -1])  # voxels, as before
    assert peak == pytest.approx(1.0, abs=1e-6)
    with pytest.warns(DeprecationWarning):
        assert svs.phase_correlation(a, b, subvoxel=False)[1] == pytest.approx(1.0, abs=1e-6)
    assert svs.translation_cost(a, b, shift_voxels=(1, 2, -1)) == 0.0
