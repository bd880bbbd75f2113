"""PyBullet simulation of the paper's servoing experiment: a robot arm with a wrist depth
camera above a table of cluttered objects. The arm is data (:class:`RobotModel`): the
presets are the KUKA LBR iiwa (the default) and the Franka Emika Panda.

Needs the optional dependency ``pybullet`` (``pip install pybullet``). The main entry
point is :class:`PyBulletRobot`, an implementation of
:class:`spectral_vs.robot.RobotInterface`.
"""

from __future__ import annotations

try:
    import pybullet  # noqa: F401
except ImportError as error:  # pragma: no cover - depends on the environment
    raise ImportError("spectral_vs.sim needs PyBullet: pip install pybullet") from error

from spectral_vs.sim.camera import (
    CameraIntrinsics,
    CameraParams,
    DepthNoise,
    NormalParams,
    back_project,
    depth_to_cloud,
    render_depth,
)
from spectral_vs.sim.robot import (
    BASE_LINK,
    HOME_Q,
    TIP_LINK,
    PyBulletRobot,
    SimParams,
    default_T_tip_camera,
    iiwa_urdf_path,
    pose_matrix,
)
from spectral_vs.sim.robots import (
    PANDA_HOME_Q,
    ROBOT_MODELS,
    RobotModel,
    iiwa_model,
    panda_model,
    panda_T_hand_camera,
    panda_urdf_path,
    robot_model,
)
from spectral_vs.sim.scene import TABLE_HEIGHT, PlacedObject, TableSceneParams, build_scene

__all__ = [
    "BASE_LINK",
    "HOME_Q",
    "PANDA_HOME_Q",
    "ROBOT_MODELS",
    "TABLE_HEIGHT",
    "TIP_LINK",
    "CameraIntrinsics",
    "CameraParams",
    "DepthNoise",
    "NormalParams",
    "PlacedObject",
    "PyBulletRobot",
    "RobotModel",
    "SimParams",
    "TableSceneParams",
    "back_project",
    "build_scene",
    "default_T_tip_camera",
    "depth_to_cloud",
    "iiwa_model",
    "iiwa_urdf_path",
    "panda_T_hand_camera",
    "panda_model",
    "panda_urdf_path",
    "pose_matrix",
    "render_depth",
    "robot_model",
]
