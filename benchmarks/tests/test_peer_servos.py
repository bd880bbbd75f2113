"""The peer controllers of benchmarks/peer_servos.py: the depth-map interaction matrix against
finite differences of an analytically rendered surface, the sign of the dense depth servo's
step, its convergence in the PyBullet scene, and ICP / FPFH position-based servoing (Open3D,
skipped when it is not installed)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import peer_servos
import pytest
from conftest import iiwa_small_start
from peer_servos import (
    DenseDepthServo,
    DepthServoParams,
    RegistrationServoParams,
    depth_gradients,
    depth_image_from_cloud,
    depth_interaction_matrix,
    normalized_coordinates,
)

from spectral_vs.servo import pose_error, rotation_matrix, run_servo

# --- A smooth surface rendered exactly --------------------------------------------------

#: Gaussian bumps on the surface: centre x, y (m), height (m), width (m).
BUMPS = ((0.03, -0.02, 0.05, 0.04), (-0.12, 0.06, -0.04, 0.05), (0.1, 0.1, 0.03, 0.03))


def height(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The surface Z_w = h(X_w, Y_w) in the world frame: a tilted plane 0.6 m in front of
    the world origin (the camera looks along +Z_w) with three bumps."""
    Z = 0.6 + 0.15 * X - 0.1 * Y
    for x0, y0, a, s in BUMPS:
        Z = Z + a * np.exp(-((X - x0) ** 2 + (Y - y0) ** 2) / (2 * s * s))
    return Z


