"""The plane turn (``ServoParams.plane_turn``): the turn of each estimate about the
reference's dominant normal (a table top's), computed in the core
(:class:`spectral_vs._core.PlaneTurn`); and the dominant plane of a view, which the levelling
recovery uses."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spectral_vs._core import AlignParams, PlaneTurn, PointCloud, dominant_direction
from spectral_vs._core import dominant_plane as _dominant_plane
from spectral_vs.poses import rotation_matrix
from spectral_vs.servo.settings import ServoParams

#: Offset bin of the dominant plane's vote, m: the levelling recovery's distance to the plane
#: is the middle of the two neighbouring bins with the most points, within 1 mm.
_PLANE_OFFSET_BIN = 0.001


def dominant_normal(normals: np.ndarray, cone: float) -> tuple[np.ndarray, float]:
    """The dominant direction of unit normals (a table top's normal) and its share: the
    core's :func:`spectral_vs.dominant_direction` (the normal with the most others within
    10 degrees, then the mean of those), the share being that of the normals within
    ``cone`` of it.

    Parameters
    ----------
    normals : ndarray, shape (N, 3)
        Unit normals.
    cone : float
        Half-angle of the cone around the direction, rad.

    Returns
    -------
    axis : ndarray, shape (3,)
        The unit direction (``(0, 0, 1)`` for no normals).
    share : float
        Share of the normals within ``cone`` of it, in [0, 1].
    """
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    axis, share = dominant_direction(normals, member_cone=cone)
    return np.asarray(axis, dtype=float), float(share)


def dominant_plane(
    points: np.ndarray,
    normals: np.ndarray,
    cone: float,
    min_share: float,
    nearest: bool = False,
) -> tuple[np.ndarray, float] | None:
    """The dominant plane of a view (a table top), camera frame: the core's
    :func:`spectral_vs.dominant_plane` with the normals within ``cone`` (rad) of its
    direction, at any distance from it, and its offset voted in 1 mm bins. Its unit normal
    ``n`` (toward the camera, as the view's normals are) and the camera's distance to it,
    ``d`` = -offset, m; None when fewer than ``min_share`` of the normals lie within ``cone``
    of its direction (:func:`dominant_normal`) or the camera is not in front of it.
    ``nearest``: of the parallel planes holding at least ``min_share`` of the points, the
    nearest to the camera (a table top rather than the floor beyond it, which a camera
    risen above the table sees more of)."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    _, share = dominant_normal(normals, cone)
    if share < min_share or share == 0.0:
        return None
    cloud = PointCloud(np.asarray(points, dtype=float).reshape(-1, 3), normals)
    plane = _dominant_plane(
        cloud, member_cone=cone, offset_bin=_PLANE_OFFSET_BIN, band=math.inf, min_share=0.0
    )
    if plane is None:
        return None
    normal = np.asarray(plane.normal, dtype=float)
    distance = -float(plane.offset)
    if nearest:
        distance = _nearest_distance(cloud, normal, cone, min_share, distance)
    return (normal, distance) if distance > 0 else None


#: Bin of the camera's distances to the parallel planes of a view, m (``nearest``): wider
#: than the depth noise across a table top.
_PARALLEL_PLANE_BIN = 0.02


def _nearest_distance(
    cloud: PointCloud, normal: np.ndarray, cone: float, min_share: float, dominant: float
) -> float:
    """The camera's distance to the nearest plane along ``normal`` holding at least
    ``min_share`` of the points of ``cloud`` (normals within ``cone``), the median over its
    bin and the next; ``dominant`` when none does."""
    points = np.asarray(cloud.points)
    member = np.asarray(cloud.normals) @ normal > math.cos(cone)
    distances = -(points[member] @ normal)
    distances = distances[distances > 0]
    if len(distances) == 0:
        return dominant
    bins = np.floor(distances / _PARALLEL_PLANE_BIN).astype(int)
    counts = np.bincount(bins)
    pairs = counts + np.append(counts[1:], 0)  # a plane across a bin edge counts whole
    enough = np.flatnonzero(pairs >= min_share * len(points))
    if len(enough) == 0:
        return dominant
    first = enough[0]
    near = distances[(bins == first) | (bins == first + 1)]
    return float(np.median(near))


def _turn_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the unit vector ``a`` to the unit vector ``b``."""
    axis = np.cross(a, b)
    sine = float(np.linalg.norm(axis))
    if sine < 1e-12:
        return np.eye(3)  # parallel (normals turned toward the camera are never opposite)
    return rotation_matrix(axis / sine * math.atan2(sine, float(a @ b)))


@dataclass
class _PlaneTurn:
    """The servo's turn about the reference's dominant normal (``ServoParams.plane_turn``):
    the core's :class:`spectral_vs._core.PlaneTurn` (the registration's rotation law along that
    normal, on the EGIs of the normals off the plane), and the turned estimate.

    Attributes
    ----------
    core : PlaneTurn
        The reference's side of the turn, made once.
    axis : ndarray, shape (3,)
        The reference's dominant normal (the table's), reference camera frame.
    centroid : ndarray, shape (3,)
        The reference's centroid, m: the registration turns the reference about it.
    """

    core: PlaneTurn
    axis: np.ndarray
    centroid: np.ndarray

    @staticmethod
    def of(
        reference: PointCloud, centroid: np.ndarray, params: ServoParams, law: AlignParams
    ) -> _PlaneTurn | None:
        """The turn's reference side from the reference (the cloud as captured, cropped),
        or None when the reference has no dominant plane. The turn steps by the
        registration's ``rotation_step`` and ``max_rotation_step`` with a gain of 1, so
        that it is one whole step, as the ``"iteration"`` estimate takes it (in ``"pose"``
        mode a half Newton step after the converged registration left 0.6 degree about
        the table's normal)."""
        plane = params.plane
        core = PlaneTurn.of(
            reference,
            plane_cone=plane.plane_cone,
            min_plane_share=plane.min_plane_share,
            stride=plane.plane_turn_stride,
            bandwidth=params.registration.bandwidth,
            fine_bandwidth=plane.plane_turn_bandwidth,
            max_tilt=plane.plane_turn_tilt,
            law=law,
        )
        if core is None:
            return None
        return _PlaneTurn(core, np.asarray(core.axis, dtype=float), np.asarray(centroid))

    def turn(self, current: PointCloud, T_scene_model: np.ndarray) -> float:
        """The turn about ``axis`` (rad, right-multiplied: ``R exp(turn axis)``) that ascends
        the correlation of the off-plane EGIs from the estimate ``T_scene_model``, given the
        current view (with normals, as captured): :meth:`spectral_vs._core.PlaneTurn.turn`."""
        return float(self.core.turn(current, T_scene_model))

    def turned(self, T_scene_model: np.ndarray, turn: float) -> np.ndarray:
        """``T_scene_model`` with its rotation turned by ``turn`` about ``axis`` around the
        reference's centroid (the registration's centre of rotation)."""
        T = np.array(T_scene_model, dtype=float)
        R = T[:3, :3]
        R_turned = R @ rotation_matrix(turn * self.axis)
        T[:3, 3] += (R - R_turned) @ self.centroid
        T[:3, :3] = R_turned
        return T
