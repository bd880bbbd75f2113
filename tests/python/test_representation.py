"""Point clouds, files, preprocessing, voxel grids and the EGI from Python."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs


def test_point_cloud_from_numpy(rng):
    points, normals = box_and_sphere(rng, 100)
    cloud = svs.PointCloud(points, normals * 3.0)
    assert len(cloud) == 100
    assert cloud.has_normals
    np.testing.assert_array_equal(cloud.points, points)
    np.testing.assert_allclose(np.linalg.norm(cloud.normals, axis=1), 1.0, atol=1e-15)
    assert not cloud.points.flags.writeable
    assert svs.PointCloud(points).normals is None
    np.testing.assert_allclose(cloud.centroid(), points.mean(axis=0), atol=1e-15)


def test_point_cloud_accepts_float32_and_fortran_order(rng):
    points = np.asfortranarray(rng.normal(size=(50, 3)).astype(np.float32))
    cloud = svs.PointCloud(points)
    np.testing.assert_allclose(cloud.points, points.astype(np.float64))


def test_point_cloud_reads_every_layout_and_byte_order_alike(rng):
    # Read in place (float64, float32, any strides, unaligned) or cast (another byte
    # order, float16): the same values either way.
    frame = rng.normal(size=(40, 6))
    unaligned = np.frombuffer(b"\0" + frame.tobytes(), dtype=np.float64, offset=1)
    layouts = {
        "column views of (N, 6)": frame[:, :3],
        "every other row": np.repeat(frame, 2, axis=0)[::2, :3],
        "reversed rows": frame[::-1, :3][::-1],
        "transposed": np.ascontiguousarray(frame[:, :3].T).T,
        "unaligned": unaligned.reshape(40, 6)[:, :3],
        "big-endian": frame[:, :3].astype(">f8"),
    }
    for name, points in layouts.items():
        np.testing.assert_array_equal(svs.PointCloud(points).points, frame[:, :3], err_msg=name)
    single = frame[:, 3:].astype(np.float32)
    for points in (single, np.asfortranarray(single), single[:, ::-1][:, ::-1]):
        np.testing.assert_array_equal(svs.PointCloud(points).points, single.astype(np.float64))
    half = frame[:, :3].astype(np.float16)
    np.testing.assert_array_equal(svs.PointCloud(half).points, half.astype(np.float64))


@pytest.mark.parametrize(
    ("points", "message"),
    [
        (np.zeros((5, 2)), r"points must have shape \(N, 3\), got \(5, 2\)"),
        (np.zeros((5, 3), dtype=np.int64), "points must have a floating dtype"),
        (np.zeros(3), r"points must have shape \(N, 3\)"),
        (np.array([[0.0, 0.0, np.nan]]), "points: row 0 is not finite"),
    ],
)
def test_point_cloud_rejects_bad_arrays(points, message):
    with pytest.raises(ValueError, match=message):
        svs.PointCloud(points)


def test_point_cloud_drops_non_finite_on_request():
    points = np.array([[0.0, 0, 0], [np.nan, 0, 0], [1, 1, np.inf], [2, 2, 2]])
    cloud = svs.PointCloud(points, drop_non_finite=True)
    np.testing.assert_array_equal(cloud.points, [[0, 0, 0], [2, 2, 2]])
    with pytest.raises(ValueError, match="normals: row 1"):
        svs.PointCloud(np.zeros((2, 3)), np.array([[0.0, 0, 1], [0, 0, 0]]))


def test_transformed_checks_rigidity(rng):
    cloud = svs.PointCloud(rng.normal(size=(10, 3)))
    scaling = np.diag([2.0, 2.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="T_target_source is not a rigid transform"):
        cloud.transformed(scaling)
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    expected = cloud.points + np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(cloud.transformed(T).points, expected)


def test_load_milk_carton(data_dir):
    cloud, info = svs.load_cloud_with_info(data_dir / "milk.pcd")
    assert info.points_in_file == 13704
    assert len(cloud) + info.non_finite_dropped == info.points_in_file
    assert not cloud.has_normals
    assert np.isfinite(cloud.points).all()


def test_load_organized_scene_drops_nans(data_dir):
    cloud, info = svs.load_cloud_with_info(data_dir / "milk_cartoon_all_small_clorox.pcd")
    assert (info.width, info.height) == (640, 480)
    assert info.non_finite_dropped > 0
    assert len(cloud) == 640 * 480 - info.non_finite_dropped
    # Every point of the cut-out carton occurs verbatim in the scene (see shared/README.md).
    milk = svs.load_cloud(data_dir / "milk.pcd")
    scene_rows = {tuple(p) for p in cloud.points.astype(np.float32)}
    assert all(tuple(p) in scene_rows for p in milk.points.astype(np.float32)[:500])


def test_load_organized_keeps_the_pixel_grid(data_dir, tmp_path):
    path = data_dir / "milk_cartoon_all_small_clorox.pcd"
    grid = svs.load_organized(path)
    cloud, info = svs.load_cloud_with_info(path)
    assert grid.shape == (480, 640, 3)
    valid = np.isfinite(grid).all(axis=2)
    assert int((~valid).sum()) == info.non_finite_dropped
    # The finite pixels, in row-major order, are the points load_cloud returns.
    np.testing.assert_array_equal(grid[valid], cloud.points)
    # A pixel's point lies on its ray: column u at x / z = (u - cx) / fx, so x / z grows
    # along a row by the same step (1 / fx) everywhere (Kinect: fx about 525 pixels).
    v, u = np.nonzero(valid)
    slope = np.polyfit(u, grid[v, u, 0] / grid[v, u, 2], 1)[0]
    assert 1 / 600 < slope < 1 / 450
    # An unorganized file is one row.
    svs.save_cloud(tmp_path / "flat.pcd", svs.PointCloud(np.eye(3)), encoding="ascii")
    assert svs.load_organized(tmp_path / "flat.pcd").shape == (1, 3, 3)
    with pytest.raises(FileNotFoundError, match="no such file"):
        svs.load_organized(tmp_path / "missing.pcd")


def test_load_bunny_with_normals(data_dir):
    cloud, info = svs.load_cloud_with_info(data_dir / "bun0.pcd")
    assert info.had_normals
    assert cloud.has_normals
    assert len(cloud) == 397 - info.non_finite_dropped


@pytest.mark.parametrize(
    ("name", "encoding"),
    [("c.pcd", "ascii"), ("c.pcd", "binary"), ("c.pcd", "binary_compressed"), ("c.ply", "binary")],
)
def test_save_load_round_trip(tmp_path, rng, name, encoding):
    points, normals = box_and_sphere(rng, 200)
    cloud = svs.PointCloud(points, normals)
    svs.save_cloud(tmp_path / name, cloud, encoding=encoding)
    loaded = svs.load_cloud(tmp_path / name)
    np.testing.assert_allclose(loaded.points, points, atol=1e-7)  # float32 on disk: 0.1 um
    np.testing.assert_allclose(loaded.normals, cloud.normals, atol=1e-6)


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        svs.load_cloud(tmp_path / "missing.pcd")
    text = tmp_path / "notes.pcd"
    text.write_text("these are notes, not a point cloud\n")
    with pytest.raises(ValueError, match="is not a PCD file"):
        svs.load_cloud(text)
    wrong = tmp_path / "cloud.obj"
    wrong.write_text("v 0 0 0\n")
    with pytest.raises(ValueError, match="unsupported extension"):
        svs.load_cloud(wrong)
    with pytest.raises(ValueError, match="encoding must be"):
        svs.save_cloud(tmp_path / "x.pcd", svs.PointCloud(np.zeros((1, 3))), encoding="zip")


def test_voxel_downsample_bounds_spacing(rng):
    points = rng.uniform(0.0, 0.1, size=(20000, 3))
    reduced = svs.voxel_downsample(svs.PointCloud(points), 0.01)
    assert 900 <= len(reduced) <= 1000  # at most one point per 1 cm cell of a 10 cm cube
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="voxel_size"):
            svs.voxel_downsample(svs.PointCloud(points), bad)


def test_estimate_normals_toward_sensor(data_dir):
    milk = svs.load_cloud(data_dir / "milk.pcd")
    with_normals = svs.estimate_normals(milk, radius=0.01, threads=2)
    assert with_normals.has_normals
    to_sensor = -with_normals.points / np.linalg.norm(with_normals.points, axis=1, keepdims=True)
    assert (np.einsum("ij,ij->i", with_normals.normals, to_sensor) >= 0).all()
    with pytest.raises(ValueError, match="orientation must be"):
        svs.estimate_normals(milk, orientation="inward")
    with pytest.raises(ValueError, match="radius must be finite and > 0"):
        svs.estimate_normals(milk, radius=-0.01)


def test_empty_and_all_nan_clouds_are_refused():
    empty = svs.PointCloud(np.zeros((0, 3)))
    assert len(empty) == 0
    with pytest.raises(ValueError, match="cloud is empty"):
        svs.voxel_downsample(empty, 0.01)
    with pytest.raises(ValueError, match="cloud is empty"):
        svs.estimate_normals(empty)
    all_nan = svs.PointCloud(np.full((10, 3), np.nan), drop_non_finite=True)
    with pytest.raises(ValueError, match="cloud is empty"):
        svs.make_grid_spec(all_nan, all_nan, 0.01)


def test_grid_spec_limits_and_fft_sizes(rng):
    points, _ = box_and_sphere(rng, 500)
    cloud = svs.PointCloud(points)
    spec = svs.make_grid_spec(cloud, cloud, 0.008)
    assert all(svs.fft_friendly_size(int(n)) == n for n in spec.dims)
    with pytest.raises(ValueError, match=r"exceeds the limit of 16777216 voxels"):
        svs.make_grid_spec(cloud, cloud, 0.0005)
    with pytest.raises(ValueError, match="limit of 1000 voxels"):
        svs.make_grid_spec(cloud, cloud, 0.008, max_voxels=1000)
    with pytest.raises(ValueError, match="resolution must be finite and > 0"):
        svs.make_grid_spec(cloud, cloud, np.nan)


def test_voxelize_matches_numpy_histogram(rng):
    points, _ = box_and_sphere(rng, 3000)
    cloud = svs.PointCloud(points)
    spec = svs.make_grid_spec(cloud, cloud, 0.01)
    index = np.floor((points - spec.origin) / spec.resolution).astype(int)
    expected = np.zeros(tuple(spec.dims))
    np.add.at(expected, tuple(index.T), 1.0)
    np.testing.assert_array_equal(svs.voxelize(cloud, spec, occupancy="count").values, expected)
    np.testing.assert_array_equal(svs.voxelize(cloud, spec).values, expected > 0)
    trilinear = svs.voxelize(cloud, spec, occupancy="trilinear").values
    assert trilinear.sum() == pytest.approx(len(points), rel=1e-5)


def test_egi_histogram(rng):
    _, normals = box_and_sphere(rng, 4000)
    bandwidth = 8
    histogram = svs.egi(normals, bandwidth)
    assert histogram.shape == (16, 16)
    assert histogram.sum() == 4000
    theta, phi = svs.sphere_grid(bandwidth)
    np.testing.assert_allclose(theta, np.pi * (2 * np.arange(16) + 1) / 32)
    np.testing.assert_allclose(phi, np.pi * np.arange(16) / 8)
    # A normal along +y lies at theta = pi/2 (row B), phi = pi/2 (column B/2).
    single = svs.egi(np.array([[0.0, 1.0, 0.0]]), bandwidth)
    assert single[8, 4] == 1 and single.sum() == 1
    # Rotating every normal about z by 2 pi / 2B moves every count one column on
    # (random directions: the poles of the box's normals have no longitude to move).
    normals = rng.normal(size=(4000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    histogram = svs.egi(normals, bandwidth)
    angle = np.pi / bandwidth
    Rz = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    rotated = svs.egi(normals @ Rz.T, bandwidth)
    np.testing.assert_array_equal(rotated, np.roll(histogram, 1, axis=1))
    weighted = svs.egi(normals, bandwidth, weights=np.full(4000, 0.5))
    np.testing.assert_allclose(weighted, histogram / 2)


def test_egi_errors(rng):
    with pytest.raises(ValueError, match=r"bandwidth must be in \[1, 128\], got 0"):
        svs.egi(np.array([[0.0, 0, 1]]), 0)
    with pytest.raises(ValueError, match="cloud has no normals"):
        svs.egi(svs.PointCloud(np.zeros((3, 3))), 8)


def test_select_keeps_the_masked_rows_in_order():
    """PointCloud.select against numpy masking (points to 0 mm, normals exactly)."""
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.0, 2.0, (5000, 3))
    normals = rng.normal(size=(5000, 3))
    cloud = svs.PointCloud(points, normals)
    keep = points[:, 2] <= 1.5
    selected = cloud.select(keep)
    assert len(selected) == int(keep.sum())
    np.testing.assert_array_equal(selected.points, points[keep])
    np.testing.assert_array_equal(selected.normals, np.asarray(cloud.normals)[keep])
    assert svs.PointCloud(points).select(keep).normals is None
    assert len(cloud.select(np.zeros(5000, dtype=bool))) == 0
    with pytest.raises(ValueError, match="one entry per point"):
        cloud.select(keep[:-1])


def test_dominant_plane_finds_a_table_under_clutter():
    """A plane 0.55 m along (0.2, -0.3, 1) under 1000 clutter points with random normals:
    its normal within 0.1 degree, its offset within a 1 mm bin, its share 3000/4000 (and
    the few clutter points on it); None when it must hold 90% of the points."""
    rng = np.random.default_rng(5)
    n = np.array([0.2, -0.3, 1.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    a, b = rng.uniform(-0.3, 0.3, (2, 3000, 1))
    plane = 0.55 * n + a * u + b * v
    clutter = rng.uniform(-0.3, 0.3, (1000, 3))
    normals = np.vstack([np.tile(n, (3000, 1)), rng.normal(size=(1000, 3))])
    normals /= np.linalg.norm(normals, axis=1)[:, None]  # unit, as the cloud stores them
    cloud = svs.PointCloud(np.vstack([plane, clutter]), normals)
    found = svs.dominant_plane(cloud, offset_bin=0.001, band=0.002)
    assert found is not None
    assert np.degrees(np.arccos(min(1.0, float(found.normal @ n)))) < 0.1
    assert found.offset == pytest.approx(0.55, abs=0.001)
    assert 3000 <= found.count < 3020 and found.share == pytest.approx(found.count / 4000)
    axis, share = svs.dominant_direction(normals)
    assert np.degrees(np.arccos(min(1.0, float(axis @ n)))) < 0.1
    assert share == pytest.approx(0.75 + 0.25 * (1 - np.cos(np.radians(20))) / 2, abs=0.01)
    assert svs.dominant_plane(cloud, offset_bin=0.001, band=0.002, min_share=0.9) is None
    with pytest.raises(ValueError, match="offset_bin must be finite and > 0 m"):
        svs.dominant_plane(cloud, offset_bin=0.0)


def test_prepare_cloud_is_the_registrations_preparation():
    # A 0.1 m square at z = 1 m every 5 mm: at a 20 mm voxel, 10 mm cubes of 2 x 2 points.
    grid = (np.arange(20) + 0.5) * 0.005
    x, y = np.meshgrid(grid, grid)
    square = svs.PointCloud(np.c_[x.ravel(), y.ravel(), np.ones(400)])
    prepared = svs.prepare_cloud(square, 0.02, viewpoint=(0.0, 0.0, 0.0))
    assert len(prepared) == 100
    np.testing.assert_allclose(
        np.sort(np.unique(prepared.points[:, 0])), (np.arange(10) + 0.5) * 0.01
    )
    np.testing.assert_allclose(prepared.normals[:, 2], -1.0, atol=1e-9)  # toward the sensor
    # align()'s own preparation is the same call: its model, downsampled, is this cloud.
    from spectral_vs.registration import prepare

    again = prepare(square, "model", 0.02, True, (0.0, 0.0, 0.0))
    assert np.array_equal(again.points, prepared.points)
    assert np.array_equal(again.normals, prepared.normals)
    with pytest.raises(ValueError, match=r"^model is empty"):
        svs.prepare_cloud(svs.PointCloud(np.zeros((0, 3))), 0.02, argument="model")
    line = svs.PointCloud(np.c_[np.arange(50) * 0.001, np.zeros(50), np.ones(50)])
    with pytest.raises(ValueError, match=r"^scene: estimating normals over a radius of 2 x"):
        svs.prepare_cloud(line, 0.01, downsample=False, argument="scene")
