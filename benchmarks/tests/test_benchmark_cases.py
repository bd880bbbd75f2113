"""The case generator of the alignment experiments (benchmarks/cases.py): its geometry.

Surface samples lie on the mesh with outward unit normals, a rendered partial scan is a
subset of the surface the camera faces, T_true maps the model onto the scene within the
noise, symmetries map the object onto itself, and a seed fixes a case. Distances are
brute force (point to triangle, nearest neighbour) on small subsets."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet")  # the meshes come with pybullet_data

import cases

MM = 1e-3


# --- Brute-force geometry -----------------------------------------------------------------


def point_triangle_distance(points: np.ndarray, a, b, c) -> np.ndarray:
    """Distance (P,) from each point to the nearest of the triangles (a, b, c: (F, 3))."""
    best = np.full(len(points), np.inf)
    for chunk in np.array_split(np.arange(len(points)), max(1, len(points) // 64)):
        p = points[chunk, None, :]  # (n, 1, 3) against (F, 3)
        n = np.cross(b - a, c - a)
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
        height = np.einsum("pfk,fk->pf", p - a, n)
        foot = p - height[..., None] * n
        inside = np.ones(height.shape, dtype=bool)
        for u, v in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("pfk,fk->pf", np.cross(v - u, foot - u), n) >= 0.0
        d = np.where(inside, np.abs(height), np.inf)
        for u, v in ((a, b), (b, c), (c, a)):
            e = v - u
            t = np.clip(np.einsum("pfk,fk->pf", p - u, e) / np.einsum("fk,fk->f", e, e), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(p - (u + t[..., None] * e), axis=-1))
        best[chunk] = d.min(axis=1)
    return best


def mesh_distance(mesh: cases.Mesh, points: np.ndarray) -> np.ndarray:
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    return point_triangle_distance(points, a, b, c)


def winding_number(mesh: cases.Mesh, points: np.ndarray) -> np.ndarray:
    """Generalised winding number (1 inside a closed outward mesh, 0 outside)."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    total = np.zeros(len(points))
    for i, p in enumerate(points):
        x, y, z = a - p, b - p, c - p
        lx, ly, lz = (np.linalg.norm(v, axis=1) for v in (x, y, z))
        det = np.einsum("ij,ij->i", x, np.cross(y, z))
        div = (
            lx * ly * lz
            + np.einsum("ij,ij->i", x, y) * lz
            + np.einsum("ij,ij->i", y, z) * lx
            + np.einsum("ij,ij->i", z, x) * ly
        )
        total[i] = 2.0 * np.arctan2(det, div).sum() / (4.0 * math.pi)
    return total


