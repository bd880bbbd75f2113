"""Registration methods a user would pick instead of ours, behind one signature.

:func:`register` runs one method on a model and a scene (points and normals, metres) and
returns ``T_scene_model`` and the seconds (wall clock and CPU) of the whole call,
downsampling, normal and feature estimation included, for every method, ours included:

==============  ================================================================================
method          what runs
==============  ================================================================================
``paper``       ours, ``spectral_vs.align(global_search=False)``: the paper's controller from
                ``T_init``
``ours``        ours, ``spectral_vs.align()``: global SO(3) search, then the same controller
``o3d_icp``     Open3D point-to-plane ICP from ``T_init``
``o3d_gicp``    Open3D Generalized ICP from ``T_init``
``o3d_ransac``  Open3D FPFH + RANSAC, then point-to-plane ICP (Open3D's global-registration
                tutorial, scaled to the voxel size)
``o3d_fgr``     Open3D FPFH + Fast Global Registration, then the same point-to-plane ICP
``sg_gicp``     small_gicp GICP from ``T_init``
``sg_icp``      small_gicp point-to-plane ICP from ``T_init``
==============  ================================================================================

The settings (:class:`PeerSettings`) are those of Open3D's global-registration tutorial
(``docs/jupyter/pipelines/global_registration.ipynb`` in Open3D), in units of the voxel size
``v``: downsample to ``v``, normals over ``2 v`` (30 neighbours at most), FPFH over ``5 v``
(100 at most), RANSAC with 3-point samples, mutual feature matches, edge-length (0.9) and
distance (``1.5 v``) pruning, 100 000 iterations / 0.999 confidence, FGR at ``0.5 v``,
then point-to-plane ICP at ``0.4 v`` on the clouds as given. The local methods started
from ``T_init`` run on the downsampled clouds with a correspondence distance that must
cover the initial offset (``PeerSettings.plane_icp_distance_voxels``,
``gicp_distance_voxels``: the best of a pilot, in the peers' favour).

OpenMP: Open3D and small_gicp each bring an OpenMP runtime; on 2 cores two spinning
runtimes starve each other, so ``OMP_WAIT_POLICY=PASSIVE`` is set before either is
imported (this module imports them lazily). The thread count of Open3D is fixed at its
import by ``OMP_NUM_THREADS``, which :func:`configure_threads` sets before the import.
Open3D 0.19 and later run part of their pipelines (FPFH + RANSAC among them) on TBB,
which ``OMP_NUM_THREADS`` does not bound: on a free second core RANSAC's CPU time was
twice its wall time (0.21-0.24 s against 0.11-0.12 s on a C-2 case; 0.19 s pinned to one
core). :func:`configure_threads` therefore also pins the process to as many cores as
threads (the first it may run on: to run two benchmarks side by side, start each under
``taskset -c N``), so that every method runs on the threads it is given.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

#: Every method, in the order of the tables.
METHODS = ("ours", "paper", "o3d_icp", "o3d_gicp", "o3d_ransac", "o3d_fgr", "sg_gicp", "sg_icp")
#: Methods that refine from ``T_init`` and so depend on the initial rotation.
LOCAL_METHODS = ("paper", "o3d_icp", "o3d_gicp", "sg_gicp", "sg_icp")
TITLES = {
    "ours": "ours (global search)",
    "paper": "ours, paper mode (from T_init)",
    "o3d_icp": "Open3D point-to-plane ICP",
    "o3d_gicp": "Open3D GICP",
    "o3d_ransac": "Open3D FPFH + RANSAC + ICP",
    "o3d_fgr": "Open3D FPFH + FGR + ICP",
    "sg_gicp": "small_gicp GICP",
    "sg_icp": "small_gicp point-to-plane ICP",
}


@dataclass(frozen=True)
class PeerSettings:
    """Settings of the peers, distances in units of the voxel size ``voxel_size``.

    Attributes
    ----------
    voxel_size : float
        ``v``, metres: the downsampling voxel of the peers (ours uses it as its voxel edge).
    normal_radius_voxels, normal_max_nn : float, int
        Normal estimation on the downsampled clouds (Open3D), oriented like the given
        normals.
    feature_radius_voxels, feature_max_nn : float, int
        FPFH features.
    ransac_distance_voxels : float
        RANSAC inlier distance and distance-pruning threshold.
    ransac_n : int
        Correspondences per RANSAC sample.
    edge_length_similarity : float
        Edge-length pruning ratio.
    ransac_max_iterations, ransac_confidence : int, float
        RANSAC stopping criteria.
    fgr_distance_voxels : float
        FGR's maximum correspondence distance.
    refine_distance_voxels, refine_max_iterations : float, int
        Point-to-plane ICP after RANSAC or FGR, on the clouds as given (Open3D's default
        of 30 iterations).
    plane_icp_distance_voxels, gicp_distance_voxels : float
        Correspondence distance of the local methods started from ``T_init``
        (point-to-plane ICP, GICP). It must cover the initial misalignment, and no tutorial
        value does: chosen as the best for these peers among 0.75, 1, 1.5, 2.5, 5, 10 and
        25 v on 48 cases of the benchmark's families at 10-90 degrees (docs/benchmarks.md).
    local_max_iterations : int
        Iteration cap of the local methods (ours in paper mode has 100 as well).
    small_gicp_translation_epsilon_voxels : float
        small_gicp's translation convergence threshold (its default, 1 mm at a 0.25 m
        downsampling, scaled to ``v``); its rotation threshold stays 0.1 degree.
    threads : int
        Threads of small_gicp and of ours (Open3D's come from :func:`configure_threads`).
    """

    voxel_size: float = 0.008
    normal_radius_voxels: float = 2.0
    normal_max_nn: int = 30
    feature_radius_voxels: float = 5.0
    feature_max_nn: int = 100
    ransac_distance_voxels: float = 1.5
    ransac_n: int = 3
    edge_length_similarity: float = 0.9
    ransac_max_iterations: int = 100_000
    ransac_confidence: float = 0.999
    fgr_distance_voxels: float = 0.5
    refine_distance_voxels: float = 0.4
    refine_max_iterations: int = 30
    plane_icp_distance_voxels: float = 1.5
    gicp_distance_voxels: float = 2.5
    local_max_iterations: int = 100
    small_gicp_translation_epsilon_voxels: float = 0.004
    threads: int = 1


class PeerResult(NamedTuple):
    """``T_scene_model`` (4 x 4, maps model coordinates into the scene) and the time.

    ``seconds`` is wall clock; ``cpu_seconds`` the CPU time of the process (all its
    threads) over the call: with one thread per method, the work itself, whatever other
    jobs share the cores.
    """

    T_scene_model: np.ndarray
    seconds: float
    cpu_seconds: float


def configure_threads(threads: int) -> None:
    """Set the OpenMP thread count of the peers and pin the process to as many cores (TBB);
    call before the first :func:`register`.

    Raises
    ------
    RuntimeError
        If Open3D was already imported with another thread count.
    """
    import sys

    if "open3d" in sys.modules and os.environ.get("OMP_NUM_THREADS") != str(threads):
        raise RuntimeError("open3d is already imported: set the threads before importing it")
    os.environ["OMP_NUM_THREADS"] = str(threads)
    if hasattr(os, "sched_setaffinity"):  # TBB sizes its pool by the cores it may run on
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, cores[:threads])


def import_peers() -> dict[str, str]:
    """Import Open3D and small_gicp now, so that no timing includes an import.

    Returns
    -------
    dict
        Their versions, by package name.
    """
    from importlib.metadata import version

    import small_gicp  # noqa: F401

    _open3d()
    return {name: version(name) for name in ("open3d", "small_gicp")}


def _open3d() -> Any:
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def _o3d_cloud(o3d: Any, points: np.ndarray, normals: np.ndarray | None) -> Any:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=float)))
    if normals is not None:
        cloud.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=float))
    return cloud


def _o3d_preprocess(o3d: Any, cloud: Any, s: PeerSettings, features: bool) -> tuple[Any, Any]:
    """Downsampled cloud with normals over 2 v (turned toward the given ones), and its FPFH."""
    v = s.voxel_size
    down = cloud.voxel_down_sample(v)
    down.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(
            radius=s.normal_radius_voxels * v, max_nn=s.normal_max_nn
        )
    )
    if not features:
        return down, None
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        down,
        o3d.geometry.KDTreeSearchParamHybrid(
            radius=s.feature_radius_voxels * v, max_nn=s.feature_max_nn
        ),
    )
    return down, fpfh


def _o3d_plane_icp(
    o3d: Any, model: Any, scene: Any, T: np.ndarray, distance: float, max_iterations: int
) -> np.ndarray:
    """Open3D point-to-plane ICP from ``T``, correspondences within ``distance`` metres."""
    reg = o3d.pipelines.registration
    result = reg.registration_icp(
        model,
        scene,
        distance,
        T,
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=max_iterations),
    )
    return np.array(result.transformation)


class _Problem(NamedTuple):
    """One registration as :func:`register` hands it on: model and scene as (points,
    normals), metres; the initial ``T_scene_model``; the settings; the seed of the random
    methods; the scene's sensor origin (or None)."""

    model: tuple[np.ndarray, np.ndarray]
    scene: tuple[np.ndarray, np.ndarray]
    T_init: np.ndarray
    settings: PeerSettings
    seed: int
    scene_viewpoint: np.ndarray | None


def _run_open3d(method: str, problem: _Problem) -> np.ndarray:
    o3d = _open3d()
    reg = o3d.pipelines.registration
    s, T_init = problem.settings, problem.T_init
    v = s.voxel_size
    model_cloud = _o3d_cloud(o3d, *problem.model)
    scene_cloud = _o3d_cloud(o3d, *problem.scene)
    global_method = method in ("o3d_ransac", "o3d_fgr")
    model_down, model_fpfh = _o3d_preprocess(o3d, model_cloud, s, global_method)
    scene_down, scene_fpfh = _o3d_preprocess(o3d, scene_cloud, s, global_method)
    if method == "o3d_icp":
        return _o3d_plane_icp(
            o3d,
            model_down,
            scene_down,
            T_init,
            s.plane_icp_distance_voxels * v,
            s.local_max_iterations,
        )
    if method == "o3d_gicp":
        result = reg.registration_generalized_icp(
            model_down,
            scene_down,
            s.gicp_distance_voxels * v,
            T_init,
            reg.TransformationEstimationForGeneralizedICP(),
            reg.ICPConvergenceCriteria(max_iteration=s.local_max_iterations),
        )
        return np.array(result.transformation)
    o3d.utility.random.seed(problem.seed % 2**31)  # a C int
    if method == "o3d_ransac":
        distance = s.ransac_distance_voxels * v
        coarse = reg.registration_ransac_based_on_feature_matching(
            model_down,
            scene_down,
            model_fpfh,
            scene_fpfh,
            True,  # mutual filter
            distance,
            reg.TransformationEstimationPointToPoint(False),
            s.ransac_n,
            [
                reg.CorrespondenceCheckerBasedOnEdgeLength(s.edge_length_similarity),
                reg.CorrespondenceCheckerBasedOnDistance(distance),
            ],
            reg.RANSACConvergenceCriteria(s.ransac_max_iterations, s.ransac_confidence),
        )
    else:
        coarse = reg.registration_fgr_based_on_feature_matching(
            model_down,
            scene_down,
            model_fpfh,
            scene_fpfh,
            reg.FastGlobalRegistrationOption(
                maximum_correspondence_distance=s.fgr_distance_voxels * v
            ),
        )
    return _o3d_plane_icp(
        o3d,
        model_cloud,
        scene_cloud,
        np.array(coarse.transformation),
        s.refine_distance_voxels * v,
        s.refine_max_iterations,
    )


def _run_small_gicp(method: str, problem: _Problem) -> np.ndarray:
    import small_gicp

    s = problem.settings
    v = s.voxel_size
    gicp = method == "sg_gicp"
    distance = s.gicp_distance_voxels if gicp else s.plane_icp_distance_voxels
    result = small_gicp.align(
        np.asarray(problem.scene[0], dtype=float),
        np.asarray(problem.model[0], dtype=float),
        np.asarray(problem.T_init, dtype=float),
        registration_type="GICP" if gicp else "PLANE_ICP",
        downsampling_resolution=v,
        max_correspondence_distance=distance * v,
        num_threads=s.threads,
        max_iterations=s.local_max_iterations,
        translation_epsilon=s.small_gicp_translation_epsilon_voxels * v,
    )
    return np.array(result.T_target_source)


def _run_ours(method: str, problem: _Problem) -> np.ndarray:
    import spectral_vs as svs

    s, viewpoint = problem.settings, problem.scene_viewpoint
    settings: dict[str, Any] = {"voxel_size": s.voxel_size, "threads": s.threads}
    if method == "paper":
        T_init = np.asarray(problem.T_init, dtype=float)
        settings |= {"global_search": False, "initial_guess": T_init}
    elif viewpoint is not None and np.all(np.isfinite(viewpoint)):
        # A single-view scan: its sensor origin is known, as with any real scan.
        settings.update(sensor_origin=np.asarray(viewpoint, dtype=float), scene_view="single_view")
    result = svs.align(svs.PointCloud(*problem.model), svs.PointCloud(*problem.scene), **settings)
    return np.array(result.T_scene_model)


def register(
    method: str,
    model_xyz: np.ndarray,
    model_normals: np.ndarray,
    scene_xyz: np.ndarray,
    scene_normals: np.ndarray,
    voxel: float = 0.008,
    T_init: np.ndarray | None = None,
    *,
    settings: PeerSettings | None = None,
    seed: int = 0,
    scene_viewpoint: np.ndarray | None = None,
) -> PeerResult:
    """Register the model onto the scene with ``method`` (one of :data:`METHODS`).

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    model_xyz, model_normals : ndarray, shape (N, 3)
        The model's points (metres) and unit normals.
    scene_xyz, scene_normals : ndarray, shape (M, 3)
        The scene's points (metres) and unit normals.
    voxel : float
        The voxel size ``v``, metres (overrides ``settings.voxel_size``).
    T_init : ndarray, shape (4, 4), optional
        Initial ``T_scene_model`` of the local methods (identity by default); the global
        ones (``ours``, ``o3d_ransac``, ``o3d_fgr``) ignore it.
    settings : PeerSettings, optional
        Defaults to ``PeerSettings()``.
    seed : int
        Seed of Open3D's random generator, set before RANSAC and FGR.
    scene_viewpoint : ndarray, shape (3,), optional
        Sensor origin of a single-view scene (used by ``ours`` only).

    Returns
    -------
    PeerResult
        ``T_scene_model`` and the wall-clock and CPU seconds of the whole call.

    Raises
    ------
    ValueError
        For an unknown ``method``.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    s = settings or PeerSettings()
    if voxel != s.voxel_size:
        s = PeerSettings(**{**vars(s), "voxel_size": voxel})
    T0 = np.eye(4) if T_init is None else np.asarray(T_init, dtype=float)
    model = (np.asarray(model_xyz, dtype=float), np.asarray(model_normals, dtype=float))
    scene = (np.asarray(scene_xyz, dtype=float), np.asarray(scene_normals, dtype=float))
    problem = _Problem(model, scene, T0, s, seed, scene_viewpoint)
    start, cpu_start = time.perf_counter(), time.process_time()
    if method in ("ours", "paper"):
        T = _run_ours(method, problem)
    elif method.startswith("o3d_"):
        T = _run_open3d(method, problem)
    else:
        T = _run_small_gicp(method, problem)
    return PeerResult(T, time.perf_counter() - start, time.process_time() - cpu_start)


#: KISS-Matcher's voxel at its own (LiDAR) scale: the points are scaled by
#: ``KISS_MATCHER_VOXEL / v`` before it runs (its constructor refuses a voxel under 5 mm and
#: its constants assume metre-scale voxels), and its translation is scaled back.
KISS_MATCHER_VOXEL = 0.3


def register_kiss_matcher(
    source_xyz: np.ndarray,
    source_normals: np.ndarray,
    target_xyz: np.ndarray,
    target_normals: np.ndarray,
    voxel: float,
    *,
    settings: PeerSettings | None = None,
) -> tuple[PeerResult, bool]:
    """KISS-Matcher (PyPI ``kiss-matcher``, Lim et al., ICRA 2025), then Open3D
    point-to-plane ICP: ``T_target_source`` and whether KISS-Matcher called its estimate
    valid.

    KISS-Matcher takes points only (it estimates its own normals and features) and runs
    with its defaults at :data:`KISS_MATCHER_VOXEL` on the points scaled by
    ``KISS_MATCHER_VOXEL / voxel``; its translation is scaled back. The refinement is the
    one after RANSAC in :func:`register`: point-to-plane ICP within
    ``settings.refine_distance_voxels * voxel`` on the clouds as given (with their
    normals), ``settings.refine_max_iterations`` iterations, from KISS-Matcher's estimate
    whether valid or not. The time covers the whole call, scaling included.

    Parameters
    ----------
    source_xyz, source_normals : ndarray, shape (N, 3)
        The cloud to move (metres, unit normals).
    target_xyz, target_normals : ndarray, shape (M, 3)
        The fixed cloud.
    voxel : float
        The voxel size ``v``, metres.
    settings : PeerSettings, optional
        The refinement's settings; defaults to ``PeerSettings()``.

    Returns
    -------
    (PeerResult, bool)
        ``T_scene_model`` (here ``T_target_source``) with the times, and KISS-Matcher's
        ``valid``.
    """
    from kiss_matcher import KISSMatcher, KISSMatcherConfig  # type: ignore[import-untyped]

    s = settings or PeerSettings()
    start, cpu_start = time.perf_counter(), time.process_time()
    scale = KISS_MATCHER_VOXEL / voxel
    matcher = KISSMatcher(KISSMatcherConfig(KISS_MATCHER_VOXEL))
    solution = matcher.estimate(
        (np.asarray(source_xyz) * scale).astype(np.float32),
        (np.asarray(target_xyz) * scale).astype(np.float32),
    )
    T = np.eye(4)
    T[:3, :3] = np.asarray(solution.rotation)
    T[:3, 3] = np.asarray(solution.translation).ravel() / scale
    o3d = _open3d()
    T = _o3d_plane_icp(
        o3d,
        _o3d_cloud(o3d, source_xyz, source_normals),
        _o3d_cloud(o3d, target_xyz, target_normals),
        T,
        s.refine_distance_voxels * voxel,
        s.refine_max_iterations,
    )
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return PeerResult(T, seconds, cpu), bool(solution.valid)
