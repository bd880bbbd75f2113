"""The robot arms of the simulation, as data: URDF, chain, home configuration and camera mount.

A :class:`RobotModel` is all :class:`spectral_vs.sim.PyBulletRobot` needs to load an arm:
the URDF, the base and tip links of the chain that :class:`spectral_vs.Kinematics` builds
(the servoed joints are the movable joints between them), the home configuration where
the reference cloud is captured, the pose of the wrist camera on the tip link, and the
joints outside the chain (a gripper's fingers) with the positions they are held at.

Presets (:data:`ROBOT_MODELS`, :func:`robot_model`): ``"iiwa"``, the KUKA LBR iiwa of
``pybullet_data/kuka_iiwa/model.urdf``, and ``"panda"``, the Franka Emika Panda of
``pybullet_data/franka_panda/panda.urdf``. Both stand at the world origin on the table top
(z = 0, see :mod:`spectral_vs.sim.scene`), and at home both wrist cameras have the same
pose: 0.55 m straight above (0.6, 0, 0) m, looking down at the clutter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet_data

#: Links of the iiwa chain in pybullet_data's kuka_iiwa/model.urdf.
BASE_LINK = "lbr_iiwa_link_0"
TIP_LINK = "lbr_iiwa_link_7"

#: A configuration whose camera looks straight down at the clutter from 0.55 m above the
#: table (camera at about (0.6, 0, 0.55) m in the base frame), rad.
HOME_Q: tuple[float, ...] = (-0.1875, 0.3408, 0.2521, -1.4288, -0.085, 1.3826, -1.5042)

#: The Panda's home configuration, rad: its camera has the pose of the iiwa's at
#: :data:`HOME_Q` (0.55 m above (0.6, 0, 0) m, optical axis straight down, image x along
#: -y of the world), to 0.02 mm and 0.003 degree. Found once by damped least squares on
#: the KDL chain with a null-space pull toward the middle of the soft joint limits, then
#: rounded to 1e-4 rad; joint 4 (-1.40) and joint 6 (1.56) are far inside their soft limits
#: [-3.07, -0.07] and [-0.02, 3.75], every joint at least 1.3 rad from a limit.
PANDA_HOME_Q: tuple[float, ...] = (0.0343, 0.1638, 0.0927, -1.3995, -0.0151, 1.5626, -0.6598)


def iiwa_urdf_path() -> Path:
    """Path of the iiwa URDF shipped with ``pybullet_data``."""
    return Path(pybullet_data.getDataPath()) / "kuka_iiwa" / "model.urdf"


def panda_urdf_path() -> Path:
    """Path of the Franka Emika Panda URDF shipped with ``pybullet_data``."""
    return Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"


def default_T_tip_camera() -> np.ndarray:
    """The camera mount on ``lbr_iiwa_link_7``: axes parallel to the flange frame (optical
    axis along the flange normal, +Z of link 7), centre 5 cm in front of the link frame
    (the flange face is at 4.5 cm) and 7 cm off the axis along -Y, so that no part of the
    robot is in view and joint 7 moves the camera as on a real wrist mount."""
    T = np.eye(4)
    T[:3, 3] = (0.0, -0.07, 0.05)
    return T


def panda_T_hand_camera() -> np.ndarray:
    """The camera mount on ``panda_hand``: optical axis along the hand's +Z (the direction
    the fingers point), centre 6 cm in front of the flange and 7 cm off the axis along the
    hand's -X, beside the hand (which is 3.2 cm deep in X) and away from the fingers (which
    open along Y); camera X and Y are the hand's -X and -Y. Seen from the camera the
    fingertips are more than 45 degrees off the axis, outside the 73 x 58 degree view."""
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, -1.0, 1.0])
    T[:3, 3] = (-0.07, 0.0, 0.06)
    return T


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A robot arm with a wrist camera, as the simulation loads it.

    Attributes
    ----------
    name : str
        Short name (a key of :data:`ROBOT_MODELS` for the presets).
    urdf_path : pathlib.Path
        The robot's URDF; PyBullet loads it with a fixed base at the world origin.
    base_link, tip_link : str
        First and last link of the servoed chain; the camera is mounted on ``tip_link``.
        Movable joints beyond ``tip_link`` (fingers) are not part of the chain.
    home_q : tuple of float
        Joint positions of the chain's movable joints (in chain order) at home, where the
        reference cloud is captured, rad.
    T_tip_camera : ndarray, shape (4, 4)
        Pose of the camera frame (Z forward, X right, Y down) in ``tip_link``, metres;
        stored read-only.
    held_joints : tuple of (str, float)
        Movable joints outside the chain and the positions they are kept at, rad or metres
        (the Panda's fingers, open).
    """

    name: str
    urdf_path: Path
    base_link: str
    tip_link: str
    home_q: tuple[float, ...]
    T_tip_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    held_joints: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("name must not be empty")
        q = np.asarray(self.home_q, dtype=float)
        if q.ndim != 1 or q.size == 0 or not np.all(np.isfinite(q)):
            raise ValueError(f"home_q must be a non-empty sequence of finite values, got {q!r}")
        T = np.array(self.T_tip_camera, dtype=float)
        if (
            T.shape != (4, 4)
            or not np.all(np.isfinite(T))
            or not np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-9)
            or not np.isclose(np.linalg.det(T[:3, :3]), 1.0, atol=1e-9)
            or not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0])
        ):
            raise ValueError(f"T_tip_camera must be a 4 x 4 rigid transform, got {T!r}")
        T.flags.writeable = False
        object.__setattr__(self, "urdf_path", Path(self.urdf_path))
        object.__setattr__(self, "home_q", tuple(float(v) for v in q))
        object.__setattr__(self, "T_tip_camera", T)
        held = tuple((str(joint), float(value)) for joint, value in self.held_joints)
        if not all(math.isfinite(value) for _, value in held):
            raise ValueError(f"held_joints positions must be finite, got {held!r}")
        object.__setattr__(self, "held_joints", held)

    def __repr__(self) -> str:
        return (
            f"RobotModel(name={self.name!r}, urdf_path={str(self.urdf_path)!r}, "
            f"base_link={self.base_link!r}, tip_link={self.tip_link!r}, "
            f"home_q={self.home_q!r}, held_joints={self.held_joints!r})"
        )


