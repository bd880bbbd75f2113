"""Kinematics of the KUKA iiwa (pybullet_data) checked against PyBullet, which computes
forward kinematics and Jacobians with its own code, and against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs

pybullet = pytest.importorskip("pybullet")
pybullet_data = pytest.importorskip("pybullet_data")
from pybullet_utils.bullet_client import BulletClient  # noqa: E402

URDF = pybullet_data.getDataPath() + "/kuka_iiwa/model.urdf"
BASE, TIP = "lbr_iiwa_link_0", "lbr_iiwa_link_7"
TIP_INDEX = 6  # PyBullet link index of lbr_iiwa_link_7


def rotation(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def transform(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def pose(position, quaternion) -> np.ndarray:
    R = np.reshape(pybullet.getMatrixFromQuaternion(quaternion), (3, 3))
    return transform(R, position)


#: A wrist camera 7 cm off the flange axis, tilted: every Jacobian term matters.
T_TIP_CAMERA = transform(rotation([0.3, -0.5, 1.0], 0.4), [0.02, -0.07, 0.05])


@pytest.fixture(scope="module")
def kinematics() -> svs.Kinematics:
    return svs.Kinematics(URDF, BASE, TIP, T_TIP_CAMERA)


@pytest.fixture(scope="module")
def bullet():
    """Two iiwas: one at the world origin, one with a moved and turned base."""
    client = BulletClient(connection_mode=pybullet.DIRECT)
    at_origin = client.loadURDF(URDF, useFixedBase=True)
    T_world_base = transform(rotation([0.2, 0.1, 1.0], 0.8), [0.3, -0.4, 0.2])
    quaternion = _quaternion(T_world_base[:3, :3])
    moved = client.loadURDF(URDF, T_world_base[:3, 3].tolist(), quaternion, useFixedBase=True)
    yield client, at_origin, moved, T_world_base
    client.disconnect()


def _quaternion(R: np.ndarray) -> list[float]:
    w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2.0
    x = (R[2, 1] - R[1, 2]) / (4 * w)
    y = (R[0, 2] - R[2, 0]) / (4 * w)
    z = (R[1, 0] - R[0, 1]) / (4 * w)
    return [x, y, z, w]


def set_joints(client, body: int, q: np.ndarray) -> None:
    for index, value in enumerate(q):
        client.resetJointState(body, index, float(value))


def random_configurations(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    limits = np.array([2.9, 2.0, 2.9, 2.0, 2.9, 2.0, 3.0])
    return rng.uniform(-limits, limits, size=(count, 7))


# --- The chain read from the URDF ---------------------------------------------------------


def test_joints_and_limits_match_pybullet(kinematics, bullet):
    client, body, _, _ = bullet
    infos = [client.getJointInfo(body, j) for j in range(client.getNumJoints(body))]
    assert kinematics.joint_count == 7
    assert kinematics.joint_names == [info[1].decode() for info in infos]
    np.testing.assert_array_equal(kinematics.lower_limits, [info[8] for info in infos])
    np.testing.assert_array_equal(kinematics.upper_limits, [info[9] for info in infos])
    np.testing.assert_array_equal(kinematics.velocity_limits, [info[11] for info in infos])
    np.testing.assert_array_equal(kinematics.T_tip_camera, T_TIP_CAMERA)


def test_loading_from_a_string_gives_the_same_chain(kinematics):
    with open(URDF) as f:
        from_string = svs.Kinematics.from_urdf_string(f.read(), BASE, TIP, T_TIP_CAMERA)
    q = random_configurations(1, seed=1)[0]
    np.testing.assert_array_equal(from_string.forward(q), kinematics.forward(q))


# --- Forward kinematics and the Jacobian ----------------------------------------------------


def test_forward_matches_pybullet_link_frame(kinematics, bullet):
    client, _, moved, T_world_base = bullet
    for q in random_configurations(10, seed=2):
        set_joints(client, moved, q)
        state = client.getLinkState(moved, TIP_INDEX, computeForwardKinematics=True)
        T_world_tip = pose(state[4], state[5])  # [4:6] is the URDF link frame
        T_base_tip = np.linalg.inv(T_world_base) @ T_world_tip
        np.testing.assert_allclose(kinematics.tip_pose(q), T_base_tip, atol=1e-6)
        np.testing.assert_allclose(kinematics.forward(q), T_base_tip @ T_TIP_CAMERA, atol=1e-6)


def test_jacobian_matches_pybullet_in_the_camera_frame(kinematics, bullet):
    client, body, _, _ = bullet
    for q in random_configurations(10, seed=3):
        set_joints(client, body, q)
        state = client.getLinkState(body, TIP_INDEX, computeForwardKinematics=True)
        T_world_camera = pose(state[4], state[5]) @ T_TIP_CAMERA
        # PyBullet 3.2.7 takes the point in the link's URDF frame here (measured: its COM
        # frame is 2 cm off and disagrees by 2e-2); the base is at the world origin.
        p_tip_camera = T_TIP_CAMERA[:3, 3].tolist()
        linear, angular = client.calculateJacobian(
            body, TIP_INDEX, p_tip_camera, q.tolist(), [0.0] * 7, [0.0] * 7
        )
        R_world_camera = T_world_camera[:3, :3]
        expected = np.vstack(
            [R_world_camera.T @ np.array(linear), R_world_camera.T @ np.array(angular)]
        )
        np.testing.assert_allclose(kinematics.jacobian(q), expected, atol=1e-6)


def _log_rotation(R: np.ndarray) -> np.ndarray:
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return axis / 2 if angle < 1e-12 else angle / (2 * np.sin(angle)) * axis


def test_jacobian_matches_central_finite_differences(kinematics):
    h = 1e-6
    for q in random_configurations(5, seed=4):
        J = kinematics.jacobian(q)
        R_base_camera = kinematics.forward(q)[:3, :3]
        for i in range(7):
            step = np.zeros(7)
            step[i] = h
            plus, minus = kinematics.forward(q + step), kinematics.forward(q - step)
            v_base = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
            omega_camera = _log_rotation(minus[:3, :3].T @ plus[:3, :3]) / (2 * h)
            np.testing.assert_allclose(J[:3, i], R_base_camera.T @ v_base, atol=1e-6)
            np.testing.assert_allclose(J[3:, i], omega_camera, atol=1e-6)


# --- The joint velocity command ------------------------------------------------------------

#: Below the iiwa's singular values away from singularities (0.1-2 here).
DAMPING = svs.DampingParams(singular_value_threshold=0.05, max_damping=0.05)


def test_command_is_the_pseudo_inverse_away_from_singularities(kinematics):
    q = np.array([0.2, 0.5, -0.3, -1.4, 0.4, 1.1, 0.3])
    twist = np.array([0.02, -0.01, 0.03, 0.05, -0.02, 0.04])
    # Without the joint-limit avoidance the command is the paper's minimum-norm eq. 18.
    params = svs.VelocityCommandParams(damping=DAMPING, limit_avoidance_gain=0.0)
    command = kinematics.joint_velocities(q, twist, params)
    J = kinematics.jacobian(q)
    assert command.min_singular_value > DAMPING.singular_value_threshold
    assert command.damping == 0.0
    np.testing.assert_allclose(command.q_dot, np.linalg.pinv(J) @ twist, atol=1e-10)
    np.testing.assert_allclose(J @ command.q_dot, twist, atol=1e-10)


@pytest.mark.parametrize("offset", [0.0, 1e-6, 1e-3])
def test_command_stays_bounded_at_the_stretched_singularity(kinematics, offset):
    # q = 0: the arm stands straight up, joints 1, 3, 5, 7 on one axis (rank 4).
    q = np.full(7, offset)
    assert np.linalg.svd(kinematics.jacobian(q), compute_uv=False)[-1] < 1e-2
    rng = np.random.default_rng(5)
    params = svs.VelocityCommandParams(damping=DAMPING)
    for twist in rng.normal(size=(20, 6)) * 0.05:
        command = kinematics.joint_velocities(q, twist, params)
        assert command.velocity_scale == 1.0  # the bound below holds before any scaling
        assert command.damping > 0.0
        # With max_damping = threshold, every singular direction has gain <= 1 / threshold.
        assert np.linalg.norm(command.q_dot) <= np.linalg.norm(twist) / 0.05 + 1e-9


def test_command_respects_the_velocity_limits_keeping_the_direction(kinematics):
    q = np.array([0.2, 0.5, -0.3, -1.4, 0.4, 1.1, 0.3])
    twist = np.array([0.5, -0.3, 0.4, 1.0, -0.8, 0.6])
    params = svs.VelocityCommandParams(
        max_joint_speed=0.8, damping=DAMPING, dt=1e-3, limit_avoidance_gain=0.0
    )
    command = kinematics.joint_velocities(q, twist, params)
    unscaled = np.linalg.pinv(kinematics.jacobian(q)) @ twist
    assert np.max(np.abs(unscaled)) > 0.8
    assert np.max(np.abs(command.q_dot)) == pytest.approx(0.8, abs=1e-12)
    np.testing.assert_allclose(command.q_dot, command.velocity_scale * unscaled, atol=1e-10)


def test_command_never_crosses_a_position_limit(kinematics):
    rng = np.random.default_rng(6)
    params = svs.VelocityCommandParams(dt=0.1, position_margin=0.02, damping=DAMPING)
    upper, lower = kinematics.upper_limits, kinematics.lower_limits
    limited = 0
    for _ in range(50):
        # Every joint within 0.05 rad of one of its limits (some inside the margin).
        inset = rng.uniform(0.0, 0.05, 7)
        q = np.where(rng.random(7) < 0.5, upper - inset, lower + inset)
        twist = rng.normal(size=6) * 0.5
        command = kinematics.joint_velocities(q, twist, params)
        limited += len(command.position_limited)
        q_next = q + command.q_dot * params.dt
        # Ending beyond a margin is allowed only for a joint that was there and moves back.
        over = q_next > upper - params.position_margin + 1e-12
        under = q_next < lower + params.position_margin - 1e-12
        assert np.all(command.q_dot[over] <= 0.0) and np.all(command.q_dot[under] >= 0.0), (
            q,
            command.q_dot,
        )
        assert np.all(np.abs(command.q_dot) <= kinematics.velocity_limits + 1e-12)
    assert limited > 0  # the limits were actually exercised


# --- Joint-limit avoidance in the redundancy ------------------------------------------------


def centring_cost(kinematics, q, exponent):
    """H of VelocityCommandParams.limit_avoidance_gain: sum h^2 |x|^(p+1) / (p+1)."""
    lower, upper = kinematics.lower_limits, kinematics.upper_limits
    half = (upper - lower) / 2
    x = (np.asarray(q) - (upper + lower) / 2) / half
    return float(np.sum(half**2 * np.abs(x) ** (exponent + 1) / (exponent + 1)))


def avoiding(gain, exponent=3.0):
    # dt small: no position limit is reached; no speed cap: no scaling.
    return svs.VelocityCommandParams(
        dt=1e-3, damping=DAMPING, limit_avoidance_gain=gain, limit_avoidance_exponent=exponent
    )


def near_limits(kinematics, rng, reach):
    lower, upper = kinematics.lower_limits, kinematics.upper_limits
    return (upper + lower) / 2 + reach * rng.uniform(-1, 1, 7) * (upper - lower) / 2


def test_limit_avoidance_defaults_are_on_and_bound():
    params = svs.VelocityCommandParams()
    assert params.limit_avoidance_gain > 0 and params.limit_avoidance_exponent >= 1
    assert "limit_avoidance_gain" in repr(params)
    with pytest.raises(ValueError, match="limit_avoidance_gain"):
        svs.Kinematics(URDF, BASE, TIP).joint_velocities(np.zeros(7), np.zeros(6), avoiding(-1))


def test_limit_avoidance_leaves_the_camera_twist_unchanged(kinematics):
    rng = np.random.default_rng(21)
    for _ in range(30):
        q = near_limits(kinematics, rng, 0.95)
        twist = rng.normal(size=6) * 0.05
        J = kinematics.jacobian(q)
        for exponent in (1.0, 3.0):
            plain = kinematics.joint_velocities(q, twist, avoiding(0.0))
            avoided = kinematics.joint_velocities(q, twist, avoiding(2.0, exponent))
            if plain.damping > 0:  # near a singularity: damped, not exact (none drawn here)
                continue
            assert not avoided.position_limited and avoided.velocity_scale == 1.0
            np.testing.assert_allclose(J @ plain.q_dot, twist, atol=1e-9)
            np.testing.assert_allclose(J @ avoided.q_dot, twist, atol=1e-9)


@pytest.mark.parametrize("exponent", [1.0, 3.0])
def test_limit_avoidance_moves_joints_toward_their_middles(kinematics, exponent):
    rng = np.random.default_rng(22)
    for _ in range(30):
        q = near_limits(kinematics, rng, 0.9)
        motion = np.asarray(
            kinematics.joint_velocities(q, np.zeros(6), avoiding(1.0, exponent)).q_dot
        )
        assert np.linalg.norm(motion) > 1e-6
        h = 1e-6
        slope = (
            centring_cost(kinematics, q + h * motion, exponent)
            - centring_cost(kinematics, q - h * motion, exponent)
        ) / (2 * h)
        # dH/dt = -|N grad H|^2 k = -|motion|^2 / k with k = 1 1/s.
        assert slope < 0
        assert slope == pytest.approx(-(motion @ motion), rel=1e-5, abs=1e-9)


def test_limit_avoidance_is_zero_at_the_middles(kinematics):
    # The iiwa's ranges are symmetric: the middles are q = 0 (a singular configuration).
    middle = (kinematics.upper_limits + kinematics.lower_limits) / 2
    assert np.all(
        np.asarray(kinematics.joint_velocities(middle, np.zeros(6), avoiding(5.0)).q_dot) == 0
    )
    twist = np.array([0.02, -0.01, 0.03, 0.05, -0.02, 0.04])
    q = np.array([0.2, 0.5, -0.3, -1.4, 0.4, 1.1, 0.3])
    moved = kinematics.joint_velocities(q, twist, avoiding(5.0)).q_dot
    still = kinematics.joint_velocities(q, twist, avoiding(0.0)).q_dot
    assert np.linalg.norm(np.asarray(moved) - still) > 1e-3  # away from the middles it acts


# --- Bad input ----------------------------------------------------------------------------


def test_bad_input_raises_naming_the_argument(kinematics, tmp_path):
    with pytest.raises(FileNotFoundError, match="urdf_path"):
        svs.Kinematics(tmp_path / "missing.urdf", BASE, TIP)
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'/><joint")
    with pytest.raises(ValueError, match="urdf"):
        svs.Kinematics(broken, BASE, TIP)
    with pytest.raises(ValueError, match="base_link"):
        svs.Kinematics(URDF, "world", TIP)
    with pytest.raises(ValueError, match="tip_link"):
        svs.Kinematics(URDF, TIP, BASE)
    with pytest.raises(ValueError, match="T_tip_camera"):
        svs.Kinematics(URDF, BASE, TIP, np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="q"):
        kinematics.forward(np.zeros(6))
    with pytest.raises(ValueError, match="q"):
        kinematics.jacobian([0.0, 0.0, np.nan, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="camera_twist"):
        kinematics.joint_velocities(np.zeros(7), np.zeros(5))
    with pytest.raises(ValueError, match="dt"):
        kinematics.joint_velocities(np.zeros(7), np.zeros(6), svs.VelocityCommandParams(dt=0.0))
    with pytest.raises(ValueError, match="max_damping"):
        svs.damped_least_squares(np.eye(2), np.ones(2), svs.DampingParams(max_damping=-1.0))
