"""The servo's scale lengths: derived from the reference view when given as 0 (the
defaults), kept when given, refused (naming the setting) when negative or not finite."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_servo import camera_pose, table_top, view

import spectral_vs as svs
from spectral_vs.servo import ServoParams, ServoScale, SpectralServo
from spectral_vs.servo.scale import SCALE_LENGTHS


def scaled_reference(factor: float) -> svs.PointCloud:
    """The synthetic table top seen from 0.5 m, every length times ``factor``."""
    reference = view(table_top(), camera_pose())
    return svs.PointCloud(factor * np.asarray(reference.points), np.asarray(reference.normals))


def test_derived_lengths_follow_the_scene():
    """Twice the scene, twice every derived length (the rule is in extents). The 0.6 x
    0.5 m table seen whole from 0.5 m has an extent of 0.387 m (the simulated table's
    view, 0.8 x 0.6 m with the floor, 0.556 m): a 10.5 mm voxel, 0.21 m and 0.07 m bounds
    and a 1.16 m depth crop (the reference's farthest point at 0.5 m plus 1.7 extents)."""
    small = SpectralServo(scaled_reference(1.0)).scale
    large = SpectralServo(scaled_reference(2.0)).scale
    assert isinstance(small, ServoScale)
    assert set(small.derived) == set(SCALE_LENGTHS)
    assert large.extent == pytest.approx(2 * small.extent, rel=0.01)
    for name in SCALE_LENGTHS:
        assert getattr(large, name) == pytest.approx(2 * getattr(small, name), rel=0.02), name
    assert small.extent == pytest.approx(0.387, abs=0.005)
    assert 1000 * small.voxel_size == pytest.approx(10.5, abs=0.2)
    assert small.downsample_size == small.voxel_size
    assert small.max_translation == pytest.approx(0.209, abs=0.003)
    assert small.tracking_translation == pytest.approx(0.0697, abs=0.001)
    assert small.max_depth == pytest.approx(1.16, abs=0.01)
    assert small.jump_limit_translation == pytest.approx(0.0697, abs=0.001)
    assert small.occlusion_margin == pytest.approx(0.0349, abs=0.0005)
    assert small.recover_standoff == pytest.approx(0.105, abs=0.002)
    assert small.refute_translation == pytest.approx(0.0209, abs=0.0003)


def test_the_servo_uses_the_lengths_it_resolved():
    """``SpectralServo.params`` holds the resolved lengths (its prepared reference is at
    the derived voxel); the settings given are left as they were."""
    given = ServoParams()
    servo = SpectralServo(scaled_reference(2.0), given)
    for name in SCALE_LENGTHS:
        assert getattr(servo.params, name) == getattr(servo.scale, name) > 0
        assert getattr(given, name) == 0.0
    assert servo._reference.align_params.voxel_size == servo.scale.voxel_size
    assert servo.params.resolved(scaled_reference(2.0)) == servo.params  # nothing left to derive


def test_explicit_lengths_are_kept():
    explicit = {
        "voxel_size": 0.02,
        "max_translation": 0.25,
        "tracking_translation": math.inf,
        "max_depth": 2.0,
        "jump_limit_translation": 0.07,
        "occlusion_margin": math.inf,
        "recover_standoff": 0.1,
        "refute_translation": 0.02,
    }
    servo = SpectralServo(scaled_reference(1.0), ServoParams(**explicit))
    for name, value in explicit.items():
        assert getattr(servo.scale, name) == value
        assert getattr(servo.params, name) == value
    assert servo.scale.derived == ("downsample_size",)
    assert servo.scale.downsample_size == 0.02  # 0: one voxel
    assert not servo.params.uses_tracking()  # inf: no tracking bound


def test_a_given_max_depth_bounds_the_extent():
    """The extent is measured on the reference within a given ``max_depth``: the rest of
    the scale follows the part of the view the servo registers."""
    reference = scaled_reference(1.0)
    cropped = SpectralServo(reference, ServoParams(max_depth=0.47)).scale
    whole = SpectralServo(reference).scale
    assert cropped.points < 0.5 * whole.points  # only the boxes' tops are within 0.47 m
    assert cropped.extent < 0.9 * whole.extent


@pytest.mark.parametrize("name", list(SCALE_LENGTHS))
@pytest.mark.parametrize("value", [-0.01, math.nan])
def test_bad_lengths_are_refused_by_name(name, value):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        ServoParams(**{name: value})


@pytest.mark.parametrize("name", ["voxel_size", "downsample_size", "recover_standoff"])
def test_lengths_without_an_off_value_must_be_finite(name):
    with pytest.raises(ValueError, match=f"^{name} must be finite"):
        ServoParams(**{name: math.inf})


def test_unresolved_settings_and_a_degenerate_reference_are_refused():
    with pytest.raises(ValueError, match="voxel_size is 0"):
        ServoParams().align_params()
    with pytest.raises(ValueError, match="extent"):
        SpectralServo(np.zeros((600, 3)))
