"""Safe stops of the servo loop that tests/python/test_servo.py leaves out: the target
leaving the field of view after the robot has moved, a cloud with a sensor's invalid (NaN)
points, and the holds on sensor faults (too few points, a repeated frame, an occluder)
with their stop after ServoParams.max_outage. The fake robot and the synthetic scene are
those of test_servo.py; the faults in the simulation are in test_sensor_faults.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
import test_servo
from test_servo import FreeCamera, FreeCameraKinematics, camera_pose, errors_mm_deg, view

from spectral_vs.sensor_faults import frame_fingerprint, near_occluders
from spectral_vs.servo import ServoParams, SpectralServo, run_servo

# The fixtures of test_servo.py: its table top and the desired camera above it.
scene = test_servo.scene
desired = test_servo.desired


def test_target_leaving_the_view_mid_run_stops_the_robot(scene, desired):
    """After three commands the camera sees nothing (for good): from the fourth step on
    only zero velocities are sent, and once the last frame is more than max_outage (0.5 s)
    old the robot is stopped once, with the reason in the log."""
    robot = FreeCamera(scene, camera_pose((0.04, -0.03, 0.02), (2.0, 1.0, 3.0)), empty_at=3)
    log = run_servo(robot, FreeCameraKinematics(), SpectralServo(view(scene, desired)), dt=0.1)
    assert log.reason == "sensor_outage" and log.status.state == "stopped"
    # Frames at 0, 0.1, 0.2 s; empty from 0.3 s; at 0.8 s the last frame is 0.6 s old.
    assert len(log.records) == 9 and len(robot.sent) == 8 and robot.stops == 1
    assert all(q_dot.any() for q_dot in robot.sent[:3])
    assert all(not q_dot.any() for q_dot in robot.sent[3:])
    assert [record.hold for record in log.records[3:]] == ["empty_cloud"] * 6
    assert np.all(log.records[-1].twist == 0) and np.all(log.records[-1].q_dot == 0)


def test_target_partly_out_of_view_holds_below_min_points(scene, desired):
    """A view that keeps only a corner of the scene (the rest outside the image) has fewer
    points than min_points: held with a zero twist, not a guess from a fragment; and
    stopped once the fault outlasts max_outage."""
    full = view(scene, desired)
    corner = np.asarray(full.points)
    corner = corner[(corner[:, 0] > 0.25) & (corner[:, 1] > 0.2)]
    servo = SpectralServo(full, ServoParams(min_points=500))
    twist, status, record = servo.step_record(corner, now=0.0)
    assert len(corner) < 500
    assert status.state == "running" and record.hold == "too_few_points"
    assert np.all(twist == 0)
    twist, status = servo.step(corner, now=0.51)
    assert status.state == "stopped" and status.reason == "sensor_outage"
    assert np.all(twist == 0)


def test_a_cloud_with_nan_points_is_servoed_on_its_finite_points(scene, desired):
    """A sensor's NaN holes (every 50th row of an (N, 6) capture, points and normals) are
    dropped at each step, never raised on: the servo converges 20 mm back."""
    robot = FreeCamera(scene, camera_pose((0.02, 0.0, 0.0)))
    finite = robot.capture

    def with_holes():
        cloud = finite()
        rows = np.hstack([np.asarray(cloud.points), np.asarray(cloud.normals)])
        rows[::50] = np.nan
        return rows

    robot.capture = with_holes  # type: ignore[method-assign]
    log = run_servo(robot, FreeCameraKinematics(), SpectralServo(view(scene, desired)), dt=0.1)
    assert log.converged, log.status
    assert all(record.points < len(finite()) for record in log.records)
    assert robot.stops == 1


# --- Holds on sensor faults ------------------------------------------------------------


def moved_by(t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A camera motion T_previous_current: a translation t, m."""
    T = np.eye(4)
    T[:3, 3] = t
    return T


def test_fault_settings_are_checked():
    with pytest.raises(ValueError, match="max_outage must be finite and >= 0 s"):
        ServoParams(max_outage=-0.1)
    with pytest.raises(ValueError, match="max_outage"):
        ServoParams(max_outage=float("inf"))
    with pytest.raises(ValueError, match="occlusion_margin must be >= 0 m"):
        ServoParams(occlusion_margin=-0.01)  # 0: derived from the reference
    with pytest.raises(ValueError, match=r"occlusion_min_share must be in \[0, 1\]"):
        ServoParams(occlusion_min_share=1.5)


