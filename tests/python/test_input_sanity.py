"""Input sanity: each check names the argument, warns (InputWarning) or raises where it
should, and stays silent on the real Kinect scans of the shared data.

- a depth_scale that puts most valid depths outside 0.05-50 m (cloud_from_depth);
- (N, 6) arrays whose last columns are not unit normals (align, align_views);
- a sensor origin inside the cloud it orients normals toward (estimate_normals,
  align_views; align orients such a cloud outward);
- far outliers: one point at 1e12 m, or 1% of points up to 100 m away, change neither
  the other points' normals nor align's pose.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs
from spectral_vs import data

KINECT = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])


def rotation(axis, angle_deg: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    angle = np.radians(angle_deg)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def transform(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


@pytest.fixture(scope="module")
def kinect_frame(data_dir):
    """The milk-carton Kinect scan's z channel: metres, NaN where the sensor saw nothing."""
    return svs.load_organized(data_dir / "milk_cartoon_all_small_clorox.pcd")[..., 2]


def median_in(message: str) -> float:
    return float(re.search(r"median ([0-9.e+-]+) m", message).group(1))


# --- Depth scale ----------------------------------------------------------------------


def test_a_float_image_in_millimetres_warns_with_the_median_and_the_fix(kinect_frame):
    millimetres = (kinect_frame * 1000.0).astype(np.float32)  # read as metres by default
    median_mm = float(np.nanmedian(millimetres))  # 739 mm: the carton's table
    with pytest.warns(svs.InputWarning, match="depth_scale") as record:
        cloud = svs.cloud_from_depth(millimetres, KINECT)
    message = str(record[0].message)
    assert record[0].filename == __file__  # the caller's line
    assert "needs depth_scale=1000" in message
    assert median_in(message) == pytest.approx(median_mm, abs=0.5)  # metres, 1000 x too far
    assert len(cloud) > 100_000  # the cloud is still returned
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        right = svs.cloud_from_depth(millimetres, KINECT, depth_scale=1000.0)
    assert np.median(right.points[:, 2]) == pytest.approx(median_mm / 1000.0, abs=0.01)


@pytest.mark.parametrize(
    ("dtype", "scale", "fix"),
    [
        (np.uint16, 0.001, "needs depth_scale=1000"),  # 1 / 1000 given for 1000: 739 km
        (np.uint16, 1e6, "too large"),  # micrometres assumed: 0.74 mm
        (np.float32, 1000.0, "a float image in metres needs depth_scale=1"),  # metres / 1000
    ],
)
def test_a_wrong_depth_scale_warns(kinect_frame, dtype, scale, fix):
    metres = np.nan_to_num(kinect_frame, nan=0.0)
    image = np.round(metres * 1000.0).astype(dtype) if dtype == np.uint16 else metres
    image = image.astype(dtype)
    with pytest.warns(svs.InputWarning, match=re.escape(f"depth_scale: {scale:g} ")) as record:
        svs.cloud_from_depth(image, KINECT, depth_scale=scale, normals=False)
    message = str(record[0].message)
    assert fix in message
    unit = 1000.0 if dtype == np.uint16 else 1.0
    assert median_in(message) == pytest.approx(0.739 * unit / scale, rel=0.01)
    with pytest.warns(svs.InputWarning, match="depth_scale"):  # organized too
        svs.cloud_from_depth(image, KINECT, depth_scale=scale, organized=True)


def test_right_scales_and_the_real_frame_do_not_warn(kinect_frame):
    metres = np.nan_to_num(kinect_frame, nan=0.0)
    raw = np.round(metres * 1000.0).astype(np.uint16)
    tum = np.round(metres * 5000.0).astype(np.uint16)
    valid = int(np.count_nonzero(raw))
    # pytest's filterwarnings = error turns any warning here into a failure.
    svs.cloud_from_depth(raw, KINECT)
    svs.cloud_from_depth(tum, KINECT, depth_scale=5000.0)
    svs.cloud_from_depth(metres.astype(np.float32), KINECT)
    check = svs.check_depth_scale(raw)
    assert (check.depth_scale, check.valid, check.plausible, check.ok) == (
        1000.0,
        valid,
        valid,
        True,
    )
    check = svs.check_depth_scale(metres, depth_scale=1000.0)
    assert (check.valid, check.plausible, check.ok) == (valid, 0, False)


