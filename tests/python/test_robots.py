"""Robots as data: the presets (iiwa, Panda), the Panda's chain and home view, the start
sets with the view check (extreme), servo-sim --robot, and one servo run of the Panda."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

pybullet = pytest.importorskip("pybullet")

from spectral_vs import (  # noqa: E402
    experiment,
    field_of_view,
    sim,
)
from spectral_vs import servo as servo_lib  # noqa: E402
from spectral_vs.sim.camera import view_matrix  # noqa: E402

SMALL = sim.CameraIntrinsics(width=160, height=120)


def errors_mm_deg(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    t, r = servo_lib.pose_error(np.linalg.inv(T_a) @ T_b)
    return 1000 * t, math.degrees(r)


@pytest.fixture(scope="module")
def panda():
    """The Panda above the default clutter, kinematic mode, small noise-free camera."""
    params = sim.SimParams(
        robot=sim.robot_model("panda"), camera=sim.CameraParams(intrinsics=SMALL)
    )
    with sim.PyBulletRobot(params) as robot:
        yield robot


# --- Presets -------------------------------------------------------------------------------


def test_unknown_preset_names_the_argument_and_the_presets():
    with pytest.raises(ValueError, match=r"name must be one of \['iiwa', 'panda'\], got 'ur5'"):
        sim.robot_model("ur5")


def test_iiwa_preset_is_the_default_and_keeps_the_old_names():
    iiwa = sim.robot_model("iiwa")
    assert sim.SimParams().robot.name == "iiwa"
    assert (iiwa.base_link, iiwa.tip_link) == (sim.BASE_LINK, sim.TIP_LINK)
    assert iiwa.urdf_path == sim.iiwa_urdf_path()
    assert iiwa.home_q == sim.HOME_Q == sim.SimParams().q_start
    np.testing.assert_array_equal(iiwa.T_tip_camera, sim.default_T_tip_camera())
    np.testing.assert_array_equal(sim.SimParams().T_tip_camera, sim.default_T_tip_camera())
    # An explicit q_start and camera mount still win over the robot's.
    params = sim.SimParams(q_start=(0.0,) * 7, T_tip_camera=np.eye(4))
    assert params.q_start == (0.0,) * 7 and np.array_equal(params.T_tip_camera, np.eye(4))
    with pytest.raises(ValueError, match="T_tip_camera"):
        sim.RobotModel("bad", iiwa.urdf_path, "a", "b", (0.0,), T_tip_camera=2 * np.eye(4))
    with pytest.raises(ValueError, match="home_q"):
        sim.RobotModel("bad", iiwa.urdf_path, "a", "b", (math.nan,))


def test_panda_loads_with_the_arm_joints_only_and_open_fingers(panda):
    k = panda.kinematics
    assert k.joint_names == [f"panda_joint{i}" for i in range(1, 8)]
    assert (k.base_link, k.tip_link) == ("panda_link0", "panda_hand")
    np.testing.assert_allclose(panda.joint_positions(), sim.PANDA_HOME_Q, atol=1e-12)
    fingers = [panda.client.getJointState(panda.robot_id, j)[0] for j in (9, 10)]
    assert fingers == pytest.approx([0.04, 0.04], abs=1e-9)
    # Every home joint is at least 1.3 rad inside the Panda's soft limits (joint 4 in
    # [-3.07, -0.07], joint 6 in [-0.02, 3.75]).
    soft_lower = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    soft_upper = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    home = np.asarray(sim.PANDA_HOME_Q)
    assert np.all(home - soft_lower > 1.3) and np.all(soft_upper - home > 1.3)


def test_panda_fingers_stay_open_while_the_arm_moves_in_dynamic_mode():
    params = sim.SimParams(
        mode="dynamic", robot=sim.robot_model("panda"), scene=sim.TableSceneParams(object_count=0)
    )
    with sim.PyBulletRobot(params) as robot:
        q0 = robot.joint_positions()
        q_dot = np.array([0.2, -0.1, 0.1, 0.2, -0.2, 0.1, 0.3])
        robot.send_joint_velocities(q_dot, 0.25)
        np.testing.assert_allclose(robot.joint_positions() - q0, q_dot * 0.25, atol=2e-3)
        fingers = [robot.client.getJointState(robot.robot_id, j)[0] for j in (9, 10)]
        assert fingers == pytest.approx([0.04, 0.04], abs=1e-3)  # within 1 mm


def test_panda_camera_from_kdl_equals_pybullet(panda):
    rng = np.random.default_rng(3)
    home = np.asarray(sim.PANDA_HOME_Q)
    try:
        for q in [home, *(home + rng.uniform(-0.6, 0.6, 7) for _ in range(4))]:
            panda.reset_joint_positions(q)
            t_mm, r_deg = errors_mm_deg(panda.T_base_camera(), panda.camera_pose())
            assert t_mm < 1e-3 and math.radians(r_deg) < 1e-6  # 1e-6 m, 1e-6 rad
    finally:
        panda.reset_joint_positions(home)


def test_panda_home_camera_looks_straight_down_at_the_clutter(panda):
    """At home the camera is 0.55 m above (0.6, 0, 0) m on the table top, its optical axis
    within 1 degree of straight down: the pose of the iiwa's camera at its home. It sees
    all the clutter and no part of the robot (segmentation and depth)."""
    T = panda.camera_pose()
    down = math.degrees(math.acos(np.clip(-T[2, 2], -1.0, 1.0)))
    assert down < 1.0
    np.testing.assert_allclose(T[:3, 3], [0.6, 0.0, 0.55], atol=1e-3)
    with sim.PyBulletRobot(sim.SimParams(scene=sim.TableSceneParams(object_count=0))) as iiwa:
        t_mm, r_deg = errors_mm_deg(iiwa.camera_pose(), T)
    assert t_mm < 0.1 and r_deg < 0.01

    w, h = SMALL.width, SMALL.height
    image = panda.client.getCameraImage(
        w,
        h,
        viewMatrix=view_matrix(T),
        projectionMatrix=panda.client.computeProjectionMatrixFOV(
            SMALL.vertical_fov_deg, w / h, SMALL.near, SMALL.far
        ),
        renderer=pybullet.ER_TINY_RENDERER,
    )
    body = np.reshape(image[4], (h, w)) & ((1 << 24) - 1)
    assert not np.any(body == panda.robot_id)
    seen = {o.body_id for o in panda.objects} & set(np.unique(body).tolist())
    assert len(seen) == len(panda.objects) == 8  # all the clutter in view
    depth = panda.capture_depth()
    assert np.all(np.isfinite(depth))
    assert 0.44 < np.min(depth) and np.max(depth) == pytest.approx(0.55, abs=2e-3)


# --- Start sets ----------------------------------------------------------------------------


def test_moderate_and_large_starts_are_unchanged():
    """The first starts of seed 0 as they were before the extreme set and the start check
    were added (iiwa, measured at commit b966e7a)."""
    with sim.PyBulletRobot(sim.SimParams(scene=sim.TableSceneParams(object_count=0))) as robot:
        moderate = experiment.start_poses(robot.kinematics, "moderate", 2)
        large = experiment.start_poses(robot.kinematics, "large", 2, q_reference=sim.HOME_Q)
    got = [(1000 * t, math.degrees(r)) for _, t, r in (*moderate, *large)]
    expected = [(140.885, 26.557), (169.032, 20.742), (443.345, 30.424), (286.273, 47.851)]
    np.testing.assert_allclose(got, expected, atol=1e-3)


def test_view_share_counts_points_in_front_and_inside_the_image():
    K = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
    points = np.array(
        [
            [0.0, 0.0, 1.0],  # centre
            [0.49, 0.0, 1.0],  # u = 99: last column
            [0.5, 0.0, 1.0],  # u = 100: one column beyond
            [0.0, 0.0, -1.0],  # behind the camera
            [0.0, 0.0, 5.0],  # beyond far
        ]
    )
    share = field_of_view.view_share(points, np.eye(4), K, (100, 80), depth_range=(0.1, 3.0))
    assert share == pytest.approx(2 / 5)
    turned = np.diag([1.0, -1.0, -1.0, 1.0])  # half a turn about x: only the one behind
    assert field_of_view.view_share(points, turned, K, (100, 80)) == pytest.approx(1 / 5)


def test_view_check_rejects_a_camera_under_the_table_and_a_lost_view():
    """A free camera (forward(q) translates by q[:3] then turns by q[3] about x) over a
    4 x 4 cm patch of the table seen from 0.55 m."""

    class FreeCamera:
        def forward(self, q):
            c, s = math.cos(q[3]), math.sin(q[3])
            T = np.eye(4)
            T[:3, :3] = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]]) @ np.array(
                [[1, 0, 0], [0, c, -s], [0, s, c]]
            )
            T[:3, 3] = q[:3]
            return T

    u, v = np.meshgrid(np.linspace(-0.02, 0.02, 21), np.linspace(-0.02, 0.02, 21))
    reference = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, 0.55)])
    K = np.array([[200.0, 0.0, 160.0], [0.0, 200.0, 120.0], [0.0, 0.0, 1.0]])
    home = np.array([0.6, 0.0, 0.55, 0.0])
    check = field_of_view.ViewCheck(FreeCamera(), home, reference, K, (320, 240), min_share=0.3)
    assert check.share(home) == pytest.approx(1.0) and check(home)
    low = np.array([0.6, 0.0, 0.04, 0.0])
    assert check.share(low) == pytest.approx(1.0)  # the whole patch in view ...
    assert not check(low)  # ... but the camera under 5 cm above the table
    assert check(np.array([0.6, 0.0, 0.06, 0.0]))  # just above it
    turned = np.array([0.6, 0.0, 0.55, math.radians(40)])
    assert check.share(turned) < 0.3 and not check(turned)
    with pytest.raises(ValueError, match="min_share"):
        field_of_view.ViewCheck(FreeCamera(), home, reference, K, (320, 240), min_share=0.0)


def _share_from_pybullet(robot, reference_world: np.ndarray) -> float:
    """Share of world points inside the current camera image, from PyBullet's link state."""
    T = np.linalg.inv(robot.camera_pose())
    p = reference_world @ T[:3, :3].T + T[:3, 3]
    intr = robot.params.camera.intrinsics
    z = p[:, 2]
    front = (z > intr.near) & (z < intr.far)
    z = np.where(front, z, 1.0)
    u = intr.fx * p[:, 0] / z + intr.cx
    v = intr.fy * p[:, 1] / z + intr.cy
    inside = (u >= -0.5) & (u < intr.width - 0.5) & (v >= -0.5) & (v < intr.height - 0.5)
    return float(np.mean(front & inside))


