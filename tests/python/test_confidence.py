"""The confidence of align() and verify_pose (inliers, their RMSE, the share of the view
that the scan confirms), and the alternatives of symmetric objects (the held-out
validation objects of benchmarks/cases.py are tested in benchmarks/tests).

Expected values are computed by hand or by brute force here, never by the code under
test; tolerances are in millimetres and degrees."""

from __future__ import annotations

import math

import numpy as np
import pytest

import spectral_vs as svs

pytest.importorskip("pybullet")  # the meshes come with pybullet_data

import cases

MM = 1e-3
UP = (0.0, 0.0, 1.0)


def cloud(points, normals) -> svs.PointCloud:
    return svs.PointCloud(np.asarray(points, dtype=float), np.asarray(normals, dtype=float))


# --- verify_pose on hand-computed cases ---------------------------------------------------


def test_inliers_and_rmse_are_the_nearest_distances_within_one_voxel():
    scene = cloud([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], [UP] * 3)
    # Nearest distances by hand: 3, 6, 5 mm (inliers at d = 8 mm), 300 mm, 1 mm.
    model = cloud(
        [[0, 0, 0.003], [0.1, 0, 0.006], [0.2, 0.005, 0], [0.5, 0, 0], [0, 0, 0.001]],
        [UP, UP, UP, UP, (0.0, 0.0, -1.0)],
    )
    v = svs.verify_pose(model, scene, np.eye(4), voxel_size=0.008, downsample=False)
    assert v.inlier_distance == pytest.approx(8 * MM)
    assert v.inliers == 4
    assert v.inlier_rmse == pytest.approx(math.sqrt((9 + 36 + 25 + 1) / 4) * MM, abs=1e-9)
    assert v.inlier_fraction == pytest.approx(0.8)
    # Tight: within 4 mm of the scene's tangent plane and turned within 45 degrees.
    assert (v.visible, v.tight, v.seen_through, v.hidden) == (5, 2, 0, 0)
    assert v.confidence == pytest.approx(2 / 5)


def test_moving_the_model_moves_its_inliers_with_it():
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.05, 0.05, size=(400, 3))
    points[:, 2] = 0.0
    scene = cloud(points, np.tile(UP, (400, 1)))
    T = np.eye(4)
    T[2, 3] = 0.003  # the model 3 mm above the plane: every point an inlier at 3 mm
    v = svs.verify_pose(scene, scene, T, voxel_size=0.008, downsample=False)
    assert v.inliers == 400
    assert v.inlier_rmse == pytest.approx(3 * MM, abs=1e-9)
    assert v.tight == 400  # 3 mm <= half a voxel from the plane
    T[2, 3] = 0.005
    assert svs.verify_pose(scene, scene, T, voxel_size=0.008, downsample=False).tight == 0


def test_verify_pose_names_bad_arguments():
    scene = cloud([[0, 0, 0], [0.1, 0, 0]], [UP] * 2)
    with pytest.raises(ValueError, match="voxel_size"):
        svs.verify_pose(scene, scene, np.eye(4), voxel_size=-0.01, downsample=False)
    skewed = np.eye(4)
    skewed[0, 1] = 0.5
    with pytest.raises(ValueError, match="T_scene_model"):
        svs.verify_pose(scene, scene, skewed, downsample=False)
    with pytest.raises(ValueError, match="sensor_origin"):
        svs.verify_pose(scene, scene, np.eye(4), sensor_origin=(0, math.nan, 0))
    with pytest.raises(ValueError, match="scene_view"):
        svs.verify_pose(scene, scene, np.eye(4), scene_view="one_view")


def test_align_reports_what_verify_pose_measures():
    case = cases.make_case(cases.CaseSpec("partial", "duck", 60.0, 0))
    view = {"voxel_size": 0.008, "sensor_origin": case.viewpoint, "scene_view": "single_view"}
    result = svs.align(case.model_cloud(), case.scene_cloud(), **view)
    v = svs.verify_pose(case.model_cloud(), case.scene_cloud(), result.T_scene_model, **view)
    # verify_pose's confidence is the uncalibrated score the result reports.
    assert result.score == pytest.approx(v.confidence, abs=1e-12)
    assert result.inliers == v.inliers
    assert result.inlier_rmse == pytest.approx(v.inlier_rmse, abs=1e-12)
    assert result.inlier_distance == pytest.approx(0.008)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert result.score > svs.CONFIDENCE_THRESHOLD
    # The same pose turned by 90 degrees about the duck's centroid is wrong and says so.
    wrong = result.T_scene_model @ cases.rotation_about(
        cases.axis_angle(np.array([1.0, 0.0, 0.0]), math.pi / 2), case.model_center
    )
    w = svs.verify_pose(case.model_cloud(), case.scene_cloud(), wrong, **view)
    assert w.confidence < svs.CONFIDENCE_THRESHOLD