def render(T_world_camera: np.ndarray, intrinsics, du: float = 0.0, dv: float = 0.0):
    """Depth image (H, W) of the surface, m, by Newton's method along each pixel's ray; the
    rays can be shifted by (du, dv) in normalized coordinates (for exact gradients)."""
    x, y = normalized_coordinates(intrinsics)
    xx, yy = np.broadcast_arrays(x + du, y + dv)
    rays = np.stack([xx, yy, np.ones_like(xx)], axis=-1) @ T_world_camera[:3, :3].T
    origin = T_world_camera[:3, 3]
    depth = np.full(xx.shape, 0.6)  # the camera-frame Z of o + depth * ray is depth
    eps = 1e-7
    for _ in range(40):
        P = origin + depth[..., np.newaxis] * rays
        X, Y = P[..., 0], P[..., 1]
        hx = (height(X + eps, Y) - height(X - eps, Y)) / (2 * eps)
        hy = (height(X, Y + eps) - height(X, Y - eps)) / (2 * eps)
        g = P[..., 2] - height(X, Y)
        depth = depth - g / (rays[..., 2] - hx * rays[..., 0] - hy * rays[..., 1])
    return depth


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """exp of the twist (v, omega) as a 4 x 4 matrix (power series: small twists only)."""
    A = np.zeros((4, 4))
    w = xi[3:]
    A[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    A[:3, 3] = xi[:3]
    T, term = np.eye(4), np.eye(4)
    for k in range(1, 25):
        term = term @ A / k
        T = T + term
    return T


def back_project(depth: np.ndarray, intrinsics) -> np.ndarray:
    x, y = normalized_coordinates(intrinsics)
    points = np.stack(np.broadcast_arrays(x * depth, y * depth, depth), axis=-1).reshape(-1, 3)
    return points[np.isfinite(points).all(axis=1)]


INTRINSICS = SimpleNamespace(width=80, height=60, fx=70.0, fy=70.0, cx=40.0, cy=29.0)


@pytest.fixture(scope="module")
def camera() -> np.ndarray:
    """A camera pose looking at the surface, turned about every axis."""
    T = np.eye(4)
    T[:3, :3] = rotation_matrix([0.1, -0.15, 0.3])
    T[:3, 3] = (0.01, -0.02, 0.0)
    return T


# --- The interaction matrix -------------------------------------------------------------


@pytest.mark.parametrize("axis", range(6))
def test_interaction_matrix_matches_finite_differences(camera, axis):
    """Moving the camera by a small twist along one axis (1 mm or 0.1 degree, in its own
    frame) changes each pixel's depth by L_Z times the twist: relative error of the
    predicted change below 1e-3 (measured 3e-7 to 1.6e-4, second-order terms), with the
    depth gradients of L_Z from rays shifted by 1e-5."""
    Z = render(camera, INTRINSICS)
    h = 1e-5
    Zx = (render(camera, INTRINSICS, du=h) - render(camera, INTRINSICS, du=-h)) / (2 * h)
    Zy = (render(camera, INTRINSICS, dv=h) - render(camera, INTRINSICS, dv=-h)) / (2 * h)
    x, y = np.broadcast_arrays(*normalized_coordinates(INTRINSICS))
    L = depth_interaction_matrix(Z.ravel(), Zx.ravel(), Zy.ravel(), x.ravel(), y.ravel())
    xi = np.zeros(6)
    xi[axis] = 1e-3 if axis < 3 else math.radians(0.1)
    # Central difference of the motion: the change is odd in the twist to second order.
    change = render(camera @ se3_exp(xi), INTRINSICS) - render(camera @ se3_exp(-xi), INTRINSICS)
    actual = change.ravel() / 2
    predicted = L @ xi
    assert np.linalg.norm(actual) > 1e-5  # every axis moves the depth map
    assert np.linalg.norm(predicted - actual) / np.linalg.norm(actual) < 1e-3


def test_interaction_matrix_with_image_gradients(camera):
    """The same prediction with the servo's own gradients (central differences of the
    80 x 60 image) for a combined twist of 1.5-2 mm and 0.1-0.3 degree: within 3% (measured
    1.1%), on the 94% of the pixels whose gradients are valid."""
    Z = render(camera, INTRINSICS)
    Zx, Zy, valid = depth_gradients(Z, INTRINSICS)
    x, y = np.broadcast_arrays(*normalized_coordinates(INTRINSICS))
    L = depth_interaction_matrix(Z[valid], Zx[valid], Zy[valid], x[valid], y[valid])
    xi = np.array([2e-3, -1e-3, 1.5e-3, *np.radians([0.2, -0.1, 0.3])])
    actual = (render(camera @ se3_exp(xi), INTRINSICS) - Z)[valid]
    assert valid.mean() > 0.9
    assert np.linalg.norm(L @ xi - actual) / np.linalg.norm(actual) < 0.03


def test_depth_gradients_mask_missing_pixels_and_discontinuities():
    """A plane Z = 0.5 + 0.1 x with one missing pixel and a 10 cm step: exact gradient
    (0.1 m per normalized unit) on the plane, masked next to the hole and across the step
    and on the 1-pixel border."""
    x, _ = normalized_coordinates(INTRINSICS)
    Z = np.tile(0.5 + 0.1 * x, (INTRINSICS.height, 1))
    Z[10, 10] = np.nan
    Z[30:, 60:] += 0.1
    Zx, Zy, valid = depth_gradients(Z, INTRINSICS)
    assert not valid[10, 10] and not valid[10, 11] and not valid[9, 10]
    assert not valid[40, 59] and not valid[40, 60] and not valid[29, 65]
    assert not valid[0].any() and not valid[:, -1].any()
    assert valid[20, 20] and valid[45, 70]
    assert np.allclose(Zx[valid], 0.1) and np.allclose(Zy[valid], 0.0, atol=1e-12)


def test_depth_image_from_cloud_recovers_the_image(camera):
    """Back-projected pixels project back onto themselves: the image is recovered exactly
    (pixels, depth to 1e-12 m), missing pixels stay missing."""
    Z = render(camera, INTRINSICS)
    Z[5:9, 20:30] = np.nan
    image = depth_image_from_cloud(back_project(Z, INTRINSICS), INTRINSICS)
    assert np.array_equal(np.isnan(image), np.isnan(Z))
    assert np.nanmax(np.abs(image - Z)) < 1e-12


# --- The dense depth servo --------------------------------------------------------------


def test_gauss_newton_step_points_to_the_desired_pose_and_reduces_the_error(camera):
    """From a camera 5.4 mm and 1.1 degrees off the desired pose: the Gauss-Newton step
    estimates the displacement (T_current_desired) to 15% of its size (measured 10% of the
    translation, 6% of the rotation: first order, gradients of the 160 x 120 image), and
    moving by the commanded twist for 0.1 s scales the RMS depth error by 1 - lambda dt =
    0.8 (to 0.05; measured 0.80)."""
    intr = SimpleNamespace(width=160, height=120, fx=140.0, fy=140.0, cx=80.0, cy=59.0)
    desired = render(camera, intr)
    delta = np.array([0.004, -0.003, 0.002, *np.radians([0.5, 0.8, -0.6])])
    T_world_current = camera @ se3_exp(delta)
    current = render(T_world_current, intr)
    servo = DenseDepthServo(desired, intr, DepthServoParams(lambda_t=2.0, lambda_r=2.0))
    twist, status, record = servo.step_record(current)
    assert status.state == "running"
    T_true = np.linalg.inv(T_world_current) @ camera  # T_current_desired
    t_err, r_err = pose_error(np.linalg.inv(T_true) @ record.T_current_desired)
    t_true, r_true = pose_error(T_true)
    assert t_err < 0.15 * t_true and r_err < 0.15 * r_true
    rms_before = record.translation_cost
    after = render(T_world_current @ se3_exp(0.1 * twist), intr)
    _, rms_after, _ = servo.gauss_newton_step(after)
    assert 0.75 * rms_before < rms_after < 0.85 * rms_before  # 1 - lambda dt = 0.8
    # The opposite twist makes it worse.
    wrong = render(T_world_current @ se3_exp(-0.1 * twist), intr)
    assert servo.gauss_newton_step(wrong)[1] > rms_before


def test_depth_servo_converges_on_the_synthetic_surface(camera):
    """Integrating the twist (dt = 0.1 s) from 22 mm and 4.4 degrees off reaches the
    desired pose to 2 mm and 0.1 degree (measured 0.96 mm, 0.004 degree, in 15 steps; the
    stop rule is a step under 1 mm and 0.2 degree), and the controller reports convergence."""
    intr = SimpleNamespace(width=160, height=120, fx=140.0, fy=140.0, cx=80.0, cy=59.0)
    servo = DenseDepthServo(render(camera, intr), intr)
    T = camera @ se3_exp(np.array([0.015, -0.01, 0.012, *np.radians([2.0, -3.0, 2.5])]))
    assert pose_error(np.linalg.inv(T) @ camera)[0] > 0.02
    for _ in range(80):
        twist, status = servo.step(render(T, intr))
        if status.state != "running":
            break
        T = T @ se3_exp(0.1 * twist)
    t, r = pose_error(np.linalg.inv(T) @ camera)
    assert status.state == "converged", status
    assert t < 2e-3 and math.degrees(r) < 0.1


def test_depth_servo_checks_its_input(camera):
    with pytest.raises(ValueError, match="interaction"):
        DepthServoParams(interaction="both")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="lambda_t"):
        DepthServoParams(lambda_t=0.0)
    servo = DenseDepthServo(render(camera, INTRINSICS), INTRINSICS)
    with pytest.raises(ValueError, match="shape"):
        servo.step(np.zeros((10, 10)))
    with pytest.raises(ValueError, match="valid pixels"):
        DenseDepthServo(np.full((60, 80), np.nan), INTRINSICS)
    # An image with nothing in common stops the servo without motion.
    twist, status = servo.step(np.full((60, 80), np.nan))
    assert status.reason == "empty_cloud" and not twist.any()