def test_a_repeated_frame_is_stale_once_the_camera_has_moved(scene, desired):
    """The same frame after the camera moved 5 mm is held as stale and leaves the previous
    estimate alone; the same frame with the camera still is a fair frame (a still camera in
    a noise-free simulation sees it), and so is a new one."""
    pose = camera_pose((0.03, -0.02, 0.01), (1.0, -1.0, 2.0))
    frame = view(scene, pose)
    servo = SpectralServo(view(scene, desired))
    first = servo.step_record(frame, now=0.0)[2]
    assert first.hold == "" and first.twist.any()
    estimate = servo.previous_estimate
    twist, status, record = servo.step_record(frame, moved_by((0.005, 0, 0)), now=0.1)
    assert record.hold == "stale_frame" and status.state == "running"
    assert "5.00 mm" in status.message and not twist.any()
    assert np.array_equal(servo.previous_estimate, estimate)
    # The camera has not moved since the frame was stale: still stale (it moved since the
    # frame came first).
    assert servo.step_record(frame, np.eye(4), now=0.2)[2].hold == "stale_frame"
    # A new frame, then the same frame with the camera still: both are used.
    fresh = view(scene, pose @ moved_by((0.005, 0, 0)))
    assert servo.step_record(fresh, np.eye(4), now=0.3)[2].hold == ""
    assert servo.step_record(fresh, np.eye(4), now=0.4)[2].hold == ""


def test_a_capture_stamp_that_does_not_advance_is_stale(scene, desired):
    servo = SpectralServo(view(scene, desired))
    frame = view(scene, camera_pose((0.02, 0.0, 0.0)))
    assert servo.step_record(frame, now=0.0, stamp=5.0)[2].hold == ""
    record = servo.step_record(view(scene, camera_pose((0.021, 0, 0))), now=0.1, stamp=5.0)[2]
    assert record.hold == "stale_frame" and "not after the last" in record.status.message
    assert servo.step_record(frame, now=0.2, stamp=5.1)[2].hold == ""


def test_a_held_step_never_converges_and_the_outage_restarts_after_a_frame(scene, desired):
    """At the goal the servo converges; a dropped frame there holds (running, not
    converged); a frame resets the outage, so faults 0.8 s apart never add up to more than 0.4 s."""
    goal = view(scene, desired)
    servo = SpectralServo(goal, ServoParams(max_outage=0.5))
    assert servo.step(goal, now=0.0)[1].state == "converged"
    empty = np.zeros((0, 3))
    for now in (0.4, 1.2):
        _, status, record = servo.step_record(empty, now=now)
        assert status.state == "running" and record.hold == "empty_cloud"
        assert record.outage == pytest.approx(0.4)
        assert servo.step(goal, now=now + 0.4)[1].state == "converged"


def test_motion_during_held_steps_is_carried_to_the_watchdog(scene, desired):
    """The camera moves 80 mm in two steps that are held (dropped frames): the next
    estimate is compared with the last accepted one carried along both motions, so it is
    no jump (100 mm limit), although the camera moved 80 mm since the last step that
    registered and the next step's own motion is zero."""
    start = camera_pose((0.03, -0.02, 0.01))
    servo = SpectralServo(view(scene, desired), ServoParams(jump_limit_translation=0.05))
    for _ in range(3):
        assert servo.step_record(view(scene, start), np.eye(4), now=0.0)[2].hold == ""
    step = moved_by((0.04, 0.0, 0.0))
    for now in (0.1, 0.2):
        assert servo.step_record(np.zeros((0, 3)), step, now=now)[2].hold == "empty_cloud"
    later = start @ step @ step
    twist, status, record = servo.step_record(view(scene, later), np.eye(4), now=0.3)
    assert status.state == "running" and record.hold == "" and twist.any(), status
    t_mm = 1000 * np.linalg.norm(record.T_current_desired[:3, 3])
    true_mm = 1000 * np.linalg.norm((np.linalg.inv(later) @ desired)[:3, 3])
    assert abs(t_mm - true_mm) < 2.0
    # Without the held steps' motion the same estimate is a jump.
    blind = SpectralServo(view(scene, desired), ServoParams(jump_limit_translation=0.05))
    for _ in range(3):
        blind.step_record(view(scene, start), np.eye(4), now=0.0)
    assert blind.step_record(view(scene, later), np.eye(4), now=0.3)[1].reason == "jump"


def plate(depth: float, half: float, spacing: float = 0.004) -> np.ndarray:
    """A square plate facing the camera at ``depth`` on its optical axis (camera frame)."""
    u = np.arange(-half, half, spacing)
    x, y = np.meshgrid(u, u)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, depth)])