def test_the_threshold_rejects_a_wrong_single_view_pose_that_fits_its_visible_side():
    # A case of the tuning family C-2 (the jenga box at 150 degrees, case 2): a truncated
    # search (2 hypotheses, 1 refinement, no reselection) returns the box turned 90 degrees,
    # its visible long face on the scan's, scoring 0.73 at the voxel derived from the model;
    # the threshold, chosen on the tuning families at that voxel, rejects it, and the
    # defaults' pose passes it. (A flat blob's wrong pose scoring 0.898, the example while
    # the threshold was 0.91, is now taken as right: docs/experiments.md, "Threshold".)
    case = cases.make_case(cases.CaseSpec("partial", "jenga", 150.0, 2))
    view = {"sensor_origin": case.viewpoint, "scene_view": "single_view", "threads": 1}
    truncated = {"hypotheses": 2, "refinements": 1, "reselect_margin": 1.0}
    wrong = svs.align(case.model_cloud(), case.scene_cloud(), **truncated, **view)
    assert cases.pose_error(case, wrong.T_scene_model)[0] > 45.0
    assert 0.6 < wrong.confidence < svs.CONFIDENCE_THRESHOLD
    right = svs.align(case.model_cloud(), case.scene_cloud(), **view)
    rotation, translation = cases.pose_error(case, right.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert right.confidence > svs.CONFIDENCE_THRESHOLD


# --- Alternatives of symmetric objects ----------------------------------------------------


def exact_error(T_true: np.ndarray, T: np.ndarray, center: np.ndarray) -> tuple[float, float]:
    """Rotation (degrees) and centroid (metres) error against T_true itself, no symmetry."""
    c = np.append(center, 1.0)
    return (
        cases.rotation_angle_deg(T[:3, :3].T @ T_true[:3, :3]),
        float(np.linalg.norm((T @ c - T_true @ c)[:3])),
    )


def reported(result) -> list[np.ndarray]:
    return [result.T_scene_model, *[a.T_scene_model for a in result.alternatives]]


def truth_among(result, T_true: np.ndarray, center: np.ndarray) -> bool:
    return any(
        r < 5.0 and t < 10 * MM
        for r, t in (exact_error(T_true, T, center) for T in reported(result))
    )


@pytest.mark.parametrize(("name", "angle"), [("jenga", 120.0), ("lego", 90.0)])
def test_a_box_and_a_brick_report_the_true_pose_among_their_symmetric_ones(name, angle):
    case = cases.make_case(cases.CaseSpec("full", name, angle, 0))
    result = svs.align(case.model_cloud(), case.scene_cloud())
    # The other poses map the object onto itself: the same answer, not an ambiguity.
    assert not result.ambiguous and result.reliable
    assert result.alternatives and all(a.symmetric for a in result.alternatives)
    assert truth_among(result, case.T_true, case.model_center)
    # Every exact symmetry of the object is a pose the scene supports: reported too.
    for S in case.symmetries:
        assert truth_among(result, case.T_true @ S, case.model_center)
    for a in result.alternatives:
        assert a.score >= result.score - 0.05
        assert math.degrees(a.rotation_apart) > 5.0 or a.translation_apart > 10 * MM


def mug_without_its_handle() -> tuple[svs.PointCloud, svs.PointCloud, np.ndarray]:
    """The mug upright at the origin, seen from 0.5 m at 20 degrees elevation from the
    side opposite its handle (the handle's direction: the horizontal direction of the
    vertex farthest from the mug's axis)."""
    rng = np.random.default_rng(11)
    mesh = cases.load_mesh("mug")
    model_points, model_normals = cases.sample_surface(mesh, cases.MODEL_SAMPLES, rng)
    body = np.median(np.linalg.norm(mesh.vertices[:, :2], axis=1))
    far = mesh.vertices[np.argmax(np.linalg.norm(mesh.vertices[:, :2], axis=1))]
    assert np.linalg.norm(far[:2]) > 1.3 * body  # the handle sticks out
    away = -far[:2] / np.linalg.norm(far[:2])
    elevation = math.radians(20.0)
    eye = 0.5 * np.array([*(math.cos(elevation) * away), math.sin(elevation)])
    T_world_camera = cases.look_at(eye, np.zeros(3))
    r = cases.renderer()
    r.reset()
    r.add_mesh(mesh.vertices, mesh.faces, np.eye(4))
    depth, _ = r.render(T_world_camera, cases.intrinsics())
    points, normals = cases._scan(depth, T_world_camera, rng)
    # The handle is hidden: no scanned point is within 5 mm of the handle's tip.
    assert np.min(np.linalg.norm(points - far, axis=1)) > 5 * MM
    return cloud(model_points, model_normals), cloud(points, normals), eye


def test_a_mug_seen_without_its_handle_is_ambiguous_and_reports_the_true_pose():
    model, scene, eye = mug_without_its_handle()
    result = svs.align(model, scene, sensor_origin=eye, scene_view="single_view")
    assert result.ambiguous
    assert truth_among(result, np.eye(4), np.zeros(3))


@pytest.mark.parametrize("name", ["bunny", "duck"])
def test_an_asymmetric_object_is_not_ambiguous(name):
    case = cases.make_case(cases.CaseSpec("full", name, 120.0, 0))
    result = svs.align(case.model_cloud(), case.scene_cloud())
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert not result.ambiguous
    assert result.alternatives == []


def test_a_clearly_more_confident_alternative_is_returned_instead():
    # A single view of the bunny (tuning family C-2, 10 degrees, case 2): the refinements,
    # ranked by fitness, keep a wrong pose; one of its alternatives is the truth.
    case = cases.in_camera_frame(cases.make_case(cases.CaseSpec("partial", "bunny", 10.0, 2)))
    model, scene = case.model_cloud(), case.scene_cloud()
    refined = svs.align(model, scene, threads=1, reselect_margin=1.0)
    assert refined.stop_reason != "reselected"
    rotation, translation = cases.pose_error(case, refined.T_scene_model)
    assert rotation > 5.0 or translation > 10 * MM
    truths = [a for a in refined.alternatives if cases.pose_error(case, a.T_scene_model)[0] < 5.0]
    # The reselection reads the uncalibrated score (the calibration is monotone).
    assert truths and truths[0].score > refined.score + 0.1

    result = svs.align(model, scene, threads=1)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert result.stop_reason == "reselected" and result.converged
    assert result.iterations == 0 and result.history == [] and result.hypothesis == -2
    assert result.score == pytest.approx(truths[0].score, abs=1e-9)
    assert result.confidence == pytest.approx(truths[0].confidence, abs=1e-9)
    assert result.score > refined.score + 0.1
    # The alternatives are those of the returned pose, apart from it.
    for alternative in result.alternatives:
        apart = math.degrees(alternative.rotation_apart) > 5.0
        assert apart or alternative.translation_apart > 10 * MM


@pytest.mark.parametrize(("name", "angle", "index"), [("tile", 10.0, 5), ("slab", 30.0, 0)])
def test_an_alternative_as_confident_with_more_inliers_is_returned_instead(name, angle, index):
    # A flat box among tuning objects (cases.THIN_OBJECTS, benchmarks/thin_objects.py):
    # the refined pose puts its large face on another object's, its other faces hidden
    # inside it, as confident as the truth; the truth, lying on the table, has more inliers
    # (its underside on the table). Measured before: 95 degrees / 194 mm and 62 degrees /
    # 254 mm off.
    case = cases.in_camera_frame(cases.make_case(cases.CaseSpec("clutter", name, angle, index)))
    model, scene = case.model_cloud(), case.scene_cloud()
    refined = svs.align(model, scene, threads=1, reselect_margin=1.0)
    rotation, translation = cases.pose_error(case, refined.T_scene_model)
    assert rotation > 20.0 and translation > 50 * MM
    truths = [a for a in refined.alternatives if cases.pose_error(case, a.T_scene_model)[0] < 5.0]
    assert truths and truths[0].score >= refined.score
    assert truths[0].inliers > refined.inliers

    result = svs.align(model, scene, threads=1)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert result.stop_reason == "reselected"
    assert result.confidence >= refined.confidence and result.inliers > refined.inliers


@pytest.mark.parametrize(("name", "angle", "index"), [("tile", 90.0, 3), ("slab", 60.0, 0)])
def test_in_clutter_an_alternative_explaining_its_object_whole_is_returned_instead(
    name, angle, index
):
    # A flat box among tuning objects: the refined pose stands on another object's face, as
    # confident as the truth (within 0.01) and with as many inliers, but explaining about
    # half of that object's part of the scene; the truth, lying on the table, explains its
    # own part whole. Measured before: 104 degrees / 233 mm and 86 degrees / 144 mm off.
    case = cases.in_camera_frame(cases.make_case(cases.CaseSpec("clutter", name, angle, index)))
    model, scene = case.model_cloud(), case.scene_cloud()
    refined = svs.align(model, scene, threads=1, reselect_margin=1.0)
    rotation, translation = cases.pose_error(case, refined.T_scene_model)
    assert rotation > 20.0 and translation > 50 * MM
    assert any(cases.pose_error(case, a.T_scene_model)[0] < 5.0 for a in refined.alternatives)

    result = svs.align(model, scene, threads=1)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert result.stop_reason == "reselected"
    assert result.confidence > refined.confidence - 0.01


def test_in_clutter_a_pose_that_does_not_rest_gives_way_to_one_that_does():
    # The fin (a tuning-side box 120 x 40 x 15 mm standing on its end) among tuning objects:
    # the refined pose lies flush with the jenga's top face, the rest of it inside the
    # jenga, 15 mm above the table with nothing under it. The truth stands on the table.
    # Measured before: 90 degrees and 132 mm off, confidence 0.99.
    case = cases.in_camera_frame(cases.make_case(cases.CaseSpec("clutter", "fin", 60.0, 0)))
    model, scene = case.model_cloud(), case.scene_cloud()
    refined = svs.align(model, scene, threads=1, reselect_margin=1.0)
    rotation, translation = cases.pose_error(case, refined.T_scene_model)
    assert rotation > 45.0 and translation > 50 * MM

    result = svs.align(model, scene, threads=1)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation < 5.0 and translation < 10 * MM
    assert result.stop_reason == "reselected"
    assert result.confidence > refined.confidence - 0.1


def test_a_wrong_pose_that_floats_is_not_reliable():
    # The wall (a tuning-side box 130 x 70 x 12 mm standing on a long edge) among tuning
    # objects: the returned pose lies flush with another object's face, 355 mm from the
    # truth, neither touching the table nor standing on anything. Measured before the
    # floating verdict: 22 degrees off, score 0.95, reliable.
    case = cases.in_camera_frame(cases.make_case(cases.CaseSpec("clutter", "wall", 10.0, 3)))
    result = svs.align(case.model_cloud(), case.scene_cloud(), threads=1)
    rotation, translation = cases.pose_error(case, result.T_scene_model)
    assert rotation > 10.0 and translation > 100 * MM
    assert not result.rests
    assert result.status == "floating" and not result.reliable
    assert result.confidence >= svs.RELIABLE_CONFIDENCE  # the score alone took it for right


def errors(model: svs.PointCloud, T_true: np.ndarray, T: np.ndarray) -> tuple[float, float]:
    """Degrees, metres (at the model's centroid)."""
    degrees = cases.rotation_angle_deg(T_true[:3, :3].T @ T[:3, :3])
    centre = np.append(model.points.mean(axis=0), 1.0)
    return degrees, float(np.linalg.norm((T @ centre - T_true @ centre)[:3]))


@pytest.mark.parametrize("lift", [0.0, 0.08])
def test_an_object_held_above_the_table_floats_unless_resting_is_not_expected(lift):
    model, scan, T_true, origin = cases.held_above_table("duck", lift)
    view = {"sensor_origin": origin, "scene_view": "single_view", "threads": 1}
    for expect_resting in (True, False):
        result = svs.align(model, scan, expect_resting=expect_resting, **view)
        rotation, translation = errors(model, T_true, result.T_scene_model)
        assert rotation < 1.0 and translation < 1 * MM  # right either way
        assert result.rests == (lift == 0.0)
        # On the table it is reliable; 80 mm above it floats, unless told it may.
        floats = lift > 0.0 and expect_resting
        assert result.status == ("floating" if floats else "reliable")
        assert result.reliable == (not floats)


def test_reselect_margin_is_checked():
    case = cases.make_case(cases.CaseSpec("full", "jenga", 30.0, 0))
    for margin in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="reselect_margin"):
            svs.align(case.model_cloud(), case.scene_cloud(), reselect_margin=margin)


def test_max_alternatives_zero_skips_the_search():
    case = cases.make_case(cases.CaseSpec("full", "jenga", 30.0, 0))
    result = svs.align(case.model_cloud(), case.scene_cloud(), max_alternatives=0)
    assert result.alternatives == [] and not result.ambiguous
    with pytest.raises(ValueError, match="max_alternatives"):
        svs.align(case.model_cloud(), case.scene_cloud(), max_alternatives=-1)