def test_pybullet_depth_servo_reaches_the_reference_pose():
    """The simulated iiwa, joints moved from HOME_Q by up to 0.05 rad (32 mm and 3.9
    degrees of camera displacement), driven by run_servo with the dense depth servo on the
    raw depth images (160 x 120): back within 5 mm and 1 degree of the reference camera
    pose (measured 1.0 mm and 0.04 degree, 29 steps)."""
    with iiwa_small_start(lambda robot: robot.capture_depth()) as start:
        robot, reference, T_world_reference = start
        start_t, start_r = pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
        assert start_t > 0.02 and math.degrees(start_r) > 3
        servo = DenseDepthServo(reference, robot.params.camera.intrinsics)
        log = run_servo(
            peer_servos.DepthImageRobot(robot), robot.kinematics, servo, dt=0.1, max_steps=100
        )
        t, r = pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
    assert log.converged, log.status
    assert 1000 * t < 5.0 and math.degrees(r) < 1.0


# --- ICP / FPFH position-based servoing (Open3D) ----------------------------------------


def test_missing_open3d_names_the_extra(monkeypatch):
    def no_open3d(name):
        raise ImportError(f"No module named {name!r}")

    monkeypatch.setattr(peer_servos.importlib, "import_module", no_open3d)
    with pytest.raises(ImportError, match=r"spectral_vs\[bench\]"):
        peer_servos.RegistrationServo(np.zeros((1000, 3)))


