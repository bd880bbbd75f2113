"""Resource limits and thread safety of the alignment (docs/reliability.md).

- A scene whose grids at the asked voxel size would take about 10 GB is refused before
  any grid is allocated, with a message naming the limit (``max_voxels``); raising the
  limit is the caller's explicit choice.
- ``max_seconds`` bounds the work: past it, the best pose so far comes back with
  ``converged = False`` and ``stop_reason = 'max_seconds'``.
- Alignments in parallel Python threads (the compiled core releases the GIL) give results
  bit-identical to the same alignments run one after the other.
"""

from __future__ import annotations

import resource
import threading

import numpy as np
import pytest
from conftest import box_and_sphere

import spectral_vs as svs

#: Bytes per voxel of the largest alignment grids (scene map 4, translation grid values
#: and its FFT buffers about 28): the figures of AlignParams.max_voxels' documentation.
BYTES_PER_VOXEL = 4 + 28


def room(extent: float, spacing: float) -> svs.PointCloud:
    """Points on the six walls of a cube of side ``extent`` metres, with inward normals."""
    ticks = np.arange(0.0, extent + 1e-9, spacing)
    u, v = (a.ravel() for a in np.meshgrid(ticks, ticks))
    points, normals = [], []
    for axis in range(3):
        for side, inward in ((0.0, 1.0), (extent, -1.0)):
            p = np.zeros((u.size, 3))
            p[:, axis] = side
            p[:, (axis + 1) % 3], p[:, (axis + 2) % 3] = u, v
            n = np.zeros_like(p)
            n[:, axis] = inward
            points.append(p)
            normals.append(n)
    return svs.PointCloud(np.vstack(points), np.vstack(normals))


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: kilobytes


def test_a_scene_needing_10_gb_is_refused_before_allocating():
    scene = room(extent=2.2, spacing=0.1)  # a 2.2 m room
    voxel = 0.0033  # 667^3 voxels of scene map: 3e8 voxels, about 10 GB of grids
    voxels = (2.2 / voxel) ** 3
    assert 8e9 < voxels * BYTES_PER_VOXEL < 12e9
    model = svs.PointCloud(*box_and_sphere(np.random.default_rng(1), 2000))
    before = peak_rss_bytes()
    with pytest.raises(ValueError, match=r"exceeds the limit of 16777216 voxels \(max_voxels\)"):
        svs.align(model, scene, voxel_size=voxel, downsample=False)
    # Nothing near the size of the grid was touched: the peak memory of the process did
    # not grow by even a tenth of it.
    assert peak_rss_bytes() - before < 1e9
    assert svs.AlignParams().max_voxels == 2**24


def test_the_limit_is_the_callers_to_raise():
    scene = room(extent=0.6, spacing=0.05)
    model = svs.PointCloud(*box_and_sphere(np.random.default_rng(2), 2000))
    with pytest.raises(ValueError, match="max_voxels"):
        svs.align(model, scene, voxel_size=0.01, max_voxels=10_000, downsample=False)
    result = svs.align(model, scene, voxel_size=0.01, max_voxels=10_000_000, downsample=False)
    assert np.all(np.isfinite(np.asarray(result.T_scene_model)))


def test_phase_correlation_refuses_its_grid_before_allocating():
    spec = svs.GridSpec([0.0, 0.0, 0.0], 0.01, [1200, 1200, 1200])  # about 35 GB of buffers
    before = peak_rss_bytes()
    with pytest.raises(ValueError, match=r"GB\) exceeds the limit of 16777216 voxels"):
        svs.PhaseCorrelation(spec)
    with pytest.raises(ValueError, match="exceeds the limit of 1000 voxels"):
        svs.PhaseCorrelation(spec, max_voxels=1000)
    assert peak_rss_bytes() - before < 1e9


def case(seed: int, angle_deg: float) -> tuple[svs.PointCloud, svs.PointCloud]:
    rng = np.random.default_rng(seed)
    points, normals = box_and_sphere(rng, 3000)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(angle_deg)
    R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    t = rng.uniform(-0.05, 0.05, 3)
    scene_points, scene_normals = box_and_sphere(rng, 3000)
    scene = svs.PointCloud(scene_points @ R.T + t, scene_normals @ R.T)
    return svs.PointCloud(points, normals), scene


@pytest.mark.parametrize("global_search", [True, False])
def test_max_seconds_returns_the_pose_so_far_without_claiming_convergence(global_search):
    model, scene = case(3, 20.0)
    result = svs.align(
        model, scene, max_seconds=1e-9, global_search=global_search, downsample=False
    )
    assert not result.converged
    assert result.stop_reason == "max_seconds"
    assert result.iterations == 1  # stopped at the first check
    assert np.all(np.isfinite(np.asarray(result.T_scene_model)))
    # Without a budget the same alignment converges: the stop was the budget's.
    unlimited = svs.align(model, scene, global_search=global_search, downsample=False)
    assert unlimited.converged and unlimited.stop_reason == "converged"


def outcome(result: svs.AlignResult) -> tuple:
    """Everything an alignment returns, bit for bit."""
    history = tuple(
        (np.asarray(i.T_scene_model).tobytes(), i.translation_cost, i.rotation_cost, i.correlation)
        for i in result.history
    )
    return (
        np.asarray(result.T_scene_model).tobytes(),
        result.converged,
        result.iterations,
        result.fitness,
        result.correlation,
        result.translation_peak,
        result.hypothesis,
        history,
    )


def test_parallel_alignments_equal_sequential_ones():
    # Bandwidths used nowhere else in the tests: the threads also race to make the FFT
    # plans and Wigner tables of a new size for the first time.
    jobs = [
        (case(11, 120.0), {"bandwidth": 13}),
        (case(12, 40.0), {"bandwidth": 13, "threads": 2}),
        (case(13, 15.0), {"bandwidth": 11, "global_search": False}),
        (case(14, 170.0), {"bandwidth": 11, "occupancy": "binary"}),
    ]
    parallel: list[tuple | None] = [None] * len(jobs)
    errors: list[BaseException] = []
    start = threading.Barrier(len(jobs))

    def run(index: int) -> None:
        (model, scene), settings = jobs[index]
        try:
            start.wait()
            parallel[index] = outcome(svs.align(model, scene, downsample=False, **settings))
        except BaseException as error:  # reported by the main thread
            errors.append(error)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(len(jobs))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    sequential = [
        outcome(svs.align(model, scene, downsample=False, **settings))
        for (model, scene), settings in jobs
    ]
    for index, (got, expected) in enumerate(zip(parallel, sequential, strict=True)):
        assert got == expected, f"job {index} differs when run in parallel"
