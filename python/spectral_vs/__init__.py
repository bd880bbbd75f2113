"""Correspondence-free point cloud registration and 3D visual servoing in the spectral domain.

The representation (voxel grids, Extended Gaussian Images), the translation (3D phase
correlation) and rotation (EGI correlation over SO(3)) estimation, the aligner of
Algorithm 1 and the camera kinematics of "3D Spectral Domain Registration-Based Visual
Servoing" run in a compiled C++ core, ``spectral_vs._core``; this package re-exports
them and adds :func:`align`, :func:`load_cloud`, :func:`pose_error` and the Open3D
conversions :func:`from_open3d` and :func:`to_open3d`. The package is typed (PEP 561):
``_core.pyi`` describes the compiled module to type checkers.
"""

from __future__ import annotations

import os
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _distribution_version

from spectral_vs._core import (
    RELIABLE_CONFIDENCE,
    SINGLE_VIEW_THRESHOLD,
    AlignAlternative,
    AlignIteration,
    AlignParams,
    AlignResult,
    AlignTimings,
    AxisRotationStep,
    CloudFileInfo,
    DampedSolution,
    DampingParams,
    DepthScaleCheck,
    DominantPlane,
    GlobalSearchParams,
    GridSpec,
    Kinematics,
    LocalParams,
    OrganizedCloud,
    PhaseCorrelation,
    PointCloud,
    RefinementParams,
    RotationRefineResult,
    SceneParams,
    SingleViewEvidence,
    So3Correlation,
    TranslationEstimate,
    VelocityCommand,
    VelocityCommandParams,
    VerificationParams,
    ViewAlignParams,
    ViewAlignResult,
    ViewAlignTimings,
    ViewAlternative,
    ViewScale,
    ViewSupport,
    VoxelGrid,
    alignment_voxel_size,
    calibrated_confidence,
    check_depth_scale,
    cloud_from_depth,
    covariance_inflation,
    damped_least_squares,
    detect_single_view,
    dominant_direction,
    dominant_plane,
    egi,
    egi_cell,
    egi_coefficients,
    fft_friendly_size,
    load_cloud_with_info,
    load_organized,
    make_grid_spec,
    phase_correlation,
    pose_covariance,
    prepare_cloud,
    real_spherical_harmonics,
    refine_rotation,
    rotation_angle,
    rotation_cost,
    rotation_step_about,
    save_cloud,
    sh_coefficients,
    sh_index,
    sh_synthesis,
    smooth_coefficients,
    so3_correlation,
    so3_exp,
    so3_log,
    so3_search,
    sphere_grid,
    step_score,
    translation_cost,
    view_scale,
    view_support,
    voxel_downsample,
    voxelize,
    wigner_generators,
    wigner_real,
)
from spectral_vs.interop import from_open3d, to_open3d
from spectral_vs.poses import PoseError, pose_error
from spectral_vs.registration import align
from spectral_vs.robot import RobotInterface
from spectral_vs.sanity import InputWarning, estimate_normals
from spectral_vs.servo import (
    ServoLog,
    ServoParams,
    ServoRecord,
    ServoStatus,
    SpectralServo,
    run_servo,
)
from spectral_vs.verification import CONFIDENCE_THRESHOLD, PoseVerification, verify_pose
from spectral_vs.views import align_views

#: The installed distribution's version: the CMake project's (CMakeLists.txt), the one place
#: it is written.
try:
    __version__ = _distribution_version("spectral_vs")
except PackageNotFoundError:  # imported from a source tree that pip never installed
    __version__ = "0+unknown"


def load_cloud(path: str | os.PathLike[str]) -> PointCloud:
    """Load a ``.pcd`` or ``.ply`` file as a :class:`PointCloud`.

    Organized clouds are flattened and points with a non-finite coordinate are
    dropped; :func:`load_cloud_with_info` also reports how many.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its extension chooses the format.

    Returns
    -------
    PointCloud
        The finite points in metres, with the file's normals if it has
        ``normal_x``/``normal_y``/``normal_z`` fields.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a point cloud, or has no finite point.
    """
    cloud, _ = load_cloud_with_info(path)
    return cloud


__all__ = [
    "CONFIDENCE_THRESHOLD",
    "RELIABLE_CONFIDENCE",
    "SINGLE_VIEW_THRESHOLD",
    "AlignAlternative",
    "AlignIteration",
    "AlignParams",
    "AlignResult",
    "AlignTimings",
    "AxisRotationStep",
    "CloudFileInfo",
    "DampedSolution",
    "DampingParams",
    "DepthScaleCheck",
    "DominantPlane",
    "GlobalSearchParams",
    "GridSpec",
    "InputWarning",
    "Kinematics",
    "LocalParams",
    "OrganizedCloud",
    "PhaseCorrelation",
    "PointCloud",
    "PoseError",
    "PoseVerification",
    "RefinementParams",
    "RobotInterface",
    "RotationRefineResult",
    "SceneParams",
    "ServoLog",
    "ServoParams",
    "ServoRecord",
    "ServoStatus",
    "SingleViewEvidence",
    "So3Correlation",
    "SpectralServo",
    "TranslationEstimate",
    "VelocityCommand",
    "VelocityCommandParams",
    "VerificationParams",
    "ViewAlignParams",
    "ViewAlignResult",
    "ViewAlignTimings",
    "ViewAlternative",
    "ViewScale",
    "ViewSupport",
    "VoxelGrid",
    "align",
    "align_views",
    "alignment_voxel_size",
    "calibrated_confidence",
    "check_depth_scale",
    "cloud_from_depth",
    "covariance_inflation",
    "damped_least_squares",
    "detect_single_view",
    "dominant_direction",
    "dominant_plane",
    "egi",
    "egi_cell",
    "egi_coefficients",
    "estimate_normals",
    "fft_friendly_size",
    "from_open3d",
    "load_cloud",
    "load_cloud_with_info",
    "load_organized",
    "make_grid_spec",
    "phase_correlation",
    "pose_covariance",
    "pose_error",
    "prepare_cloud",
    "real_spherical_harmonics",
    "refine_rotation",
    "rotation_angle",
    "rotation_cost",
    "rotation_step_about",
    "run_servo",
    "save_cloud",
    "sh_coefficients",
    "sh_index",
    "sh_synthesis",
    "smooth_coefficients",
    "so3_correlation",
    "so3_exp",
    "so3_log",
    "so3_search",
    "sphere_grid",
    "step_score",
    "to_open3d",
    "translation_cost",
    "verify_pose",
    "view_scale",
    "view_support",
    "voxel_downsample",
    "voxelize",
    "wigner_generators",
    "wigner_real",
]
