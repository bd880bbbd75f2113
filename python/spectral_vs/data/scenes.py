"""Seeded synthetic scenes with exact normals, and the milk carton's scan split into a
model and a scene that share no point: the data of ``spectral-vs demo`` and of the tests."""

from __future__ import annotations

from dataclasses import dataclass
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


@dataclass(frozen=True)
class BoxWithBall:
    """The synthetic object: a box and a ball, in metres.

    The default is the demo's object: a 20 x 12 x 8 cm box with a 7 cm ball on its top,
    the origin on the bottom face's centre.
    """

    half: tuple[float, float, float] = (0.10, 0.06, 0.04)  #: the box's half-sizes
    ball_centre: tuple[float, float, float] = (0.05, 0.0, 0.04)  #: from the box's centre
    ball_radius: float = 0.035
    #: where the box's centre is placed (every point is shifted by it last)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.04)
    bottom: bool = False  #: the box's bottom face is sampled (it stands on nothing)
    #: the ball's points inside the box and the box's inside the ball are dropped
    hidden_dropped: bool = True


def _box_by_density(
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


def _box_by_count(
    rng: np.random.Generator, half: np.ndarray, samples: int, bottom: bool
) -> tuple[np.ndarray, np.ndarray]:
    """``samples`` points and outward normals on a box's faces, each face drawn in
    proportion to its area."""
    faces = [(axis, sign) for axis in range(3) for sign in (1.0, -1.0)]
    faces = [(axis, sign) for axis, sign in faces if bottom or (axis, sign) != (2, -1.0)]
    areas = np.array([np.prod(np.delete(half, axis)) for axis, _ in faces])
    face = rng.choice(len(faces), size=samples, p=areas / areas.sum())
    axis = np.array([faces[f][0] for f in face], dtype=int)
    sign = np.array([faces[f][1] for f in face])
    rows = np.arange(samples)
    points = rng.uniform(-1, 1, size=(samples, 3)) * half
    points[rows, axis] = sign * half[axis]
    normals = np.zeros((samples, 3))
    normals[rows, axis] = sign
    return points, normals


def box_with_ball(
    rng: np.random.Generator,
    density: float | None = None,
    *,
    samples: int | None = None,
    shape: BoxWithBall = BoxWithBall(),
) -> tuple[np.ndarray, np.ndarray]:
    """Points and exact outward normals of a box with a ball (``shape``), seeded by ``rng``.

    Either ``density`` points per square metre on every surface (the demo's scenes), or
    ``samples`` points before the hidden ones are dropped: half on the ball, the rest on
    the box's faces in proportion to their areas (a ball much denser than the box, whose
    normals then weigh as much as the box's). The box first, then the ball.
    """
    if (density is None) == (samples is None):
        raise ValueError("box_with_ball: give either density or samples")
    half = np.asarray(shape.half, dtype=float)
    centre = np.asarray(shape.ball_centre, dtype=float)
    if density is not None:
        points, normals = _box_by_density(rng, half, density, shape.bottom)
        count = int(density * 4 * np.pi * shape.ball_radius**2)
    else:
        assert samples is not None
        points, normals = _box_by_count(rng, half, samples - samples // 2, shape.bottom)
        count = samples // 2
    ball = rng.normal(size=(count, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    ball_points = centre + shape.ball_radius * ball
    if shape.hidden_dropped:
        shown = ~np.all(np.abs(ball_points) <= half, axis=1)
        under = np.linalg.norm(points - centre, axis=1) < shape.ball_radius
        points, normals = points[~under], normals[~under]
        ball_points, ball = ball_points[shown], ball[shown]
    points = np.vstack([points, ball_points])
    return points + np.asarray(shape.offset), np.vstack([normals, ball])


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
        parts.append(_placed(*_box_by_density(rng, half, density), yaw, position))
    scene_points = np.vstack([p for p, _ in parts])
    scene_points = scene_points + rng.normal(0, 0.001, scene_points.shape)
    scene = PointCloud(scene_points, np.vstack([n for _, n in parts]))
    model = PointCloud(*_placed(*box_with_ball(rng, density), *pose))
    return model, scene
