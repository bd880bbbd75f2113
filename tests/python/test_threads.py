"""Threads (docs/reliability.md, "Threads"): the same pose with ``threads=1`` and
``threads=2`` on a real scan, and one ``ModelAligner`` shared by two Python threads (its
calls wait for each other and each gives what it gives alone). The C++ side of both, and
parallel alignments, run under ThreadSanitizer in ``make test-tsan``."""

from __future__ import annotations

import threading

import numpy as np
from conftest import box_and_sphere

import spectral_vs as svs
from spectral_vs import _core


def rotation_about(axis: list[float], degrees: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a /= np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(degrees)
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def test_the_real_scan_gives_the_same_result_with_one_and_two_threads(data_dir):
    # The milk carton, turned by 120 degrees, aligned onto the cluttered Kinect scan it was
    # cut from; the Python wrapper's downsampling and normals (PCL's OpenMP) run with the
    # threads too. (The points alone are moved, so their normals are estimated toward the
    # wrong viewpoint: the pose found is not the motion; the test is of the threads.)
    model = svs.load_cloud(str(data_dir / "milk.pcd"))
    scene = svs.load_cloud(str(data_dir / "milk_cartoon_all_small_clorox.pcd"))
    points = np.asarray(model.points)
    c = points.mean(axis=0)
    T = np.eye(4)
    T[:3, :3] = rotation_about([1.0, 1.0, 0.5], 120.0)
    T[:3, 3] = c - T[:3, :3] @ c + [0.1, -0.05, 0.1]
    moved = svs.PointCloud(points @ T[:3, :3].T + T[:3, 3])
    one = svs.align(moved, scene, threads=1)
    two = svs.align(moved, scene, threads=2)
    assert np.asarray(one.T_scene_model).tobytes() == np.asarray(two.T_scene_model).tobytes()
    assert (one.fitness, one.iterations, one.hypothesis) == (
        two.fitness,
        two.iterations,
        two.hypothesis,
    )
    assert len(one.history) == len(two.history)
    for a, b in zip(one.history, two.history, strict=True):
        assert (a.translation_cost, a.rotation_cost, a.correlation) == (
            b.translation_cost,
            b.rotation_cost,
            b.correlation,
        )


def test_one_model_aligner_shared_by_two_threads(rng):
    points, normals = box_and_sphere(rng, 3000)
    model = svs.PointCloud(points, normals)
    params = svs.AlignParams()
    params.voxel_size = 0.012
    params.bandwidth = 8
    params.global_search = False
    params.max_iterations = 3
    params.max_translation = 0.1
    aligner = _core.ModelAligner(model, params)
    scenes = []
    for i in range(6):
        T = np.eye(4)
        T[:3, :3] = rotation_about([1.0, 0.0, 1.0], 2.0 + i)
        T[:3, 3] = [0.004 * i, 0.05 if i % 2 else -0.003, 0.0]
        scenes.append(model.transformed(T))
    results: dict[int, np.ndarray] = {}
    errors: list[BaseException] = []
    start = threading.Barrier(2)

    def run(first: int) -> None:
        try:
            start.wait()
            for i in range(first, len(scenes), 2):
                results[i] = np.asarray(aligner.align(scenes[i]).T_scene_model)
        except BaseException as error:  # reported by the main thread
            errors.append(error)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    for i, scene in enumerate(scenes):
        alone = np.asarray(svs.align(model, scene, params, downsample=False).T_scene_model)
        # ModelAligner gives align()'s pose to rounding (test_model_aligner.py)
        assert np.abs(results[i] - alone).max() < 1e-9, f"scene {i}"