@pytest.mark.parametrize("name", ["iiwa", "panda"])
def test_extreme_starts_are_in_range_and_keep_the_reference_in_view(name):
    params = sim.SimParams(
        robot=sim.robot_model(name),
        scene=sim.TableSceneParams(object_count=0),
        camera=sim.CameraParams(intrinsics=SMALL),
    )
    with sim.PyBulletRobot(params) as robot:
        home = params.robot.home_q
        with pytest.raises(ValueError, match="accept must be given"):
            experiment.start_poses(robot.kinematics, "extreme", 1, q_reference=home)
        check = robot.view_check()
        four = experiment.start_poses(robot.kinematics, "extreme", 4, 5, home, accept=check)
        two = experiment.start_poses(robot.kinematics, "extreme", 2, 5, home, accept=check)
        # The reference in the world: the home depth image through PyBullet's camera pose.
        robot.reset_joint_positions(home)
        T_home = robot.camera_pose()
        points = sim.back_project(robot.capture_depth(), SMALL).reshape(-1, 3)
        reference_world = points @ T_home[:3, :3].T + T_home[:3, 3]
        for q, t, r in four:
            robot.reset_joint_positions(q)
            t_mm, r_deg = errors_mm_deg(robot.camera_pose(), T_home)
            assert t_mm == pytest.approx(1000 * t, abs=1e-3)
            assert r_deg == pytest.approx(math.degrees(r), abs=1e-4)
            assert t_mm < 600 and r_deg < 90 and (t_mm >= 450 or r_deg >= 60)
            assert robot.camera_pose()[2, 3] >= 0.05  # above the table top
            assert _share_from_pybullet(robot, reference_world) >= 0.3
    for (q4, t4, _), (q2, t2, _) in zip(four[:2], two, strict=True):
        assert np.array_equal(q4, q2) and t4 == t2


