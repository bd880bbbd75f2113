"""Safe stops of the servo loop that tests/python/test_servo.py leaves out: the target
leaving the field of view after the robot has moved, and a cloud with a sensor's invalid
(NaN) points. The fake robot and the synthetic scene are those of test_servo.py."""

from __future__ import annotations

import numpy as np
import pytest
import test_servo
from test_servo import FreeCamera, FreeCameraKinematics, camera_pose, view

from spectral_vs.servo import ServoParams, SpectralServo, run_servo

# The fixtures of test_servo.py: its table top and the desired camera above it.
scene = test_servo.scene
desired = test_servo.desired


def test_target_leaving_the_view_mid_run_stops_the_robot(scene, desired):
    """After three commands the camera sees nothing: the fourth step sends no command,
    the robot is stopped once, and the log names the reason."""
    robot = FreeCamera(scene, camera_pose((0.04, -0.03, 0.02), (2.0, 1.0, 3.0)), empty_at=3)
    log = run_servo(robot, FreeCameraKinematics(), SpectralServo(view(scene, desired)), dt=0.1)
    assert log.reason == "empty_cloud" and log.status.state == "stopped"
    assert len(robot.sent) == 3 and robot.stops == 1
    assert np.all(log.records[-1].twist == 0)


def test_target_partly_out_of_view_stops_below_min_points(scene, desired):
    """A view that keeps only a corner of the scene (the rest outside the image) has fewer
    points than min_points: stopped with a zero twist, not a guess from a fragment."""
    full = view(scene, desired)
    corner = np.asarray(full.points)
    corner = corner[(corner[:, 0] > 0.25) & (corner[:, 1] > 0.2)]
    servo = SpectralServo(full, ServoParams(min_points=500))
    twist, status = servo.step(corner)
    assert len(corner) < 500
    assert status.state == "stopped" and status.reason == "too_few_points"
    assert np.all(twist == 0)


def test_a_cloud_with_nan_points_stops_the_robot_with_an_error(scene, desired):
    """The servo takes finite points only: a cloud with a sensor's NaN holes raises
    ValueError, and run_servo stops the robot before passing it on."""
    robot = FreeCamera(scene, camera_pose((0.02, 0.0, 0.0)))
    finite = robot.capture

    def with_holes():
        points = np.array(finite().points)
        points[::50] = np.nan
        return points

    robot.capture = with_holes  # type: ignore[method-assign]
    with pytest.raises(ValueError, match="not finite"):
        run_servo(robot, FreeCameraKinematics(), SpectralServo(view(scene, desired)), dt=0.1)
    assert robot.sent == [] and robot.stops == 1
