"""Open3D point clouds in and out: points, normals and colours survive the round trip,
align() takes Open3D clouds directly, and without Open3D the package still imports and
says what to install. Skipped where Open3D (the bench extra) is not installed, except the
checks that need it absent."""

from __future__ import annotations

import builtins
import sys

import numpy as np
import pytest

import spectral_vs as svs
from spectral_vs import interop
from spectral_vs.poses import rotation_matrix


def test_the_package_does_not_import_open3d():
    # A fresh interpreter: importing spectral_vs (and converting nothing) leaves Open3D out.
    import subprocess

    code = "import sys, spectral_vs; print('open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_without_open3d_to_open3d_says_what_to_install(monkeypatch):
    real_import = builtins.__import__

    def no_open3d(name, *args, **kwargs):
        if name == "open3d" or name.startswith("open3d."):
            raise ImportError("No module named 'open3d'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_open3d)
    with pytest.raises(ImportError, match=r"pip install open3d .*spectral_vs\[bench\]"):
        svs.to_open3d(svs.PointCloud(np.zeros((3, 3))))
    # Our clouds and arrays never need it.
    assert not interop.is_open3d_cloud(svs.PointCloud(np.zeros((3, 3))))
    assert not interop.is_open3d_cloud(np.zeros((3, 3)))
    with pytest.raises(TypeError, match=r"cloud must be an open3d\.geometry\.PointCloud"):
        svs.from_open3d(np.zeros((3, 3)))


@pytest.fixture
def o3d():
    return pytest.importorskip("open3d")


def test_points_normals_and_colours_round_trip(o3d, rng):
    points = rng.uniform(-1, 1, size=(500, 3))
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    colours = rng.uniform(0, 1, size=(500, 3))
    pcd = svs.to_open3d(svs.PointCloud(points, normals), colors=colours)
    assert isinstance(pcd, o3d.geometry.PointCloud)
    np.testing.assert_array_equal(np.asarray(pcd.points), points)
    np.testing.assert_allclose(np.asarray(pcd.normals), normals, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(pcd.colors), colours)
    back = svs.from_open3d(pcd)
    np.testing.assert_array_equal(back.points, points)
    np.testing.assert_allclose(back.normals, normals, rtol=0, atol=1e-15)
    # Points only, from an array; an Open3D cloud without normals gives none.
    bare = svs.to_open3d(points)
    assert not bare.has_normals() and not bare.has_colors()
    assert not svs.from_open3d(bare).has_normals
    # (N, 6) arrays carry normals.
    assert svs.to_open3d(np.hstack([points, normals])).has_normals()


def test_non_finite_points_are_dropped_or_refused(o3d):
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.array([[0, 0, 1], [np.nan, 0, 1], [1, 1, 1.0]]))
    assert len(svs.from_open3d(pcd)) == 2
    with pytest.raises(ValueError, match="row 1 is not finite"):
        svs.from_open3d(pcd, drop_non_finite=False)


def test_bad_colours_are_refused(o3d):
    cloud = svs.PointCloud(np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"colors must have shape \(4, 3\)"):
        svs.to_open3d(cloud, colors=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        svs.to_open3d(cloud, colors=np.full((4, 3), 255.0))


def test_align_takes_open3d_clouds(o3d, data_dir):
    model = svs.voxel_downsample(svs.load_cloud(data_dir / "milk.pcd"), 0.004)
    T = np.eye(4)
    T[:3, :3] = rotation_matrix([0.0, 0.0, np.radians(40.0)])
    T[:3, 3] = [0.05, -0.02, 0.03]
    scene = model.transformed(T)
    ours = svs.align(model, scene)
    theirs = svs.align(svs.to_open3d(model), svs.to_open3d(scene))
    np.testing.assert_array_equal(theirs.T_scene_model, ours.T_scene_model)
    error = svs.pose_error(ours.T_scene_model, T, center=model.centroid())
    assert error.rotation_deg < 1.0 and error.translation_mm < 2.0