def nearest_distance(points: np.ndarray, reference: np.ndarray) -> np.ndarray:
    best = np.full(len(points), np.inf)
    rows = max(1, 1_000_000 // len(reference))  # about 24 MB of differences at a time
    for chunk in np.array_split(np.arange(len(points)), max(1, len(points) // rows)):
        d = np.linalg.norm(points[chunk, None, :] - reference[None, :, :], axis=-1)
        best[chunk] = d.min(axis=1)
    return best


def to_object(case: cases.Case, points: np.ndarray) -> np.ndarray:
    return cases.apply(np.linalg.inv(np.asarray(case.info["T_scene_object"])), points)


# --- Meshes and samples -------------------------------------------------------------------


def test_ear_clipping_handles_a_non_convex_polygon():
    # An L shape: a fan from vertex 0 would put a triangle outside it.
    polygon = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    polygon = np.roll(polygon, -3, axis=0)  # start at the reflex corner's neighbour
    triangles = cases.triangulate(polygon)
    assert len(triangles) == 4
    area = sum(
        0.5 * np.linalg.norm(np.cross(polygon[j] - polygon[i], polygon[k] - polygon[i]))
        for i, j, k in triangles
    )
    assert area == pytest.approx(3.0)  # no overlap, nothing outside


def test_obj_quads_become_two_triangles_each():
    import pybullet_data

    _, faces, _ = cases.read_obj(Path(pybullet_data.getDataPath()) / "objects/mug.obj")
    assert len(faces) == 48 + 2 * 408  # the mug's triangles and quads


@pytest.mark.parametrize("name", ["mug", "duck", "jenga", "blob000"])
def test_samples_lie_on_the_mesh_with_outward_unit_normals(name):
    mesh = cases.load_mesh(name)
    points, normals = cases.sample_surface(mesh, 150, np.random.default_rng(1))
    assert np.max(mesh_distance(mesh, points)) < 1e-6  # metres: on a triangle
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    step = 0.3 * MM
    outside = winding_number(mesh, points + step * normals)
    inside = winding_number(mesh, points - step * normals)
    if name == "blob000":  # overlapping convex parts: inside one part, not inside another
        assert np.mean(inside > 0.5) > 0.97 and np.mean(outside < 0.5) > 0.97
    else:
        assert np.mean(inside - outside > 0.5) > 0.97


def test_samples_skip_the_hidden_surface_of_overlapping_parts():
    mesh = cases.load_mesh("blob000")
    points, normals = cases.sample_surface(mesh, 2000, np.random.default_rng(2))
    assert not cases.inside_other_part(mesh, points, np.full(len(points), -1), normals).any()


@pytest.mark.parametrize("name", list(cases.OBJECTS))
def test_objects_have_household_sizes_and_centred_frames(name):
    mesh = cases.load_mesh(name)
    extent = mesh.vertices.max(0) - mesh.vertices.min(0)
    assert 0.08 - 1e-9 <= extent.max() <= 0.25
    points, _ = cases.sample_surface(mesh, 20000, np.random.default_rng(3))
    assert np.linalg.norm(points.mean(axis=0)) < 1.5 * MM  # origin at the surface centroid


def is_symmetry(mesh: cases.Mesh, R: np.ndarray) -> bool:
    """The rule of cases.OBJECTS: a turn is a symmetry when it moves 90% of the surface by
    less than 2 mm and none of it by more than 5 mm."""
    points, _ = cases.sample_surface(mesh, 300, np.random.default_rng(4))
    moved = mesh_distance(mesh, points @ R.T)
    return bool(np.percentile(moved, 90) < 2 * MM and moved.max() < 5 * MM)


@pytest.mark.parametrize(
    "name",
    ["jenga", "lego", "blob000", "blob008", "plate", "tile", "slab", "fin", "panel", "wall"],
)
def test_symmetries_map_the_object_onto_itself(name):
    mesh = cases.load_mesh(name)
    for R in cases.object_spec(name).symmetry.rotations[1:]:
        assert is_symmetry(mesh, R)


@pytest.mark.parametrize(
    ("name", "size_mm"),
    [
        ("plate", (9, 90, 120)),
        ("tile", (10, 40, 80)),
        ("slab", (14, 50, 110)),
        ("fin", (15, 40, 120)),
        ("panel", (10, 60, 90)),
        ("wall", (12, 70, 130)),
    ],
)
def test_the_thin_objects_have_their_sizes_and_are_outside_the_benchmark_cycles(name, size_mm):
    mesh = cases.load_mesh(name)
    extent = np.sort(mesh.vertices.max(0) - mesh.vertices.min(0))
    np.testing.assert_allclose(extent, np.array(size_mm) * MM, atol=0.1 * MM)
    for family, objects in cases.FAMILY_OBJECTS.items():
        assert name not in objects, family


@pytest.mark.parametrize(("name", "height_mm"), [("fin", 120), ("panel", 60), ("wall", 70)])
def test_the_standing_thin_objects_stand_on_an_edge_or_an_end(name, height_mm):
    # In clutter an object keeps its model frame's up: its height is its z extent.
    mesh = cases.load_mesh(name)
    height = mesh.vertices[:, 2].max() - mesh.vertices[:, 2].min()
    assert height == pytest.approx(height_mm * MM, abs=0.1 * MM)


@pytest.mark.parametrize("name", ["mug", "blob004", "bunny"])
def test_asymmetric_objects_have_no_half_turn_symmetry(name):
    # The mug's handle breaks the turn about its axis, its open top the upside-down flip.
    mesh = cases.load_mesh(name)
    assert len(cases.OBJECTS[name].symmetry.rotations) == 1
    _, axes = np.linalg.eigh(np.cov(mesh.vertices.T))
    for axis in [*np.eye(3), *axes.T]:
        assert not is_symmetry(mesh, cases.axis_angle(axis, math.pi))


# --- Cases --------------------------------------------------------------------------------


def assert_true_transform_is_the_cell(case: cases.Case, angle: float, offset: float | None):
    R = case.T_true[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert cases.rotation_angle_deg(R) == pytest.approx(angle, abs=1e-6)
    moved = case.T_true @ np.append(case.model_center, 1.0)
    shift = np.linalg.norm(moved[:3] - case.model_center)
    assert shift <= cases.MAX_OFFSET + 1e-12 if offset is None else shift == pytest.approx(offset)


@pytest.mark.parametrize("angle", [10.0, 90.0, 180.0])
def test_full_case_truth_maps_the_model_onto_the_noisy_copy(angle):
    case = cases.make_case(cases.CaseSpec("full", "bunny", angle, 0))
    assert_true_transform_is_the_cell(case, angle, None)
    mesh = cases.load_mesh("bunny")
    # The model, moved by T_true, is exactly the placed object ...
    placed = to_object(case, cases.apply(case.T_true, case.model_points[:200]))
    assert np.max(mesh_distance(mesh, placed)) < 1e-6
    normals = case.model_normals @ case.T_true[:3, :3].T
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    # ... and the scene is that object with 1 mm Gaussian noise: |N(0, 1 mm)| has median 0.67 mm
    # along the normal (more near edges).
    offsets = mesh_distance(mesh, to_object(case, case.scene_points[:300]))
    assert 0.5 * MM < np.median(offsets) < 0.9 * MM
    assert np.max(offsets) < 5 * MM
    # Estimated scene normals are unit and agree with the surface's orientation.
    scene_n = case.scene_normals @ np.linalg.inv(np.asarray(case.info["T_scene_object"]))[:3, :3].T
    np.testing.assert_allclose(np.linalg.norm(scene_n, axis=1), 1.0, atol=1e-9)


def test_translation_sweep_sets_the_exact_offset():
    case = cases.make_case(cases.CaseSpec("full", "bunny", 30.0, 0, offset=0.15))
    assert_true_transform_is_the_cell(case, 30.0, 0.15)


def test_pose_error_measures_rotation_and_centroid_translation():
    case = cases.make_case(cases.CaseSpec("full", "bunny", 60.0, 1))
    assert case.symmetries.shape == (1, 4, 4)
    assert cases.pose_error(case, case.T_true) == pytest.approx((0.0, 0.0), abs=1e-6)
    turn = cases.rotation_about(cases.axis_angle([0, 0, 1], math.radians(3.0)), case.model_center)
    rotation, translation = cases.pose_error(case, case.T_true @ turn)
    assert rotation == pytest.approx(3.0) and translation == pytest.approx(0.0, abs=1e-9)
    shifted = case.T_true.copy()
    shifted[:3, 3] += [0.007, 0.0, 0.0]
    assert cases.pose_error(case, shifted) == pytest.approx((0.0, 0.007), abs=1e-9)


def test_symmetric_poses_score_zero_and_the_group_is_in_model_coordinates():
    case = cases.make_case(cases.CaseSpec("full", "jenga", 120.0, 2))
    assert len(case.symmetries) == 4
    mesh = cases.load_mesh("jenga")
    for S in case.symmetries:
        assert cases.pose_error(case, case.T_true @ S) == pytest.approx((0.0, 0.0), abs=1e-5)
        moved = to_object(case, cases.apply(case.T_true @ S, case.model_points[:100]))
        assert np.max(mesh_distance(mesh, moved)) < 1e-6
    flipped = case.T_true @ case.symmetries[1]
    R = flipped[:3, :3].T @ case.T_true[:3, :3]
    assert cases.rotation_angle_deg(R) == pytest.approx(180.0)


@pytest.mark.parametrize("name", ["bunny", "mug"])
def test_partial_scan_is_a_subset_of_the_surface_facing_the_camera(name):
    spec = cases.CaseSpec("partial", name, 60.0, 3)
    case = cases.partial_case(spec, noise=False)
    mesh = cases.load_mesh(name)
    points = to_object(case, case.scene_points)
    sample = points[:: max(1, len(points) // 400)]
    distance = mesh_distance(mesh, sample)
    assert np.percentile(distance, 99) < 0.5 * MM
    # Every scan point sees the camera: the surface there faces it.
    camera = to_object(case, case.viewpoint[None])[0]
    normals = case.scene_normals @ np.linalg.inv(np.asarray(case.info["T_scene_object"]))[:3, :3].T
    facing = np.einsum("ij,ij->i", normals, camera - points)
    assert np.mean(facing > 0.0) == 1.0
    # The scan covers less than the whole object and lies 0.4-0.8 m from the camera.
    full, _ = cases.sample_surface(mesh, 3000, np.random.default_rng(5))
    seen = nearest_distance(full, sample) < 5 * MM
    assert 0.1 < seen.mean() < 0.8
    assert 0.35 < np.linalg.norm(camera) < 0.85


def test_noisy_partial_scan_stays_near_the_surface():
    case = cases.make_case(cases.CaseSpec("partial", "duck", 90.0, 4))
    assert_true_transform_is_the_cell(case, 90.0, None)
    mesh = cases.load_mesh("duck")
    sample = to_object(case, case.scene_points[:: max(1, len(case.scene_points) // 300)])
    assert np.median(mesh_distance(mesh, sample)) < 1.5 * MM
    assert len(case.scene_points) >= cases.MIN_SCAN_POINTS


def test_clutter_case_shows_the_target_among_others_on_a_table():
    case = cases.make_case(cases.CaseSpec("clutter", "blob004", 150.0, 5))
    assert_true_transform_is_the_cell(case, 150.0, None)
    assert 4 <= len(case.info["objects"]) <= 6 and case.info["objects"][0] == "blob004"
    assert case.info["visible_fraction"] >= cases.MIN_VISIBLE
    # The table top is in view, and the target rests on it.
    assert np.mean(np.abs(case.scene_points[:, 2]) < 2 * MM) > 0.2
    placed = cases.apply(case.T_true, case.model_points)
    assert placed[:, 2].min() == pytest.approx(0.0, abs=1e-9)
    # The placed model lies on the scene where the camera sees it.
    near = nearest_distance(placed[::10], case.scene_points[::3]) < 4 * MM
    assert 0.1 < near.mean() < 0.8


@pytest.mark.parametrize("family", ["full", "partial", "clutter", "milk"])
def test_a_seed_fixes_the_case(family, data_dir):
    obj = "milk" if family == "milk" else "lego"
    spec = cases.CaseSpec(family, obj, 120.0, 7)
    first, second = cases.make_case(spec), cases.make_case(spec)
    assert first.seed == spec.seed
    for field in ("model_points", "model_normals", "scene_points", "scene_normals", "T_true"):
        np.testing.assert_array_equal(getattr(first, field), getattr(second, field))
    other = cases.make_case(cases.CaseSpec(family, obj, 120.0, 8))
    assert not np.array_equal(first.T_true, other.T_true)


def test_milk_model_and_scene_are_disjoint_halves_of_the_kinect_scan(data_dir):
    case = cases.make_case(cases.CaseSpec("milk", "milk", 90.0, 0))
    assert_true_transform_is_the_cell(case, 90.0, None)
    placed = cases.apply(case.T_true, case.model_points)
    # No model point is a scene point; each has a scene neighbour from the other half.
    distance = nearest_distance(placed[::29], case.scene_points)
    assert distance.min() > 1e-7
    assert np.median(distance) < 3 * MM
    assert np.allclose(case.T_true @ np.append(case.model_center, 1), np.append(placed.mean(0), 1))


def test_bunny_scan_halves_come_back_together(data_dir):
    case = cases.make_case(cases.CaseSpec("bunny_scan", "bunny_scan", 180.0, 0))
    assert_true_transform_is_the_cell(case, 180.0, None)
    placed = cases.apply(case.T_true, case.model_points)
    assert np.median(nearest_distance(placed, case.scene_points)) < 10 * MM  # sparse scan


def test_case_round_trips_through_npz(tmp_path):
    case = cases.make_case(cases.CaseSpec("full", "lego", 30.0, 0))
    cases.save_case(case, tmp_path / "case.npz")
    loaded = cases.load_case(tmp_path / "case.npz")
    assert loaded.case_id == case.case_id and loaded.info == case.info
    np.testing.assert_array_equal(loaded.symmetries, case.symmetries)
    np.testing.assert_array_equal(loaded.scene_points, case.scene_points)


# --- The held-out validation set ----------------------------------------------------------


def test_the_held_out_objects_are_new_meshes_and_enough_of_them():
    held = cases.HELDOUT_OBJECTS
    assert len(held) >= 6
    used = {spec.obj for spec in cases.OBJECTS.values()}
    assert not used & {spec.obj for spec in held.values()}
    assert not set(held) & set(cases.OBJECTS)
    for family in cases.HELDOUT_FAMILIES:
        assert set(cases.FAMILY_OBJECTS[family]) == set(held)
        assert family not in cases.TUNING_FAMILIES


@pytest.mark.parametrize("name", list(cases.HELDOUT_OBJECTS))
def test_held_out_objects_have_their_stated_symmetries_only(name):
    mesh = cases.load_mesh(name)
    extent = mesh.vertices.max(0) - mesh.vertices.min(0)
    assert 0.08 - 1e-9 <= extent.max() <= 0.25 + 1e-9
    rotations = cases.HELDOUT_OBJECTS[name].symmetry.rotations
    for R in rotations[1:]:
        assert is_symmetry(mesh, R)
    if len(rotations) == 1:
        _, axes = np.linalg.eigh(np.cov(mesh.vertices.T))
        for axis in [*np.eye(3), *axes.T]:
            assert not is_symmetry(mesh, cases.axis_angle(axis, math.pi))


@pytest.mark.parametrize("family", ["heldout_full", "heldout_partial", "heldout_clutter"])
def test_held_out_cases_are_built_in_each_condition(family):
    spec = cases.CaseSpec(family, "panda_link3", 90.0, 0)
    case = cases.make_case(spec)
    assert case.condition == cases.CONDITIONS[family]
    # T_true maps the model onto the scene: the nearest scene point of a model point moved
    # by it is within the noise and sampling (brute force on a subset).
    moved = cases.apply(case.T_true, case.model_points[::25])
    nearest = np.min(np.linalg.norm(moved[:, None] - case.scene_points[None, ::3], axis=2), axis=1)
    assert np.percentile(nearest, 50 if family == "heldout_full" else 10) < 5 * MM
    if family == "heldout_clutter":
        others = case.info["objects"][1:]
        assert 2 <= len(others) <= 3 and set(others) <= set(cases.HELDOUT_OBJECTS)
    # The same spec gives the same case.
    again = cases.make_case(spec)
    np.testing.assert_array_equal(case.scene_points, again.scene_points)