def with_occluder(cloud, occluder: np.ndarray) -> np.ndarray:
    """The points of ``cloud`` behind ``occluder`` (same rays) removed, the occluder added:
    (N, 6) points and normals (the occluder's facing the camera)."""
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    tangent = occluder[:, :2] / occluder[:, 2:]
    low, high = tangent.min(axis=0), tangent.max(axis=0)
    ray = points[:, :2] / points[:, 2:]
    hidden = np.all((ray >= low) & (ray <= high), axis=1)
    facing = np.tile([0.0, 0.0, -1.0], (len(occluder), 1))
    return np.vstack(
        [np.hstack([points[~hidden], normals[~hidden]]), np.hstack([occluder, facing])]
    )


def test_an_occluder_is_dropped_and_ridden_or_held(scene, desired):
    """Locked on, a 10 cm plate 0.2 m in front of the camera (nearer than the boxes' tops
    by 0.19 m) is dropped before the registration: the servo moves on the rest. A plate
    that leaves fewer than min_points behind it holds ("occluded") and changes nothing;
    the next clean frame is no jump."""
    pose = camera_pose((0.03, -0.02, 0.01), (1.0, -1.0, 2.0))
    servo = SpectralServo(view(scene, desired))
    clean = servo.step_record(view(scene, pose), np.eye(4), now=0.0)[2]
    assert clean.occluded_points == 0 and clean.fitness > 0.9
    hand = plate(0.2, 0.05)
    twist, status, record = servo.step_record(
        with_occluder(view(scene, pose), hand), np.eye(4), now=0.1
    )
    assert record.occluded_points == len(hand) and record.hold == "" and twist.any()
    # It covers (0.5 / 1.2) of the table's tangents across, 0.21 of them; measured 0.15:
    # its returns are 6 times sparser than the table's, so its edge bins count for less.
    assert 0.12 < record.hidden_share < 0.25
    # The registration of the rest, next to the clean one (measured 1.8 mm, 0.8 degree).
    t_mm, r_deg = errors_mm_deg(record.T_current_desired, clean.T_current_desired)
    assert t_mm < 3.0 and r_deg < 1.5
    estimate = servo.previous_estimate
    wall = plate(0.2, 0.2)
    twist, status, record = servo.step_record(
        with_occluder(view(scene, pose), wall), np.eye(4), now=0.2
    )
    assert record.hold == "occluded" and "min_points" in status.message and not twist.any()
    assert np.array_equal(servo.previous_estimate, estimate)
    record = servo.step_record(view(scene, pose), np.eye(4), now=0.3)[2]
    assert record.hold == "" and record.status.state == "running"
    # Before any estimate (the first step) the plate is found without one: nearer to the
    # camera than the table and higher above it than the reference's tallest box.
    fresh = SpectralServo(view(scene, desired))
    first = fresh.step_record(with_occluder(view(scene, pose), hand), now=0.0)[2]
    assert first.occluded_points == len(hand)


def test_near_points_that_hide_none_of_the_reference_are_no_occluder(scene, desired):
    """Points nearer than the reference could be but on none of its rays (a plate 0.2 m
    away, off to the side) are dropped, and they are no occluder: a jump beyond the
    watchdog's bound beside them stops the servo ("jump"), as it does without them, where
    an occluder would hold it ("occluded", a frame the occluder may have spoiled)."""
    params = ServoParams(jump_limit_translation=0.05)
    pose = camera_pose((0.03, -0.02, 0.01), (1.0, -1.0, 2.0))
    servo = SpectralServo(view(scene, desired), params)
    assert servo.step_record(view(scene, pose), np.eye(4), now=0.0)[2].fitness > 0.9
    side = plate(0.2, 0.05, spacing=0.002) + np.array([0.3, 0.0, 0.0])  # rays at x/z 1.25-1.75
    moved = camera_pose((0.13, -0.02, 0.01), (1.0, -1.0, 2.0))  # 100 mm on, not measured
    _, status, record = servo.step_record(
        with_occluder(view(scene, moved), side), np.eye(4), now=0.1
    )
    assert record.occluded_points == len(side) and record.hidden_share == 0.0
    assert status.reason == "jump" and record.hold == "", status


