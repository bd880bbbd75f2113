"""Units in Python: one pose distance (metres, radians, with mm and degree views) and the
phase correlation's shift in metres, against closed forms; the names 0.3 removed are
refused."""

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
    # From the trace, a half turn's angle would keep about 1e-9 rad of rounding (its cosine
    # is within 5e-15 of -1); the quaternion of so3_log does better, within the bound.
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
    with pytest.raises(ValueError, match="center must be 3 finite numbers"):
        svs.pose_error(np.eye(4), np.eye(4), center=[1.0, 2.0])


# --- The SO(3) helpers bound from C++ (so3_exp, so3_log, rotation_angle) ---------------


def rotation_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def random_rotations(count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Uniform rotations from normalised Gaussian quaternions, written out by hand."""
    out = []
    for w, x, y, z in rng.normal(size=(count, 4)):
        n = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
        out.append(
            np.array(
                [
                    [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
                ]
            )
        )
    return out


@pytest.mark.parametrize("degrees", [0.0, 1e-7, 0.01, 30.0, 90.0, 179.0, 180.0 - 1e-6])
def test_exp_and_log_about_z_match_the_closed_form(degrees):
    angle = math.radians(degrees)
    np.testing.assert_allclose(svs.so3_exp([0.0, 0.0, angle]), rotation_z(angle), atol=1e-15)
    np.testing.assert_allclose(svs.so3_log(rotation_z(angle)), [0.0, 0.0, angle], atol=1e-12)
    assert svs.rotation_angle(rotation_z(-angle)) == pytest.approx(angle, abs=1e-12)


def test_exp_is_the_inverse_of_log_on_random_rotations():
    rng = np.random.default_rng(7)
    for R in random_rotations(200, rng):
        w = svs.so3_log(R)
        assert np.linalg.norm(w) <= math.pi + 1e-12
        np.testing.assert_allclose(svs.so3_exp(w), R, atol=1e-12)
        # The angle is the one of the trace: 1 + 2 cos(angle) = trace(R).
        assert 1 + 2 * math.cos(svs.rotation_angle(R)) == pytest.approx(np.trace(R), abs=1e-12)


def test_the_half_turn_and_its_neighbours_keep_their_axis():
    axis = np.array([2.0, -1.0, 2.0]) / 3.0
    for angle in (math.pi - 1e-9, math.pi - 1e-4, math.pi):
        w = svs.so3_log(svs.so3_exp(angle * axis))
        assert np.linalg.norm(w) == pytest.approx(angle, abs=1e-9)
        # At exactly pi the sign of the axis is free: either one is the same rotation.
        assert abs(abs(w @ axis) - angle) < 1e-9


def test_exp_is_a_homomorphism_about_one_axis_and_its_derivative_is_hat():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    np.testing.assert_allclose(
        svs.so3_exp(0.3 * axis) @ svs.so3_exp(0.5 * axis), svs.so3_exp(0.8 * axis), atol=1e-15
    )
    w, h = np.array([0.2, -0.4, 0.1]), 1e-6
    derivative = (svs.so3_exp(h * w) - svs.so3_exp(-h * w)) / (2 * h)
    hat = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    np.testing.assert_allclose(derivative, hat, atol=1e-9)


def test_the_so3_helpers_refuse_bad_input_by_name():
    with pytest.raises(ValueError, match=r"rotation_vector must have shape \(3,\)"):
        svs.so3_exp(np.zeros(4))
    with pytest.raises(ValueError, match="rotation_vector is not finite"):
        svs.so3_exp([0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="R is not a rotation matrix"):
        svs.so3_log(2.0 * np.eye(3))
    with pytest.raises(ValueError, match=r"R must have shape \(3, 3\)"):
        svs.rotation_angle(np.eye(4))
    with pytest.raises(ValueError, match="R is not finite"):
        svs.rotation_angle(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="T must be a rigid transform: R is not a rotation"):
        svs.pose_error(np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="T and T_true must be rigid transforms"):
        svs.pose_error(np.eye(4), np.diag([2.0, 1.0, 1.0, 1.0]))


def test_the_servo_and_the_plots_use_the_one_function():
    assert servo.pose_error is svs.pose_error
    T_true = pose([0.1, 0.2, 0.3], [0.1, 0.2, 0.3])
    T_estimate = T_true @ pose([0.0, math.radians(3.0), 0.0], [0.002, 0.0, 0.0])
    assert not hasattr(plotting, "pose_errors")  # 0.2's (degrees, mm) helper, removed in 0.3
    error = svs.pose_error(T_estimate, T_true)
    assert error.rotation_deg == pytest.approx(3.0, abs=1e-9)
    assert error.translation_mm == pytest.approx(2.0)


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


def test_phase_correlation_is_no_longer_the_tuple_of_0_1():
    # Unpacking it as (shift in voxels, peak) warned in 0.2 and is gone in 0.3.
    a = np.zeros((8, 8, 8))
    a[2:4, 2:5, 3:6] = 1.0
    b = np.roll(a, (1, 2, -1), axis=(0, 1, 2))
    estimate = svs.phase_correlation(a, b, subvoxel=False)
    with pytest.raises(TypeError):
        _shift, _peak = estimate
    with pytest.raises(TypeError):
        estimate[1]
    np.testing.assert_array_equal(estimate.shift_voxels, [1, 2, -1])
    assert estimate.peak == pytest.approx(1.0, abs=1e-6)
    assert svs.translation_cost(a, b, shift_voxels=(1, 2, -1)) == 0.0
