"""cloud_from_depth from Python: a real Kinect frame rebuilt as the sensor's uint16 image,
closed forms (a tilted plane, a sphere), the units, the organized output and bad input.

The Kinect scans of the shared data are organized 640 x 480 clouds whose depths are whole
millimetres, taken with fx = fy = 525 and the principal point (319.5, 239.5) (recovered
from the points to 1e-5 pixel by least squares): their z channel in millimetres is the
sensor's raw frame.
"""

from __future__ import annotations

import numpy as np
import pytest

import spectral_vs as svs

KINECT = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])
SKEWED = np.array([[525.0, 0.5, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])
NOT_FINITE = np.array([[525.0, 0.0, np.nan], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise angles between unit vectors, degrees."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(cross, np.sum(a * b, axis=-1)))


def rays(K: np.ndarray, height: int, width: int) -> np.ndarray:
    v, u = np.mgrid[0:height, 0:width]
    return np.stack(
        [(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((height, width))], axis=-1
    )


def plane_depth(n: np.ndarray, offset: float, K=KINECT, shape=(480, 640)) -> np.ndarray:
    """Depth of the plane n . x = offset: z = offset / (n . ray)."""
    return offset / (rays(K, *shape) @ n)


def sphere_depth(center: np.ndarray, radius: float, K=KINECT, shape=(480, 640)) -> np.ndarray:
    """Depth of the nearer intersection of each ray with a sphere, NaN where it misses."""
    r = rays(K, *shape)
    a, b = np.sum(r * r, axis=-1), -2.0 * (r @ center)
    c = center @ center - radius**2
    discriminant = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        return np.where(discriminant >= 0, (-b - np.sqrt(discriminant)) / (2 * a), np.nan)


@pytest.fixture(scope="module")
def milk_scan(data_dir):
    """The milk-carton Kinect scan: its organized points and its raw uint16 frame."""
    points = svs.load_organized(data_dir / "milk_cartoon_all_small_clorox.pcd")
    z = points[..., 2]
    raw = np.where(np.isfinite(z), np.round(z * 1000.0), 0).astype(np.uint16)
    return points, raw


def test_a_kinect_frame_gives_back_the_scan(milk_scan):
    points, raw = milk_scan
    organized = svs.cloud_from_depth(raw, KINECT, organized=True, normals=False)
    assert (organized.height, organized.width) == (480, 640)
    assert organized.normals is None
    # NaN exactly where the sensor had no return, and the scan's points elsewhere (it
    # stores float32: 1e-6 relative, 2 micrometres at its farthest 2 m).
    np.testing.assert_array_equal(np.isnan(organized.points[..., 2]), np.isnan(points[..., 2]))
    np.testing.assert_array_equal(organized.valid, np.isfinite(points[..., 2]))
    valid = organized.valid
    np.testing.assert_allclose(organized.points[valid], points[valid], rtol=0, atol=5e-6)
    # The unorganized default: the pixels with a normal, in row-major order.
    cloud = svs.cloud_from_depth(raw, KINECT)
    with_normals = svs.cloud_from_depth(raw, KINECT, organized=True)
    assert len(cloud) == with_normals.valid.sum() > 0.9 * valid.sum()
    np.testing.assert_array_equal(cloud.points, with_normals.points[with_normals.valid])
    np.testing.assert_array_equal(with_normals.valid_cloud().points, cloud.points)
    np.testing.assert_array_equal(with_normals.valid_cloud().normals, cloud.normals)
    # A cloud's normals are renormalised on construction: the same to the last bit or two.
    np.testing.assert_allclose(
        cloud.normals, with_normals.normals[with_normals.valid], rtol=0, atol=1e-15
    )


def test_kinect_normals_agree_with_the_plane_fit_normals(milk_scan):
    # An independent estimate: PCL's plane fits over the 30 nearest neighbours, turned
    # toward the sensor. Measured: median 4.2 degrees apart, 98% within 20 (the stencil
    # and the neighbourhood see the 1 mm depth steps at different scales).
    _, raw = milk_scan
    cloud = svs.cloud_from_depth(raw, KINECT, stride=2)
    fitted = svs.estimate_normals(svs.PointCloud(cloud.points), k_neighbors=30)
    normals = np.asarray(cloud.normals)
    errors = angle_deg(normals, np.asarray(fitted.normals))
    assert np.all(np.sum(normals * np.asarray(cloud.points), axis=1) < 0)  # toward the camera
    assert np.median(errors) < 6.0
    assert np.mean(errors < 20.0) > 0.95


def test_tilted_plane_points_and_normals_in_metres_and_millimetres():
    n = np.array([0.0, np.sin(np.radians(30.0)), -np.cos(np.radians(30.0))])  # faces the camera
    offset = -0.7
    depth = plane_depth(n, offset)
    for image in (depth, depth.astype(np.float32)):
        cloud = svs.cloud_from_depth(image, KINECT)
        assert len(cloud) == (480 - 4) * (640 - 4)  # all but the stencil's border
        tolerance = 1e-9 if image.dtype == np.float64 else 1e-6  # float32 rounds the depth
        np.testing.assert_allclose(np.asarray(cloud.points) @ n, offset, rtol=0, atol=tolerance)
        assert angle_deg(np.asarray(cloud.normals), n).max() < 0.5
    raw = np.round(depth * 1000.0).astype(np.uint16)
    cloud = svs.cloud_from_depth(raw, KINECT)
    points = np.asarray(cloud.points)
    # Each point is its pixel's ray at the stored millimetres.
    expected = (rays(KINECT, 480, 640) * (raw / 1000.0)[..., None])[2:-2, 2:-2].reshape(-1, 3)
    np.testing.assert_allclose(points, expected, rtol=0, atol=1e-12)
    mean = np.asarray(cloud.normals).mean(axis=0)
    assert angle_deg(mean / np.linalg.norm(mean), n) < 0.5


def test_sphere_normals_are_radial():
    center, radius = np.array([-0.04, 0.02, 0.8]), 0.15
    cloud = svs.cloud_from_depth(sphere_depth(center, radius), KINECT)
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    radial = (points - center) / np.linalg.norm(points - center, axis=1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(points - center, axis=1), radius, atol=1e-9)
    errors = angle_deg(normals, radial)
    facing = angle_deg(radial, -points / np.linalg.norm(points, axis=1, keepdims=True)) < 60.0
    assert facing.sum() > 0.7 * len(points)
    assert errors[facing].max() < 0.5
    assert errors.max() < 3.0


def test_depth_scale_min_max_depth_and_stride():
    depth = np.full((30, 40), 1200, dtype=np.uint16)  # 1.2 m in millimetres
    depth[:, 20:] = 6000  # 6 m at 1000 units per metre; 1.2 m at 5000
    z = np.asarray(svs.cloud_from_depth(depth, KINECT, normals=False).points)[:, 2]
    np.testing.assert_array_equal(np.unique(z), [1.2, 6.0])
    z = np.asarray(svs.cloud_from_depth(depth, KINECT, normals=False, depth_scale=5000).points)
    np.testing.assert_array_equal(np.unique(z[:, 2]), [0.24, 1.2])
    near = svs.cloud_from_depth(depth, KINECT, normals=False, max_depth=3.0)
    assert len(near) == 30 * 20
    far = svs.cloud_from_depth(depth, KINECT, normals=False, min_depth=3.0)
    assert len(far) == 30 * 20
    # A float image in millimetres, with its scale.
    mm = svs.cloud_from_depth(depth.astype(np.float32), KINECT, depth_scale=1000.0, normals=False)
    np.testing.assert_array_equal(
        mm.points, svs.cloud_from_depth(depth, KINECT, normals=False).points
    )
    # Stride: the lattice of every third pixel, ceil(30 / 3) x ceil(40 / 3).
    strided = svs.cloud_from_depth(depth, KINECT, stride=3, organized=True, normals=False)
    assert (strided.height, strided.width) == (10, 14)
    full = svs.cloud_from_depth(depth, KINECT, organized=True, normals=False)
    np.testing.assert_array_equal(strided.points, full.points[::3, ::3])
    # The truncated part counts as missing for its neighbours' normals: the columns within
    # normal_step = 2 of the cut have none.
    cut = svs.cloud_from_depth(depth, KINECT, organized=True, max_depth=3.0)
    has_normal = np.isfinite(cut.normals[..., 0])
    assert has_normal[2:-2, 2:18].all() and not has_normal[:, 18:].any()


def test_invalid_pixels_are_dropped():
    depth = np.full((20, 20), 0.9)
    depth[3, 4], depth[5, 6], depth[7, 8], depth[9, 10] = np.nan, np.inf, 0.0, -1.0
    cloud = svs.cloud_from_depth(depth, KINECT, normals=False)
    assert len(cloud) == 400 - 4
    organized = svs.cloud_from_depth(depth, KINECT, organized=True, normals=False)
    assert np.isnan(organized.points[[3, 5, 7, 9], [4, 6, 8, 10]]).all()
    assert organized.valid.sum() == 396
    assert organized.points.flags.writeable is False


def test_an_open3d_camera_is_taken_for_its_matrix():
    o3d = pytest.importorskip("open3d")
    intrinsic = o3d.camera.PinholeCameraIntrinsic(
        o3d.camera.PinholeCameraIntrinsicParameters.PrimeSenseDefault
    )
    depth = np.full((480, 640), 1000, dtype=np.uint16)
    ours = svs.cloud_from_depth(depth, intrinsic, normals=False)
    np.testing.assert_array_equal(
        ours.points,
        svs.cloud_from_depth(depth, intrinsic.intrinsic_matrix, normals=False).points,
    )
    # Open3D's own back-projection of the same frame (its depth_scale is also 1000).
    theirs = o3d.geometry.PointCloud.create_from_depth_image(o3d.geometry.Image(depth), intrinsic)
    np.testing.assert_allclose(ours.points, np.asarray(theirs.points), rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("depth", "K", "message"),
    [
        (np.ones(5), KINECT, r"depth must be a 2-D image \(height, width\), got shape \(5,\)"),
        (np.ones((2, 3, 4)), KINECT, r"2-D image .* got shape \(2, 3, 4\)"),
        (np.ones((5, 5), dtype=np.int64), KINECT, "depth must have dtype uint16 .* got int64"),
        (np.ones((5, 5), dtype=bool), KINECT, "depth must have dtype uint16"),
        (np.ones((5, 5), dtype=np.float16), KINECT, "got float16"),
        (np.ones((0, 5)), KINECT, r"depth is empty: 0 x 5 pixels"),
        (np.full((5, 5), np.nan), KINECT, "depth has no valid pixel"),
        (np.zeros((5, 5), dtype=np.uint16), KINECT, "depth has no valid pixel"),
        (np.ones((5, 5)), np.eye(4), r"K must be a 3x3 camera matrix .* got shape \(4, 4\)"),
        (np.ones((5, 5)), [[1, 2], [3, 4]], r"K must be a 3x3 camera matrix"),
        (np.ones((5, 5)), [["a"] * 3] * 3, "K must be a 3x3 camera matrix of numbers"),
        (np.ones((5, 5)), KINECT.T, r"K must be a camera matrix .* bottom row"),
        (np.ones((5, 5)), KINECT * [[1], [1], [0]], r"bottom row is \(0, 0, 0\)"),
        (np.ones((5, 5)), KINECT * [[-1], [1], [1]], r"fx = K\[0, 0\] > 0"),
        (np.ones((5, 5)), SKEWED, "K must have no skew"),
        (np.ones((5, 5)), NOT_FINITE, "K must have finite"),
    ],
)
def test_bad_input_names_the_argument(depth, K, message):
    with pytest.raises(ValueError, match=message):
        svs.cloud_from_depth(depth, K)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"depth_scale": 0.0}, "depth_scale must be finite and > 0"),
        ({"depth_scale": float("nan")}, "depth_scale"),
        ({"min_depth": -0.1}, "min_depth must be finite and >= 0"),
        ({"min_depth": 2.0, "max_depth": 1.0}, r"max_depth must be > min_depth = 2"),
        ({"stride": 0}, "stride must be >= 1"),
        ({"window": 4}, "window must be odd"),
        ({"normal_step": 0}, "normal_step must be >= 1"),
        ({"max_depth_jump": 0.0}, "max_depth_jump must be > 0"),
    ],
)
def test_bad_settings_name_the_setting(settings, message):
    with pytest.raises(ValueError, match=message):
        svs.cloud_from_depth(np.ones((5, 5)), KINECT, **settings)