def test_the_warning_needs_over_half_of_the_depths_out_of_range():
    depth = np.full((100, 100), 1.0)
    depth[:50] = 100.0  # half at 100 m: half plausible, not over half
    with pytest.warns(svs.InputWarning, match="5000 of the 10000 valid depths"):
        svs.cloud_from_depth(depth, KINECT, normals=False)
    depth[49] = 1.0  # 5100 at 1 m
    check = svs.check_depth_scale(depth)
    assert (check.valid, check.plausible, check.ok) == (10000, 5100, True)
    svs.cloud_from_depth(depth, KINECT, normals=False)  # no warning
    depth[:, :10] = 0.0  # no return: not counted
    assert svs.check_depth_scale(depth).valid == 9000


# --- (N, 6) arrays ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def object_and_view():
    """The box-and-ball model (no normals), centred near the origin, and a single view of
    it moved 0.9 m in front of the camera, with the true T_scene_model."""
    rng = np.random.default_rng(5)
    model, _ = box_and_sphere(rng)
    points, normals = box_and_sphere(rng)
    T = transform(rotation([1.0, -2.0, 0.5], 70.0), [0.08, -0.04, 0.9])
    points = points @ T[:3, :3].T + T[:3, 3]
    normals = normals @ T[:3, :3].T
    facing = np.einsum("ij,ij->i", normals, -points) > 0  # the faces toward the camera
    return model, points[facing], normals[facing], T


@pytest.mark.parametrize(
    ("colours", "reason"),
    [
        (lambda rng, n: rng.uniform(0, 1, (n, 3)), "lengths are not 1"),
        (lambda rng, n: rng.integers(0, 256, (n, 3)).astype(float), "lengths are not 1"),
        (lambda rng, n: np.full((n, 3), 0.55), "all three columns are >= 0"),  # grey, 0.95
    ],
)
def test_colours_in_an_n_by_6_array_are_refused_naming_the_argument(
    object_and_view, colours, reason
):
    model, scene, _, _ = object_and_view
    rng = np.random.default_rng(1)
    coloured = np.hstack([scene, colours(rng, len(scene))])
    with pytest.raises(ValueError, match=f"^scene: .*{reason}.*PointCloud\\(points, normals\\)"):
        svs.align(model, coloured)
    with pytest.raises(ValueError, match=f"^reference: .*{reason}"):
        svs.align_views(coloured, scene)
    svs.PointCloud(coloured[:, :3], coloured[:, 3:])  # the explicit form is taken as given


def test_unit_and_slightly_non_unit_normals_are_taken(object_and_view):
    _, scene, normals, _ = object_and_view
    rng = np.random.default_rng(2)
    scaled = normals * rng.uniform(0.9, 1.1, (len(normals), 1))
    cloud = svs.clouds.as_cloud(np.hstack([scene, scaled]), "scene")
    np.testing.assert_allclose(cloud.normals, normals, rtol=0, atol=1e-12)  # normalised
    # Unit normals all in one octant, all >= 0 (a plane facing +x +y +z), are normals.
    facing = np.tile(np.ones(3) / np.sqrt(3.0), (100, 1))
    plane = rng.uniform(-0.1, 0.1, (100, 3))
    svs.clouds.as_cloud(np.hstack([plane, facing]), "scene")
    with pytest.raises(ValueError, match=r"^scene: .*all three columns are >= 0"):
        svs.clouds.as_cloud(np.hstack([plane, facing * 0.95]), "scene")


# --- Sensor origin inside the cloud ------------------------------------------------------