def test_run_servo_passes_the_capture_stamp_on(scene, desired):
    """A driver whose stamp stops advancing after the third capture: the loop holds from
    then on and stops after max_outage."""

    class FrozenDriver(FreeCamera):
        def capture_stamp(self) -> float:
            return float(min(self.captures, 3))

    robot = FrozenDriver(scene, camera_pose((0.04, -0.03, 0.02)))
    log = run_servo(robot, FreeCameraKinematics(), SpectralServo(view(scene, desired)), dt=0.1)
    assert log.reason == "sensor_outage"
    assert [record.hold for record in log.records[:3]] == ["", "", ""]
    assert {record.hold for record in log.records[3:]} == {"stale_frame"}


def test_near_occluders_and_the_fingerprint():
    """A plate 0.3 m in front of a wall at 0.6 m seen through a reference moved 10 mm
    toward the camera: exactly the plate is an occluder, hiding the share of the wall
    behind it; a fingerprint changes with any point."""
    wall = plate(0.6, 0.3, 0.01)
    hand = plate(0.3, 0.05, 0.005)
    T = moved_by((0.0, 0.0, -0.01))
    # What a depth camera sees: the wall where the plate does not hide it, and the plate.
    seen = np.abs(wall[:, :2] / wall[:, 2:]).max(axis=1) > 0.05 / 0.3
    current = np.vstack([wall[seen], hand])
    occluders, hidden = near_occluders(current, wall, T, margin=0.05)
    assert np.array_equal(
        occluders, np.r_[np.zeros(int(seen.sum()), bool), np.ones(len(hand), bool)]
    )
    # The plate covers tangents within 0.05 / 0.3 of the axis, the wall within 0.3 / 0.61:
    # (0.167 / 0.49)^2 = 0.115 of the wall; measured 0.111 in 2.9-degree bins.
    assert 0.09 < hidden < 0.14
    assert not near_occluders(wall, wall, T, margin=0.05)[0].any()
    # Stray returns: 1% of the wall's points at random depths nearer than it are
    # occluders, but each is one among many returns along its rays: they hide nothing.
    rng = np.random.default_rng(0)
    speckle = wall.copy()
    stray = rng.random(len(wall)) < 0.01
    speckle[stray] *= rng.uniform(0.2, 0.8, (int(stray.sum()), 1))
    occluders, hidden = near_occluders(speckle, wall, T, margin=0.05)
    assert occluders.sum() == stray.sum() and hidden == 0.0
    with pytest.raises(ValueError, match="margin must be > 0 m"):
        near_occluders(current, wall, T, margin=0.0)
    assert frame_fingerprint(current) == frame_fingerprint(current.copy())
    nudged = current.copy()
    nudged[123, 0] += 1e-9
    assert frame_fingerprint(nudged) != frame_fingerprint(current)


def test_a_view_emptied_by_what_stands_above_the_scene_holds_and_never_raises(scene, desired):
    """Before an estimate, the points above the scene's plane are dropped: when they are the
    whole view (a large start of seed 201 on the iiwa, whose first-found plane left nothing,
    raised ValueError in the relocalization), the step holds as occluded and the servo
    stops with sensor_outage past max_outage, raising nothing."""
    servo = SpectralServo(view(scene, desired))
    assert servo.params.relocalize

    def everything_above(cloud, record, odometry):
        record.occluded_points = len(cloud)
        return cloud.select(np.zeros(len(cloud), dtype=bool))

    servo._relocalizer.recovery.drop_above_the_scene = everything_above  # type: ignore[method-assign]
    current = view(scene, camera_pose((0.03, 0.02, -0.02), (-2.0, 3.0, -4.0)))
    for k in range(7):
        twist, status, record = servo.step_record(current, np.eye(4), now=0.1 * k)
        assert record.hold == "occluded" and not twist.any()
        assert "0 points remain" in status.message
    assert status.state == "stopped" and status.reason == "sensor_outage"


@pytest.mark.parametrize(("icp", "converges"), [(False, False), (True, True)])
def test_an_occluded_estimate_converges_only_when_the_icp_refined_it(icp, converges):
    """The stop rule: an estimate at the goal (0.3 mm, 0.02 degree) with an occluder hiding
    30% of the reference converges only when it ends with the tracking ICP, whose pairs lie
    where both views see the scene; Algorithm 1's alone is biased by the hole."""
    from spectral_vs.servo.records import _empty_record
    from spectral_vs.servo.stop import StopRule

    record = _empty_record(0, 50_000)
    record.translation_error, record.rotation_error = 0.0003, math.radians(0.02)
    record.visible_fitness, record.hidden_share, record.icp = 1.0, 0.3, icp
    assert StopRule(ServoParams()).settled(record) is converges
    record.hidden_share = 0.0
    assert StopRule(ServoParams()).settled(record)  # a clear view converges either way