def iiwa_model() -> RobotModel:
    """The KUKA LBR iiwa 14 of ``pybullet_data``: chain ``lbr_iiwa_link_0`` to
    ``lbr_iiwa_link_7``, home :data:`HOME_Q`, camera :func:`default_T_tip_camera`."""
    return RobotModel(
        name="iiwa",
        urdf_path=iiwa_urdf_path(),
        base_link=BASE_LINK,
        tip_link=TIP_LINK,
        home_q=HOME_Q,
        T_tip_camera=default_T_tip_camera(),
    )


def panda_model() -> RobotModel:
    """The Franka Emika Panda of ``pybullet_data``: chain ``panda_link0`` to ``panda_hand``
    (the 7 arm joints; the fixed ``panda_link8`` and hand are on the chain, the prismatic
    fingers beyond it are not and stay open at 0.04 m), home :data:`PANDA_HOME_Q`, camera
    :func:`panda_T_hand_camera`."""
    return RobotModel(
        name="panda",
        urdf_path=panda_urdf_path(),
        base_link="panda_link0",
        tip_link="panda_hand",
        home_q=PANDA_HOME_Q,
        T_tip_camera=panda_T_hand_camera(),
        held_joints=(("panda_finger_joint1", 0.04), ("panda_finger_joint2", 0.04)),
    )


#: The robot presets by name.
ROBOT_MODELS: dict[str, RobotModel] = {"iiwa": iiwa_model(), "panda": panda_model()}


def robot_model(name: str) -> RobotModel:
    """The preset robot called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`ROBOT_MODELS`: ``"iiwa"`` or ``"panda"``.

    Returns
    -------
    RobotModel
        The preset (immutable, shared).

    Raises
    ------
    ValueError
        If ``name`` is not a preset; the message lists the presets.
    """
    if name not in ROBOT_MODELS:
        raise ValueError(f"name must be one of {sorted(ROBOT_MODELS)}, got {name!r}")
    return ROBOT_MODELS[name]
