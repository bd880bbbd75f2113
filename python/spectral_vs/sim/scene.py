"""The static scene of the servoing experiment: floor, table, and a seeded clutter of
household objects from ``pybullet_data``.

World frame = robot base frame: the iiwa stands at the origin, the table top is the
plane z = 0 and the floor is at z = -TABLE_HEIGHT.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet_data

#: Height of the top of pybullet_data's table/table.urdf above its origin, metres.
TABLE_HEIGHT = 0.625

#: Objects of pybullet_data used for clutter (URDF, scale): 5-15 cm household items.
DEFAULT_OBJECTS: tuple[tuple[str, float], ...] = (
    ("duck_vhacd.urdf", 1.2),
    ("objects/mug.urdf", 1.0),
    ("teddy_vhacd.urdf", 1.2),
    ("lego/lego.urdf", 2.0),
    ("jenga/jenga.urdf", 1.0),
    ("random_urdfs/000/000.urdf", 1.0),
    ("cube_small.urdf", 1.0),
    ("random_urdfs/002/002.urdf", 1.0),
)


@dataclass(frozen=True)
class TableSceneParams:
    """The table and its clutter.

    Attributes
    ----------
    object_count : int
        Number of objects on the table, taken in order from ``objects`` (cycling).
    objects : tuple of (str, float)
        URDF paths relative to ``pybullet_data`` and their global scale factors.
    clutter_center : tuple of float
        Centre (x, y) of the clutter area on the table, metres, world frame.
    clutter_size : tuple of float
        Side lengths (x, y) of the clutter area, metres.
    min_gap : float
        Smallest gap between the footprints of two objects, metres.
    seed : int
        Seed of the placement (positions and yaw angles).
    table_center : tuple of float
        Centre (x, y) of the 1.5 x 1.0 m table, metres.
    """

    object_count: int = 8
    objects: tuple[tuple[str, float], ...] = DEFAULT_OBJECTS
    clutter_center: tuple[float, float] = (0.6, 0.0)
    clutter_size: tuple[float, float] = (0.45, 0.6)
    min_gap: float = 0.005
    seed: int = 0
    table_center: tuple[float, float] = (0.55, 0.0)

    def __post_init__(self) -> None:
        if self.object_count < 0:
            raise ValueError(f"object_count must be >= 0, got {self.object_count}")
        if self.object_count > 0 and not self.objects:
            raise ValueError("objects is empty but object_count > 0")


@dataclass(frozen=True)
class PlacedObject:
    """An object of the scene: its PyBullet body id, URDF and pose.

    Attributes
    ----------
    body_id : int
        PyBullet body unique id.
    urdf : str
        URDF path relative to ``pybullet_data``.
    position : tuple of float
        Position (x, y, z) of the URDF's frame, metres, world frame.
    yaw : float
        Rotation about the vertical axis, radians.
    """

    body_id: int
    urdf: str
    position: tuple[float, float, float]
    yaw: float


def build_scene(client, params: TableSceneParams) -> list[PlacedObject]:
    """Load the floor, the table and the clutter into ``client`` (static bodies).

    Each object gets a random yaw and a random place in the clutter area where its
    axis-aligned footprint keeps ``min_gap`` from the others (rejection sampling,
    restarted from the first object when one does not fit); all rest on the table top
    and are static, so the scene depends only on the seed.

    Parameters
    ----------
    client
        A ``pybullet_utils.bullet_client.BulletClient`` (or the ``pybullet`` module).
    params : TableSceneParams
        The table and the clutter.

    Returns
    -------
    list of PlacedObject
        The clutter objects in the order they were loaded.

    Raises
    ------
    RuntimeError
        If the objects cannot be placed without overlap in the clutter area.
    """
    client.setAdditionalSearchPath(pybullet_data.getDataPath())
    client.loadURDF("plane.urdf", basePosition=[0.0, 0.0, -TABLE_HEIGHT], useFixedBase=True)
    cx, cy = params.table_center
    client.loadURDF("table/table.urdf", basePosition=[cx, cy, -TABLE_HEIGHT], useFixedBase=True)

    rng = np.random.default_rng(params.seed)
    bodies = []
    for i in range(params.object_count):
        urdf, scale = params.objects[i % len(params.objects)]
        yaw = float(rng.uniform(-math.pi, math.pi))
        orientation = client.getQuaternionFromEuler([0.0, 0.0, yaw])
        body = client.loadURDF(
            urdf, baseOrientation=orientation, globalScaling=scale, useFixedBase=True
        )
        bodies.append((body, urdf, yaw, *(np.asarray(v) for v in client.getAABB(body, -1))))
    centers = _footprint_centers(
        [0.5 * (high[:2] - low[:2]) for *_, low, high in bodies], params, rng
    )

    placed = []
    for (body, urdf, yaw, low, high), center in zip(bodies, centers, strict=True):
        # The URDF frame is at the origin: shift the body so its footprint is centred at
        # `center` and its lowest point touches the table (resetBasePositionAndOrientation
        # places the inertial frame, so move that by the same shift).
        shift = np.array([*(center - 0.5 * (high[:2] + low[:2])), -low[2]])
        inertial, orientation = client.getBasePositionAndOrientation(body)
        client.resetBasePositionAndOrientation(
            body, (np.asarray(inertial) + shift).tolist(), orientation
        )
        x, y, z = (float(v) for v in shift)
        placed.append(PlacedObject(body, urdf, (x, y, z), yaw))
    return placed


def _footprint_centers(
    halves, params: TableSceneParams, rng: np.random.Generator
) -> list[np.ndarray]:
    """Centres of non-overlapping boxes of half sizes ``halves`` in the clutter area."""
    area_half = 0.5 * np.asarray(params.clutter_size)
    center = np.asarray(params.clutter_center)
    gap = 0.5 * params.min_gap
    for _ in range(100):
        boxes: list[tuple[np.ndarray, np.ndarray]] = []
        for half in halves:
            room = np.maximum(area_half - half, 0.0)
            for _ in range(100):
                xy = center + rng.uniform(-room, room)
                box = (xy - half - gap, xy + half + gap)
                if all(np.any(box[1] < lo) or np.any(box[0] > hi) for lo, hi in boxes):
                    boxes.append(box)
                    break
            else:
                break
        if len(boxes) == len(halves):
            return [0.5 * (lo + hi) for lo, hi in boxes]
    raise RuntimeError(
        f"could not place {len(halves)} objects without overlap in a {params.clutter_size} m area: "
        "lower object_count or enlarge clutter_size"
    )
