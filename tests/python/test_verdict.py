"""The verdict every registration carries (docs/trust.md): ``reliable`` and ``status``, the
calibrated ``confidence``, symmetric alternatives, ``determined`` and the covariance.

The failures a user must never see: views that share nothing, or a model of an object the
scene does not hold, reported ``reliable``; a voxel ten times too large with a confident
pose; a covariance whose normalised errors leave their band on a fixed seeded set."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs
from spectral_vs import data


def rotation(axis, degrees: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def left_error(T_true: np.ndarray, T: np.ndarray) -> np.ndarray:
    """delta with T_true = exp(delta) T, to first order: (rotation vector, translation)."""
    D = T_true @ np.linalg.inv(T)
    angle = np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1))
    w = np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    turn = np.zeros(3) if angle < 1e-12 else w * angle / (2 * np.sin(angle))
    return np.r_[turn, D[:3, 3]]


@pytest.fixture(scope="module")
def scans(data_dir):
    return (
        svs.load_organized(data_dir / "milk_cartoon_all_small_clorox.pcd"),
        svs.load_organized(data_dir / "five_people.pcd"),
    )


def test_a_copy_of_a_model_is_reliable_and_its_fields_agree():
    rng = np.random.default_rng(5)
    points, normals = box_and_sphere(rng, 3000)
    scene_points, scene_normals = box_and_sphere(rng, 3000)
    T = np.eye(4)
    T[:3, :3] = rotation([1, 2, 3], 70)
    T[:3, 3] = [0.04, -0.02, 0.05]
    scene = svs.PointCloud(scene_points @ T[:3, :3].T + T[:3, 3], scene_normals @ T[:3, :3].T)
    result = svs.align(svs.PointCloud(points, normals), scene, threads=1)
    error = left_error(T, result.T_scene_model)
    assert np.degrees(np.linalg.norm(error[:3])) < 1.0
    assert result.reliable and result.status == "reliable" and result.determined
    assert result.confidence >= svs.RELIABLE_CONFIDENCE
    # confidence is the score through a monotone map; the covariance is a covariance.
    assert 0.9 < result.score <= 1.0
    C = result.covariance
    assert C.shape == (6, 6) and np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)
    # Its deviations are those of an 8 mm-class alignment: under 1 degree and 2 mm.
    assert np.degrees(np.sqrt(C[:3, :3].diagonal()).max()) < 1.0
    assert 1000 * np.sqrt(C[3:, 3:].diagonal()).max() < 2.0
    assert 0.9 < result.inlier_fraction <= 1.0


def test_views_that_share_nothing_are_never_reliable(scans):
    """Windows of the table scan against windows of the room scan, both ways: no pose of one
    is right in the other, whatever the search finds."""
    table, room = scans
    for seed in range(3):
        a = data.make_view_pair(table, seed=seed)
        b = data.make_view_pair(room, seed=seed + 10)
        for reference, other in ((a, b), (b, a)):
            pair = dataclasses.replace(
                reference, current=other.current, current_viewpoint=other.current_viewpoint
            )
            result = svs.align_views(
                pair.reference, pair.current, sensor_origin=pair.current_viewpoint
            )
            assert not result.reliable, (seed, result)
            assert result.confidence < svs.RELIABLE_CONFIDENCE


def test_a_view_pair_that_shares_half_its_pixels_is_reliable(scans):
    table, _ = scans
    pair = data.make_view_pair(table, seed=2)
    result = svs.align_views(pair.reference, pair.current, sensor_origin=pair.current_viewpoint)
    centroid = np.asarray(pair.reference.points).mean(axis=0)
    error = svs.pose_error(result.T_current_reference, pair.T_current_reference, center=centroid)
    assert error.rotation_deg < 1.0 and error.translation_mm < 5.0
    assert result.reliable and result.status == "reliable", result
    assert result.determined and not result.ambiguous


def test_an_object_absent_from_the_scene_is_never_reliable(data_dir):
    """The bunny's scan aligned into the milk carton's scene: every pose is wrong."""
    scene = svs.load_cloud(data_dir / "milk_cartoon_all_small_clorox.pcd")
    bunny = svs.load_cloud(data_dir / "bun0.pcd")
    result = svs.align(bunny, scene, threads=1)
    assert not result.reliable, result
    assert result.status != "reliable"


def test_a_voxel_ten_times_too_large_is_bad_scale_with_no_confidence():
    """A 10 cm box aligned at 0.3 m voxels (metres slipped for decimetres): the search
    returns a pose, and the verdict refuses it at once."""
    rng = np.random.default_rng(3)
    faces = rng.integers(0, 6, 4000)
    points = rng.uniform(-0.05, 0.05, (4000, 3))
    normals = np.zeros((4000, 3))
    for axis in range(3):
        for sign, face in ((-1, 2 * axis), (1, 2 * axis + 1)):
            on = faces == face
            points[on, axis] = sign * 0.05
            normals[on, axis] = sign
    box = svs.PointCloud(points, normals)
    result = svs.align(box, box, voxel_size=0.3, threads=1)
    assert result.status == "bad_scale" and not result.reliable
    assert result.confidence == 0.0


def test_a_box_turned_half_a_turn_is_the_same_answer_not_an_ambiguity():
    """A whole box aligned onto a copy: the poses turned half a turn about its axes fit as
    well, and they are the same answer (the box maps onto itself)."""
    rng = np.random.default_rng(8)
    half = np.array([0.12, 0.06, 0.04])
    points = rng.uniform(-1, 1, (6000, 3)) * half
    normals = np.zeros_like(points)
    axes = rng.integers(0, 3, 6000)
    signs = rng.choice([-1.0, 1.0], 6000)
    points[np.arange(6000), axes] = signs * half[axes]
    normals[np.arange(6000), axes] = signs
    box = svs.PointCloud(points, normals)
    result = svs.align(box, box.transformed(np.eye(4)), threads=1)
    assert result.alternatives, "a box has poses a half turn apart that fit as well"
    assert all(a.symmetric for a in result.alternatives)
    assert not result.ambiguous and result.reliable


def test_the_covariance_bounds_the_errors_of_a_fixed_seeded_set():
    """The first three problems of each object family of the validation set (never fitted
    on): the mean normalised estimation error squared (NEES) of the right answers lies in
    [3, 12] (6 for a consistent 6-dimensional covariance). The error is the left
    perturbation T_true = exp(delta) T, nearest over the object's exact symmetries."""
    pytest.importorskip("pybullet")
    import verdict_benchmark as bench
    import verdict_sets as vs

    values = []
    for spec in vs.specs("validation", per_family=3):
        if spec.kind != "align" or spec.family in (*vs.NO_TRUTH_FAMILIES, "wrong_voxel"):
            continue
        case = vs.build_case(spec)
        result = bench._call(case)
        T = np.asarray(result.T_scene_model)
        if vs.is_right(case, T):
            error = vs.left_error(vs.nearest_truth(case, T), T)
            values.append(float(error @ np.linalg.solve(result.covariance, error)))
    assert len(values) >= 15
    assert 3.0 <= np.mean(values) <= 12.0, values


def test_the_calibration_maps_are_monotone_probabilities_per_kind():
    """calibrated_confidence reads one map per kind: non-decreasing in the score, in
    [0, 1], a NaN score no evidence; an unknown kind named in the error."""
    scores = np.linspace(0.0, 1.0, 201)
    for kind in ("align", "views", "servo", "servo_carried"):
        p = np.array([svs.calibrated_confidence(float(s), kind) for s in scores])
        assert np.all(np.diff(p) >= -1e-12), kind
        assert p.min() >= 0.0 and p.max() <= 1.0
        assert p[-1] > 0.9, kind  # a perfect fit is a good answer, whatever the map
        assert svs.calibrated_confidence(float("nan"), kind) == 0.0
    for kind in ("align", "views"):  # no fit at all is a bad one
        assert svs.calibrated_confidence(0.0, kind) < 0.1
    with pytest.raises(ValueError, match="kind must be 'align', 'views', 'servo' or"):
        svs.calibrated_confidence(0.5, "icp")
    with pytest.raises(ValueError, match="no covariance"):
        svs.covariance_inflation("servo")