def test_estimate_normals_warns_of_a_viewpoint_inside_the_cloud(object_and_view):
    model = svs.PointCloud(object_and_view[0])
    with pytest.warns(svs.InputWarning, match=r"^viewpoint \[0.0, 0.0, 0.0\] lies inside") as w:
        inward = svs.estimate_normals(model, radius=0.015)
    assert "orientation='outward'" in str(w[0].message)
    outward = svs.estimate_normals(model, radius=0.015, orientation="outward")  # no warning
    # Toward the centre, most normals of this closed model point into it.
    centre = np.asarray(model.points).mean(axis=0)
    into = np.einsum("ij,ij->i", inward.normals, inward.points - centre) < 0
    out = np.einsum("ij,ij->i", outward.normals, outward.points - centre) > 0
    assert into.mean() > 0.85 and out.mean() > 0.95  # 88% and 99%
    svs.estimate_normals(model, radius=0.015, viewpoint=(0.0, 0.0, 2.0))  # outside: silent


def test_real_scans_raise_no_warning(data_dir):
    # The organized Kinect scans in their camera frame: the sensor is outside their box.
    # pytest's filterwarnings = error makes any warning a failure.
    for name in ("five_people.pcd", "milk_cartoon_all_small_clorox.pcd", "milk.pcd"):
        cloud = svs.voxel_downsample(svs.load_cloud(data_dir / name), 0.01)
        svs.estimate_normals(cloud, radius=0.03)
        svs.estimate_normals(cloud, k_neighbors=20)
    scene = svs.load_cloud(data_dir / "milk_cartoon_all_small_clorox.pcd")
    model = svs.load_cloud(data_dir / "milk.pcd")
    result = svs.align(model, scene)  # the carton cut from that scan: the identity
    assert svs.pose_error(result.T_scene_model).rotation_deg < 1.0
    pair = data.make_view_pair(svs.load_organized(data_dir / "five_people.pcd"), seed=1)
    svs.align_views(pair.reference, pair.current, sensor_origin=pair.current_viewpoint)


def test_align_orients_a_model_centred_at_the_origin_outward(object_and_view):
    """A model centred at the origin onto a single view of it: with its normals toward the
    origin (inside it) 0 of 12 such cases were right (147 degrees off at the median);
    outward, 12 of 12 (0.06 degree, 0.1 mm at the median)."""
    model, scene, _, T = object_and_view
    centre = model.mean(axis=0)
    voxel = svs.alignment_voxel_size(svs.PointCloud(model), svs.PointCloud(scene))
    result = svs.align(model, scene)  # no warning: oriented outward
    error = svs.pose_error(result.T_scene_model, T, center=centre)
    assert error.rotation_deg < 1.0 and error.translation_mm < 2.0
    with pytest.warns(svs.InputWarning, match="^viewpoint"):
        inward = svs.estimate_normals(
            svs.voxel_downsample(svs.PointCloud(model), voxel / 2), 2 * voxel
        )
    flipped = svs.align(inward, scene, voxel_size=voxel)
    assert svs.pose_error(flipped.T_scene_model, T, center=centre).rotation_deg > 30.0


def test_align_views_warns_of_a_sensor_origin_inside_a_view(object_and_view):
    model, scene, _, _ = object_and_view
    with pytest.warns(svs.InputWarning, match=r"^reference_sensor_origin \[0.0, 0.0, 0.0\]"):
        svs.align_views(model, scene, hypotheses=4)
    moved = scene - [0.0, 0.0, 0.9]  # the view's camera now inside its box
    with pytest.warns(svs.InputWarning, match=r"^sensor_origin .* bounding box of current"):
        svs.align_views(scene, moved, hypotheses=4)


# --- Far outliers ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def room_view(data_dir):
    """A Kinect view of a room (five_people.pcd) at 1 cm: 115 845 points, 1.8-9.8 m away."""
    return svs.voxel_downsample(svs.load_cloud(data_dir / "five_people.pcd"), 0.01)


def along_rays(points: np.ndarray, share: float, seed: int, keep_off: float) -> np.ndarray:
    """``share`` of len(points) outliers at random depths in 0.3-100 m along the rays of
    random points, none within ``keep_off`` of a point (grid cells of that size)."""
    rng = np.random.default_rng(seed)
    count = int(share * len(points))
    rays = points[rng.integers(0, len(points), 3 * count)]
    rays = rays / rays[:, 2:3] * rng.uniform(0.3, 100.0, (len(rays), 1))
    occupied = {tuple(c) for c in np.floor(points / keep_off).astype(np.int64)}
    cells = np.floor(rays / keep_off).astype(np.int64)
    offsets = np.array(np.meshgrid(*[[-1, 0, 1]] * 3)).reshape(3, -1).T
    far = [not any(tuple(c + o) in occupied for o in offsets) for c in cells]
    return rays[np.array(far)][:count]


