"""ModelAligner, the reference prepared once for many scenes: the same results as the plain
alignment on a sequence of servo views, and the servo's estimate made with it."""

from __future__ import annotations

import copy
import ctypes
import math

import numpy as np
import pytest
from test_servo import camera_pose, table_top, view

import spectral_vs as svs
from spectral_vs import _core
from spectral_vs.registration import prepare
from spectral_vs.servo import ServoParams, SpectralServo, pose_error

#: The scale lengths these tests were written at (given: they test the prepared
#: reference, not the servo's scale rule).
SCALE = {"voxel_size": 0.015, "max_translation": 0.3, "tracking_translation": 0.1}


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
    params = ServoParams(mode=mode, **SCALE).align_params()
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
    params = ServoParams(**SCALE).align_params()
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
    servo = SpectralServo(
        view(scene, desired), ServoParams(mode="pose", downsample_size=0.0075, **SCALE)
    )
    T, result = servo.estimate(view(scene, current))
    plain = _core._align(
        servo.reference, prepared(view(scene, current)), servo._reference.align_params
    )
    assert_same(result, plain)
    truth = np.linalg.inv(current) @ desired
    t, r = pose_error(np.linalg.inv(truth) @ T)
    assert 1000 * t < 3.0
    assert math.degrees(r) < 1.0


def test_servo_registrations_skip_the_verification_and_change_nothing(views):
    """The servo reads only the fitness, so its registrations run without the pose
    verification (``AlignParams.verify`` off): the same pose, fitness and history, bit for
    bit, as the verified call, on the full and the tracking bound; only the verification's
    figures stay 0."""
    reference, currents = views
    servo_params = ServoParams(**SCALE)
    assert svs.AlignParams().verify is True
    assert servo_params.align_params().verify is False
    for bound in (servo_params.max_translation, servo_params.tracking_translation):
        unverified = servo_params.align_params()
        unverified.max_translation = bound
        verified = copy.copy(unverified)
        verified.verify = True
        with_check = _core.ModelAligner(reference, verified)
        without_check = _core.ModelAligner(reference, unverified)
        for current in currents:
            a, b = with_check.align(current), without_check.align(current)
            assert np.array_equal(np.asarray(a.T_scene_model), np.asarray(b.T_scene_model))
            assert a.fitness == b.fitness and a.correlation == b.correlation
            assert [x.translation_cost for x in a.history] == [
                x.translation_cost for x in b.history
            ]
            assert b.confidence == 0.0 and b.inliers == 0 and b.inlier_rmse == 0.0
        # The last view is the reference's pose: the verified call confirms it.
        assert a.confidence > 0.8 and a.inliers > 0.8 * len(reference)
        assert 1000 * a.inlier_rmse < 5.0


def test_servo_steps_are_the_same_with_the_verification(views):
    """A servo run over a sequence of views approaching the goal, with the verification
    turned back on (``align_overrides``): every step's estimate and fitness are the default
    servo's, bit for bit, tracking steps included."""
    scene = table_top()
    reference = view(scene, camera_pose())
    poses = [
        camera_pose((0.02 * s, -0.015 * s, 0.01 * s), (1.5 * s, -1.0 * s, 2.0 * s))
        for s in (1.0, 0.8, 0.6, 0.45, 0.3, 0.2, 0.1)
    ]
    servos = [
        SpectralServo(reference, ServoParams()),
        SpectralServo(reference, ServoParams(align_overrides={"verify": True})),
    ]
    records = [[], []]
    for servo, out in zip(servos, records, strict=True):
        previous = None
        for pose in poses:
            motion = None if previous is None else np.linalg.inv(previous) @ pose
            out.append(servo.step_record(view(scene, pose), motion, now=len(out) * 0.1)[2])
            previous = pose
    for a, b in zip(*records, strict=True):
        assert np.array_equal(a.T_current_desired, b.T_current_desired)
        assert a.fitness == b.fitness and a.tracking == b.tracking
    assert any(r.tracking for r in records[0])


def _malloc_in_use() -> int | None:
    """Bytes that malloc has handed out (glibc's ``mallinfo2``), or None elsewhere."""
    fields = ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks")
    fields += ("uordblks", "fordblks", "keepcost")

    class MallInfo2(ctypes.Structure):
        _fields_ = [(name, ctypes.c_size_t) for name in fields]

    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = MallInfo2
    except (OSError, AttributeError):
        return None
    info = libc.mallinfo2()
    return int(info.uordblks + info.hblkhd)


def test_model_aligner_keeps_a_bounded_number_of_fft_plans(views):
    """The servo's aligner keeps the FFT plans and buffers of the grid sizes it saw last (3
    besides the one in use). Starts turned by 0-70 degrees about the camera's x axis give
    5 grid sizes (4.6-6.7 MB of buffers each); cycled, 37 of the 72 calls plan anew and
    free the least recently used. After a first round, 64 more calls leave malloc's memory
    in use within 2 MB of where it was: the plans and buffers given up are freed and
    nothing is kept per call or per size beyond the bound (the soak's memory,
    docs/reliability.md)."""
    reference, currents = views
    aligner = _core.ModelAligner(reference, ServoParams(**SCALE).align_params())
    starts = []
    for degrees in (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0):
        c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
        turn = np.eye(4)
        turn[1:3, 1:3] = [[c, -s], [s, c]]  # about the camera's x axis
        starts.append(turn)
    for start in starts:
        aligner.align(currents[0], start)
    before = _malloc_in_use()
    if before is None:
        pytest.skip("needs glibc's mallinfo2")
    for _ in range(8):
        for start in starts:
            aligner.align(currents[0], start)
    grown = _malloc_in_use() - before
    assert abs(grown) < 2 * 2**20, f"malloc's memory in use changed by {grown / 2**20:.2f} MB"
