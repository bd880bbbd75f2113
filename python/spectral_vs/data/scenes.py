"""Seeded synthetic scenes with exact normals, and the milk carton's scan split into a
model and a scene that share no point: the data of ``spectral-vs demo`` and of the tests."""

from __future__ import annotations

from typing import Any

import numpy as np

from spectral_vs._core import PointCloud, so3_exp

#: The object of the milk scan and the scan it was cut out of (files of the data folder).
MILK_MODEL = "milk.pcd"
MILK_SCENE = "milk_cartoon_all_small_clorox.pcd"


def _yaw(angle_deg: float) -> np.ndarray:
    return so3_exp(np.array([0.0, 0.0, np.radians(angle_deg)]))


def milk_split(model: PointCloud, scene: PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint samples of the milk carton scan: the model and the scene share no point.

    ``milk.pcd`` was cut out of the scene scan, so each of its points is a scene point.
    The scene's finite points are numbered in file order; the model keeps the carton points
    whose scene number is odd, the scene keeps the points with an even number.
    """
    scene_rows = np.ascontiguousarray(scene.points.astype(np.float32))
    number = {row: i for i, row in enumerate(map(tuple, scene_rows.tolist()))}
    model_rows = model.points.astype(np.float32).tolist()
    matches = np.array([number.get(tuple(row), -1) for row in model_rows])
    if np.any(matches < 0):
        raise ValueError(
            f"model: {np.sum(matches < 0)} of its points are not in the scene (the model must "
            f"be cut out of the scene, as {MILK_MODEL} is out of {MILK_SCENE})"
        )
    model_part = np.asarray(model.points)[matches % 2 == 1]
    scene_part = np.asarray(scene.points)[0::2]
    shared = set(map(tuple, model_part.astype(np.float32).tolist()))
    shared &= set(map(tuple, scene_part.astype(np.float32).tolist()))
    if shared:
        raise RuntimeError(f"the demo's model and scene share {len(shared)} points")
    return model_part, scene_part


def _box_surface(
    rng: np.random.Generator, half: np.ndarray, density: float, bottom: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward normals on a box's faces, ``density`` points per square metre."""
    points, normals = [], []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        count = int(density * 4 * half[a] * half[b])
        for sign in (1.0, -1.0):
            if axis == 2 and sign < 0 and not bottom:
                continue
            u = rng.uniform(-1, 1, size=(count, 3)) * half
            u[:, axis] = sign * half[axis]
            n = np.zeros((count, 3))
            n[:, axis] = sign
            points.append(u)
            normals.append(n)
    return np.vstack(points), np.vstack(normals)


def box_with_ball(rng: np.random.Generator, density: float) -> tuple[np.ndarray, np.ndarray]:
    """A 20 x 12 x 8 cm box with a 7 cm ball on its top, origin on the bottom face's centre."""
    half = np.array([0.10, 0.06, 0.04])
    points, normals = _box_surface(rng, half, density)
    count = int(density * 4 * np.pi * 0.035**2)
    ball = rng.normal(size=(count, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    ball_points = np.array([0.05, 0.0, 0.04]) + 0.035 * ball
    keep = ball_points[:, 2] > 0.04
    # Drop the box top under the ball, which the ball hides.
    top = (points[:, 2] > 0.0399) & (np.linalg.norm(points[:, :2] - [0.05, 0.0], axis=1) < 0.035)
    points = np.vstack([points[~top], ball_points[keep]])
    normals = np.vstack([normals[~top], ball[keep]])
    return points + np.array([0.0, 0.0, 0.04]), normals


def _placed(points: np.ndarray, normals: np.ndarray, yaw_deg: float, position: Any):
    R = _yaw(yaw_deg)
    return points @ R.T + position, normals @ R.T


def synthetic_scene(seed: int = 0) -> tuple[PointCloud, PointCloud]:
    """A seeded table-top scene and, sampled independently, the object to find in it.

    The object is a box with a ball on top; it stands among two other boxes on a plane
    (z = 0, z up). Returns ``(object, scene)`` in scene coordinates with exact normals;
    the scene has 1 mm of noise.
    """
    rng = np.random.default_rng(seed)
    density = 60000.0  # points per square metre, about one per 4 mm
    pose = (25.0, [0.02, -0.03, 0.0])
    obstacles = [
        (np.array([0.06, 0.05, 0.07]), 10.0, [0.22, 0.13, 0.07]),
        (np.array([0.09, 0.04, 0.03]), -30.0, [-0.2, -0.17, 0.03]),
    ]
    target_points, target_normals = _placed(*box_with_ball(rng, density), *pose)
    parts = [(target_points, target_normals)]
    plane = rng.uniform([-0.45, -0.35, 0], [0.45, 0.35, 0], size=(int(density * 0.63), 3))
    hidden = np.zeros(len(plane), dtype=bool)
    footprints = [(np.array([0.10, 0.06]), *pose)]
    footprints += [(half[:2], yaw, position) for half, yaw, position in obstacles]
    for half, yaw, position in footprints:
        R = _yaw(yaw)
        local = (plane - np.asarray(position, dtype=float)) @ R
        hidden |= np.all(np.abs(local[:, :2]) <= half, axis=1)
    plane = plane[~hidden]
    parts.append((plane, np.tile([0.0, 0.0, 1.0], (len(plane), 1))))
    for half, yaw, position in obstacles:
        parts.append(_placed(*_box_surface(rng, half, density), yaw, position))
    scene_points = np.vstack([p for p, _ in parts])
    scene_points = scene_points + rng.normal(0, 0.001, scene_points.shape)
    scene = PointCloud(scene_points, np.vstack([n for _, n in parts]))
    model = PointCloud(*_placed(*box_with_ball(rng, density), *pose))
    return model, scene