def normals_by_point(cloud: svs.PointCloud) -> dict:
    return {p.tobytes(): n for p, n in zip(cloud.points, cloud.normals, strict=True)}


@pytest.mark.parametrize(
    ("search", "outliers"),
    [
        ({"radius": 0.03}, "1e12"),
        ({"k_neighbors": 20}, "1e12"),
        # Along the rays, 10 cm or more from every point: outside a 3 cm radius. (Twenty
        # nearest neighbours reach past 10 cm at the room's sparse edges, where an outlier
        # may rightly be one.)
        ({"radius": 0.03}, "1% along rays"),
    ],
)
def test_far_outliers_change_no_other_normal(room_view, search, outliers):
    """Before: one point at 1e12 m changed 57% of this view's normals with 20 neighbours,
    49% with a 3 cm radius (33% by more than 0.5 in a component: flipped or turned)."""
    points = room_view.points
    clean = normals_by_point(svs.estimate_normals(room_view, **search))
    assert len(clean) > 114_000
    extra = np.full((1, 3), 1e12) if outliers == "1e12" else along_rays(points, 0.01, 3, 0.1)
    assert len(extra) in (1, len(points) // 100)
    noisy = svs.estimate_normals(svs.PointCloud(np.vstack([points, extra])), **search)
    found = normals_by_point(noisy)
    assert set(clean) <= set(found)  # the same points have normals
    difference = max(np.abs(found[key] - n).max() for key, n in clean.items())
    assert difference < 1e-6


def test_a_far_point_leaves_a_small_plane_its_normals():
    """Before: 'no point has enough neighbours' (every float coordinate 256 m apart)."""
    rng = np.random.default_rng(4)
    plane = np.c_[rng.uniform(-0.1, 0.1, (500, 2)), np.ones(500)]
    clean = svs.estimate_normals(svs.PointCloud(plane), radius=0.03)
    noisy = svs.estimate_normals(svs.PointCloud(np.vstack([plane, [[1e12] * 3]])), radius=0.03)
    assert len(clean) == len(noisy) == 500
    np.testing.assert_allclose(noisy.normals, clean.normals, rtol=0, atol=1e-6)
    reduced = svs.voxel_downsample(svs.PointCloud(np.vstack([plane, [[-1e12] * 3]])), 0.01)
    expected = svs.voxel_downsample(svs.PointCloud(plane), 0.01).points
    np.testing.assert_array_equal(reduced.points[1:], expected)  # -1e12 first, by z index


def test_far_outliers_leave_the_pose_of_align(data_dir):
    """The carton moved by 60 degrees onto its scan: the scan with a point at 1e12 m (whose
    box the downsampling refused before), or with 1% of points up to 100 m away."""
    scene = svs.load_cloud(data_dir / "milk_cartoon_all_small_clorox.pcd").points[::2]
    model = svs.load_cloud(data_dir / "milk.pcd").points[1::2]
    centre = model.mean(axis=0)
    R = rotation([1.0, 1.0, 0.5], 60.0)
    moved = (model - centre) @ R.T + centre + [0.05, 0.03, -0.02]
    clean = svs.align(moved, scene)
    T_true = np.linalg.inv(transform(R, centre - R @ centre + [0.05, 0.03, -0.02]))
    assert svs.pose_error(clean.T_scene_model, T_true, center=centre).rotation_deg < 1.0
    for outliers in (np.full((1, 3), 1e12), along_rays(scene, 0.01, 5, 0.05)):
        result = svs.align(moved, np.vstack([scene, outliers]))
        error = svs.pose_error(result.T_scene_model, clean.T_scene_model, center=centre)
        assert error.rotation_deg < 0.5 and error.translation_mm < 1.0
