"""The PyBullet simulation: depth camera geometry against known planes and boxes, the
noise model's statistics, the two control modes, and the camera pose from KDL against
PyBullet's. Small images (160 x 120) and few steps keep it fast."""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs

pybullet = pytest.importorskip("pybullet")
from pybullet_utils.bullet_client import BulletClient  # noqa: E402
from reference_normals import organized_normals  # noqa: E402

from spectral_vs import sim  # noqa: E402

SMALL = sim.CameraIntrinsics(width=160, height=120)


def rotation(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between rows of a and the unit vector b, degrees."""
    return np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0)))


def to_world(cloud: svs.PointCloud, T_world_camera: np.ndarray) -> np.ndarray:
    return cloud.points @ T_world_camera[:3, :3].T + T_world_camera[:3, 3]


@pytest.fixture(scope="module")
def empty_table():
    """The robot above an empty table, kinematic mode, small noise-free camera."""
    params = sim.SimParams(
        scene=sim.TableSceneParams(object_count=0), camera=sim.CameraParams(intrinsics=SMALL)
    )
    with sim.PyBulletRobot(params) as robot:
        yield robot


@pytest.fixture()
def at_home(empty_table):
    empty_table.reset_joint_positions(sim.HOME_Q)
    return empty_table


@pytest.fixture(scope="module")
def bare_client():
    """A PyBullet client with nothing in it, for rendering known shapes."""
    client = BulletClient(connection_mode=pybullet.DIRECT)
    yield client
    client.disconnect()


# --- Camera geometry ---------------------------------------------------------------------


def test_table_seen_from_above_has_the_right_depth_and_normals(at_home):
    T_world_camera = at_home.camera_pose()  # PyBullet's link state: the ground truth
    cloud = at_home.capture()
    assert len(cloud) >= 0.9 * SMALL.width * SMALL.height
    height = T_world_camera[2, 3]
    assert height == pytest.approx(0.55, abs=0.005)  # HOME_Q as documented
    # Looking straight down (within 0.1 degree), the planar depth is the height.
    assert angle_deg(T_world_camera[:3, 2], np.array([0.0, 0.0, -1.0])) < 0.1
    np.testing.assert_allclose(cloud.points[:, 2], height, atol=1e-3)
    np.testing.assert_allclose(to_world(cloud, T_world_camera)[:, 2], 0.0, atol=1e-4)
    up_in_camera = T_world_camera[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    assert np.max(angle_deg(cloud.normals, up_in_camera)) < 1.0


@pytest.mark.parametrize("intrinsics", [SMALL, sim.CameraIntrinsics(161, 121, 45.0)])
def test_oblique_plane_is_reconstructed_exactly(bare_client, intrinsics):
    # A 6 m plate z = 0 seen at 40 degrees incidence from a generic pose: one pixel of
    # error in the principal point or 1% in the focal length moves points by >= 4 mm.
    shape = bare_client.createVisualShape(pybullet.GEOM_BOX, halfExtents=[3, 3, 0.001])
    plate = bare_client.createMultiBody(0, baseVisualShapeIndex=shape, basePosition=[0, 0, -0.001])
    T_world_camera = np.eye(4)
    T_world_camera[:3, :3] = rotation([1, 0.6, 0.2], 0.7) @ np.diag([1.0, -1.0, -1.0])
    T_world_camera[:3, 3] = [0.1, -0.2, 0.7]
    try:
        depth = sim.render_depth(bare_client, T_world_camera, intrinsics)
    finally:
        bare_client.removeBody(plate)
    cloud = sim.depth_to_cloud(depth, intrinsics)
    assert len(cloud) > 0.9 * intrinsics.width * intrinsics.height
    np.testing.assert_allclose(to_world(cloud, T_world_camera)[:, 2], 0.0, atol=1e-4)
    up_in_camera = T_world_camera[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    assert np.max(angle_deg(cloud.normals, up_in_camera)) < 0.1


def test_box_on_the_table_is_where_it_was_put(at_home):
    client = at_home.client
    half = np.array([0.04, 0.03, 0.025])
    center = np.array([0.62, 0.05, half[2]])
    shape = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half.tolist())
    box = client.createMultiBody(0, baseVisualShapeIndex=shape, basePosition=center.tolist())
    try:
        T_world_camera = at_home.camera_pose()
        cloud = at_home.capture()
    finally:
        client.removeBody(box)
    world = to_world(cloud, T_world_camera)
    normals_up = (cloud.normals @ T_world_camera[:3, :3].T)[:, 2]
    top = world[(world[:, 2] > 0.01) & (normals_up > 0.9)]
    assert len(top) > 100
    np.testing.assert_allclose(top[:, 2], 2 * half[2], atol=1e-4)
    assert np.all(np.abs(top[:, :2] - center[:2]) <= half[:2] + 1e-4)
    # Pixels on a regular grid: the centroid of those inside a rectangle is within half a
    # pixel spacing (4.6 mm at 160 x 120 here) of the rectangle's centre, per axis.
    spacing = (T_world_camera[2, 3] - 2 * half[2]) / SMALL.fx
    assert np.all(np.abs(top[:, :2].mean(axis=0) - center[:2]) <= 0.5 * spacing + 1e-4)


def test_depth_jumps_and_missing_pixels_give_no_normal():
    depth = np.full((SMALL.height, SMALL.width), 0.8)
    depth[:, 80:] = 0.5  # a step edge
    depth[30, 40] = np.nan
    cloud = sim.depth_to_cloud(depth, SMALL)
    points = cloud.points
    # Flat on both sides: normals exactly toward the camera (-Z).
    assert np.max(angle_deg(cloud.normals, np.array([0.0, 0.0, -1.0]))) < 1e-4
    u = np.rint(points[:, 0] / points[:, 2] * SMALL.fx + SMALL.cx).astype(int)
    v = np.rint(points[:, 1] / points[:, 2] * SMALL.fy + SMALL.cy).astype(int)
    # No point whose stencil (2 px along rows and columns) crosses the edge or the hole.
    assert not np.any((u >= 78) & (u <= 81))
    assert not np.any((v == 30) & np.isin(u, [38, 40, 42]))
    assert not np.any((u == 40) & np.isin(v, [28, 30, 32]))
    assert np.any((v == 31) & (u == 41))  # diagonal neighbours keep their normals
    np.testing.assert_allclose(points[u < 78, 2], 0.8)
    np.testing.assert_allclose(points[u > 81, 2], 0.5)


# --- Noise ---------------------------------------------------------------------------------


def test_noise_statistics_follow_the_model():
    noise = sim.DepthNoise(sigma_0=0.001, sigma_quadratic=0.002, missing_fraction=0.1, seed=3)
    depth = np.empty((400, 400))
    depth[:200] = 0.5
    depth[200:] = 2.0
    noisy = noise.apply(depth, np.random.default_rng(noise.seed))
    missing = np.isnan(noisy)
    assert missing.mean() == pytest.approx(0.1, abs=0.005)
    for rows, z in ((slice(0, 200), 0.5), (slice(200, 400), 2.0)):
        residual = (noisy[rows] - depth[rows])[~missing[rows]]
        sigma = 0.001 + 0.002 * z**2
        assert np.std(residual) == pytest.approx(sigma, rel=0.02)
        assert abs(np.mean(residual)) < 4 * sigma / np.sqrt(residual.size)


def test_capture_is_deterministic_with_a_seed():
    def captures(seed: int) -> list[np.ndarray]:
        noise = sim.DepthNoise(
            sigma_0=0.001, sigma_quadratic=0.002, missing_fraction=0.05, seed=seed
        )
        params = sim.SimParams(
            scene=sim.TableSceneParams(object_count=2, seed=4),
            camera=sim.CameraParams(intrinsics=SMALL, noise=noise),
        )
        with sim.PyBulletRobot(params) as robot:
            return [robot.capture().points.copy() for _ in range(2)]

    first, again, other = captures(7), captures(7), captures(8)
    np.testing.assert_array_equal(first[0], again[0])
    np.testing.assert_array_equal(first[1], again[1])
    assert first[0].shape != first[1].shape or not np.array_equal(first[0], first[1])
    assert first[0].shape != other[0].shape or not np.array_equal(first[0], other[0])


def test_noisy_plane_normals_stay_close(at_home):
    noise = sim.DepthNoise(sigma_0=0.0005, sigma_quadratic=0.0019, seed=1)
    depth = noise.apply(at_home.capture_depth(), np.random.default_rng(1))
    cloud = sim.depth_to_cloud(depth, SMALL, sim.NormalParams(window=5))
    up_in_camera = at_home.camera_pose()[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    assert np.median(angle_deg(cloud.normals, up_in_camera)) < 2.0


def rough_depth(rng: np.random.Generator) -> np.ndarray:
    """A 120 x 160 depth image with slopes, steps (silhouettes), noise and holes."""
    v, u = np.mgrid[0:120, 0:160]
    depth = 0.6 + 0.002 * u - 0.001 * v + 0.01 * np.sin(u / 7.0) * np.cos(v / 5.0)
    depth[30:70, 40:90] -= 0.2  # a box nearer the camera
    depth += rng.normal(0.0, 0.0005, depth.shape)
    depth[rng.random(depth.shape) < 0.02] = np.nan
    depth[:, 150:] = np.nan  # nothing seen at the right edge
    return depth


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_depth_to_cloud_is_the_numpy_reference(stride):
    # The core's cloud_from_depth against back_project + organized_normals in float64,
    # the same pixels and the same values.
    depth = rough_depth(np.random.default_rng(stride))
    params = sim.NormalParams(stride=stride)
    cloud = sim.depth_to_cloud(depth, SMALL, params)
    points = sim.back_project(depth, SMALL)
    normals = organized_normals(points, params, np.float64)
    points = points[::stride, ::stride].reshape(-1, 3)
    normals = normals[::stride, ::stride].reshape(-1, 3)
    keep = np.isfinite(normals[:, 0])
    assert keep.sum() > 0.5 * len(keep)
    assert len(cloud) == keep.sum()
    np.testing.assert_allclose(cloud.points, points[keep], rtol=0, atol=1e-12)
    np.testing.assert_allclose(cloud.normals, normals[keep], rtol=0, atol=1e-6)
    # The float32 default of the reference is within 1e-4 of it.
    single = organized_normals(sim.back_project(depth, SMALL), params)
    single = single[::stride, ::stride].reshape(-1, 3)[keep]
    np.testing.assert_allclose(cloud.normals, single, rtol=0, atol=1e-4)


def test_depth_to_cloud_refuses_a_depth_of_another_size_and_sees_nothing_as_empty():
    with pytest.raises(ValueError, match="shape"):
        sim.depth_to_cloud(np.full((20, 30), 1.0), SMALL)
    # A frame with no return at all is an empty cloud (the servo holds on it), not an error.
    nothing = np.full((SMALL.height, SMALL.width), np.nan)
    assert len(sim.depth_to_cloud(nothing, SMALL)) == 0


# --- Robot ---------------------------------------------------------------------------------


def test_robot_implements_the_robot_interface(empty_table):
    assert isinstance(empty_table, svs.RobotInterface)


def test_camera_pose_from_kinematics_equals_pybullet(empty_table):
    rng = np.random.default_rng(9)
    for _ in range(5):
        q = np.asarray(sim.HOME_Q) + rng.uniform(-0.5, 0.5, 7)
        empty_table.reset_joint_positions(q)
        np.testing.assert_allclose(empty_table.joint_positions(), q, atol=1e-12)
        np.testing.assert_allclose(
            empty_table.T_base_camera(), empty_table.camera_pose(), atol=1e-6
        )


def test_kinematic_mode_integrates_the_commanded_velocities(empty_table):
    robot = empty_table
    q0 = np.asarray(sim.HOME_Q)
    robot.reset_joint_positions(q0)
    t0 = robot.time()
    q_dot = np.array([0.1, -0.2, 0.3, 0.05, -0.1, 0.2, 5.0])  # the last saturates at 1.5
    for _ in range(10):
        robot.send_joint_velocities(q_dot, 0.05)
    expected = q0 + np.clip(q_dot, -1.5, 1.5) * 0.5
    np.testing.assert_allclose(robot.joint_positions(), expected, atol=1e-12)
    assert robot.time() - t0 == pytest.approx(0.5)
    # Driving into a limit stops at the limit.
    robot.send_joint_velocities(np.array([0, 0, 0, 0, 0, 0, 1.5]), 10.0)
    assert robot.joint_positions()[6] == pytest.approx(robot.kinematics.upper_limits[6])
    robot.stop()
    with pytest.raises(ValueError, match="q_dot"):
        robot.send_joint_velocities(np.zeros(6), 0.05)
    with pytest.raises(ValueError, match="dt"):
        robot.send_joint_velocities(np.zeros(7), 0.0)


def test_dynamic_mode_tracks_velocities_and_holds_when_stopped():
    params = sim.SimParams(mode="dynamic", scene=sim.TableSceneParams(object_count=0))
    with sim.PyBulletRobot(params) as robot:
        q0 = robot.joint_positions()
        q_dot = np.array([0.2, -0.1, 0.1, 0.2, -0.2, 0.1, 0.3])
        robot.send_joint_velocities(q_dot, 0.25)  # 60 physics steps
        assert robot.time() == pytest.approx(0.25)
        moved = robot.joint_positions() - q0
        np.testing.assert_allclose(moved, q_dot * 0.25, atol=1e-3)  # motors reach speed fast
        robot.stop()
        robot.send_joint_velocities(np.zeros(7), 0.1)
        held = robot.joint_positions()
        robot.send_joint_velocities(np.zeros(7), 0.25)
        np.testing.assert_allclose(robot.joint_positions(), held, atol=1e-3)


def test_default_scene_puts_clutter_in_view_of_the_home_pose():
    params = sim.SimParams(camera=sim.CameraParams(intrinsics=SMALL))
    with sim.PyBulletRobot(params) as robot:
        world = to_world(robot.capture(), robot.camera_pose())
        assert len(robot.objects) == 8
        on_objects = world[:, 2] > 0.005
        assert 0.05 < on_objects.mean() < 0.6
        assert np.all(world[:, 2] > -1e-3)  # only table and objects: no floor, no robot


def test_the_table_settings_are_not_the_aligners_scene_settings():
    assert not hasattr(sim, "SceneParams")  # 0.2's name of TableSceneParams, removed in 0.3
    assert sim.TableSceneParams is not svs.SceneParams  # the aligner's scene settings
