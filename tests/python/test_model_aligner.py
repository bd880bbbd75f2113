"""ModelAligner, the reference prepared once for many scenes: the same results as the plain
alignment on a sequence of servo views, and the servo's estimate made with it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_servo import camera_pose, table_top, view

import spectral_vs as svs
from spectral_vs import _core
from spectral_vs.registration import prepare
from spectral_vs.servo import ServoParams, SpectralServo, pose_error


def prepared(cloud: svs.PointCloud) -> svs.PointCloud:
    return prepare(cloud, "cloud", 0.015, True, (0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def views():
    scene = table_top()
    reference = prepared(view(scene, camera_pose()))
    currents = [
        prepared(view(scene, camera_pose(t, r)))
        for t, r in [
            ((0.03, -0.02, 0.01), (2.0, -1.0, 3.0)),
            ((0.031, -0.021, 0.01), (2.0, -1.0, 3.1)),  # next to the previous view
            ((-0.08, 0.05, 0.04), (-5.0, 4.0, -8.0)),
            ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
        ]
    ]
    return reference, currents


def assert_same(a: svs.AlignResult, b: svs.AlignResult) -> None:
    np.testing.assert_allclose(np.asarray(a.T_scene_model), np.asarray(b.T_scene_model), atol=1e-9)
    assert a.fitness == pytest.approx(b.fitness, abs=1e-12)
    assert a.iterations == b.iterations
    assert a.converged == b.converged
    assert len(a.history) == len(b.history)
    for x, y in zip(a.history, b.history, strict=True):
        assert x.translation_cost == pytest.approx(y.translation_cost, abs=1e-9)
        assert x.rotation_cost == pytest.approx(y.rotation_cost, abs=1e-12)


@pytest.mark.parametrize("mode", ["iteration", "pose"])
def test_model_aligner_matches_plain_alignment_view_after_view(views, mode):
    reference, currents = views
    params = ServoParams(mode=mode).align_params()
    aligner = _core.ModelAligner(reference, params)
    for current in currents:
        assert_same(aligner.align(current), _core._align(reference, current, params))
        timings = aligner.last_timings
        parts = (
            timings.scene_coefficients,
            timings.scene_map,
            timings.translation_grid,
            timings.rotation,
            timings.translation,
            timings.records,
            timings.fitness,
        )
        assert all(part >= 0.0 for part in parts)
        assert sum(parts) <= timings.total + 1e-6


def test_model_aligner_initial_guess_and_properties(views):
    reference, currents = views
    params = ServoParams().align_params()
    aligner = _core.ModelAligner(reference, params)
    guess = np.linalg.inv(camera_pose((0.03, -0.02, 0.01), (2.0, -1.0, 3.0))) @ camera_pose()
    params.initial_guess = guess
    assert_same(aligner.align(currents[0], guess), _core._align(reference, currents[0], params))
    assert len(aligner.model) == len(reference)
    assert aligner.params.voxel_size == pytest.approx(0.015)
    np.testing.assert_allclose(
        aligner.model_coefficients, svs.egi_coefficients(reference, 8), atol=1e-12
    )
    assert "ModelAligner" in repr(aligner)
    with pytest.raises(ValueError, match="initial_guess"):
        aligner.align(currents[0], np.zeros((4, 4)))


def test_servo_estimate_is_the_plain_alignment(views):
    """The servo's prepared reference gives the estimate the plain alignment gives, and
    that estimate is the true relative pose to within the servo's accuracy."""
    scene = table_top()
    desired = camera_pose()
    current = camera_pose((0.01, -0.01, 0.005), (0.5, -0.5, 0.5))
    # Downsampled to half a voxel, as prepared() does.
    servo = SpectralServo(view(scene, desired), ServoParams(mode="pose", downsample_size=0.0075))
    T, result = servo.estimate(view(scene, current))
    plain = _core._align(servo.reference, prepared(view(scene, current)), servo._align_params)
    assert_same(result, plain)
    truth = np.linalg.inv(current) @ desired
    t, r = pose_error(np.linalg.inv(truth) @ T)
    assert 1000 * t < 3.0
    assert math.degrees(r) < 1.0