# --- Command line and servo ----------------------------------------------------------------


def test_cli_choices_are_the_presets_and_the_sets():
    from spectral_vs.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    servo = commands.choices["servo-sim"]
    choices = {a.dest: a.choices for a in servo._actions if a.choices}
    assert choices["robot"] == sorted(sim.ROBOT_MODELS)
    assert choices["set"] == list(experiment.START_SETS)


def test_servo_sim_runs_the_panda_and_names_it(capfd, tmp_path):
    from spectral_vs.cli import main

    argv = ["servo-sim", "--robot", "panda", "--starts", "1", "--max-steps", "2"]
    code = main([*argv, "--json", "--no-figures", "--out", str(tmp_path)])
    summary = json.loads(capfd.readouterr().out)
    assert code == 1  # two steps do not converge
    assert summary["robot"] == "panda" and summary["set"] == "moderate"
    with sim.PyBulletRobot(
        sim.SimParams(robot=sim.robot_model("panda"), scene=sim.TableSceneParams(object_count=0))
    ) as robot:
        ((_, t, r),) = experiment.start_poses(
            robot.kinematics, "moderate", 1, q_reference=sim.PANDA_HOME_Q
        )
    (run,) = summary["starts"]
    assert run["start_mm"] == pytest.approx(1000 * t, abs=1e-6)
    assert run["start_deg"] == pytest.approx(math.degrees(r), abs=1e-6)
    assert run["steps"] == 2 and run["reason"] == "max_steps" and not run["success"]
    assert set(run) >= {"start_mm", "start_deg", "final_mm", "final_deg", "steps", "reason"}


def test_panda_servo_reaches_the_reference_from_a_moderate_start():
    """The first moderate start of seed 0 (116 mm and 23.6 degrees from home), default
    ServoParams and camera: back within 5 mm and 1 degree (PyBullet's ground truth)."""
    params = sim.SimParams(robot=sim.robot_model("panda"))
    with sim.PyBulletRobot(params) as robot:
        reference = robot.capture()
        T_world_reference = robot.camera_pose()
        ((q, t, _),) = experiment.start_poses(
            robot.kinematics, "moderate", 1, q_reference=sim.PANDA_HOME_Q
        )
        robot.reset_joint_positions(q)
        assert 1000 * t > 100
        servo = servo_lib.SpectralServo(reference, servo_lib.ServoParams())
        log = servo_lib.run_servo(robot, robot.kinematics, servo, dt=0.1, max_steps=150)
        t_mm, r_deg = errors_mm_deg(robot.camera_pose(), T_world_reference)
    assert log.converged, log.status
    assert t_mm < 5.0 and r_deg < 1.0