def test_registration_params_are_checked():
    with pytest.raises(ValueError, match="method"):
        RegistrationServoParams(method="gicp")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="voxel_size"):
        RegistrationServoParams(voxel_size=-1.0)


@pytest.mark.parametrize("method", ["icp", "fpfh"])
def test_registration_servo_estimates_the_pose_and_commands_the_law(camera, method):
    """Clouds of the synthetic surface from the desired camera and from one 12 mm and 3
    degrees off: the estimated T_current_desired is within 1 mm and 0.2 degree of the
    truth (measured 0.1 mm / 0.004 degree for ICP, 0.01 mm / 0.005 degree for FPFH), and
    the twist is (lambda_t t, lambda_r theta u) of the estimate."""
    pytest.importorskip("open3d")
    from spectral_vs.servo import rotation_vector

    intr = SimpleNamespace(width=160, height=120, fx=140.0, fy=140.0, cx=80.0, cy=59.0)
    T_world_current = camera @ se3_exp(np.array([0.008, -0.006, 0.006, *np.radians([1, 2, -2])]))
    reference = back_project(render(camera, intr), intr)
    current = back_project(render(T_world_current, intr), intr)
    params = RegistrationServoParams(method=method, voxel_size=0.008, min_points=100)
    servo = peer_servos.RegistrationServo(reference, params)
    twist, status, record = servo.step_record(current)
    T_true = np.linalg.inv(T_world_current) @ camera
    t_err, r_err = pose_error(np.linalg.inv(T_true) @ record.T_current_desired)
    assert 1000 * t_err < 1.0 and math.degrees(r_err) < 0.2
    assert status.state == "running" and record.fitness > 0.85  # measured 0.92
    T = record.T_current_desired
    expected = np.concatenate([2.0 * T[:3, 3], 4.0 * rotation_vector(T[:3, :3])])
    assert np.allclose(twist, expected * record.saturation)
    # At the goal it reports convergence and commands nothing.
    twist, status = servo.step(reference)
    assert status.state == "converged" and not twist.any()


@pytest.mark.parametrize("warm_start", [False, True])
def test_pybullet_icp_servo_reaches_the_reference_pose(warm_start):
    """ICP-PBVS on the simulated iiwa from the small start of the depth-servo test: within
    5 mm and 1 degree (measured 0.8 mm and 0.03 degree, cold and warm, 18 steps)."""
    pytest.importorskip("open3d")
    with iiwa_small_start(lambda robot: robot.capture()) as start:
        robot, reference, T_world_reference = start
        servo = peer_servos.RegistrationServo(
            reference, RegistrationServoParams(warm_start=warm_start)
        )
        log = run_servo(robot, robot.kinematics, servo, dt=0.1, max_steps=100)
        t, r = pose_error(np.linalg.inv(robot.camera_pose()) @ T_world_reference)
    assert log.converged, log.status
    assert 1000 * t < 5.0 and math.degrees(r) < 1.0
