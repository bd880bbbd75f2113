"""The plane turn (``ServoParams.plane_turn``): the turn of each estimate about the
reference's dominant normal (a table top's) by the registration's rotation law
(:func:`spectral_vs.rotation_step_about`) on the EGIs without that plane; and the dominant
plane of a view, which the turn and the levelling recovery use."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from spectral_vs._core import (
    AlignParams,
    AxisRotationStep,
    PointCloud,
    So3Correlation,
    dominant_direction,
    egi_coefficients,
    rotation_step_about,
)
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


#: Fewest normals off the dominant plane (reference or current view) for the plane turn.
_MIN_OFF_PLANE = 50


@dataclass
class _PlaneTurn:
    """The reference's side of the turn about its dominant normal (``ServoParams.plane_turn``).

    Attributes
    ----------
    axis : ndarray, shape (3,)
        The reference's dominant normal (the table's), reference camera frame.
    centroid : ndarray, shape (3,)
        The reference's centroid, m: the registration turns the reference about it.
    coefficients : ndarray, shape (B**2,)
        EGI coefficients of the reference's normals outside ``plane_cone`` of ``axis``.
    bandwidth : int
        Their bandwidth B (the larger of ``plane_turn_bandwidth`` and ``bandwidth``).
    cos_cone : float
        Cosine of ``ServoParams.plane_cone``.
    law : AlignParams
        The rotation law the turn steps by (:func:`spectral_vs.rotation_step_about`): the
        registration's ``rotation_step`` and ``max_rotation_step`` with a
        ``rotation_gain`` of 1, so that the turn is one whole step, as the
        ``"iteration"`` estimate takes it (in ``"pose"`` mode a half Newton step after
        the converged registration left 0.6 degree about the table's normal).
    params : ServoParams
        The servo's settings (``plane_turn_stride``, ``max_rotation_step``).
    """

    axis: np.ndarray
    centroid: np.ndarray
    coefficients: np.ndarray
    bandwidth: int
    cos_cone: float
    law: AlignParams
    params: ServoParams

    @staticmethod
    def of(
        reference: PointCloud, centroid: np.ndarray, params: ServoParams, law: AlignParams
    ) -> _PlaneTurn | None:
        """The turn's reference side from the reference's normals (the cloud as captured,
        cropped), or None when the reference has no dominant plane."""
        normals = np.asarray(reference.normals)
        axis, share = dominant_normal(normals, params.plane.plane_cone)
        cos_cone = math.cos(params.plane.plane_cone)
        sampled = normals[:: params.plane.plane_turn_stride]
        off = sampled[sampled @ axis <= cos_cone]
        if share < params.plane.min_plane_share or len(off) < _MIN_OFF_PLANE:
            return None
        bandwidth = max(params.plane.plane_turn_bandwidth, params.registration.bandwidth)
        coefficients = np.asarray(egi_coefficients(off, bandwidth))
        law = copy.copy(law)
        law.rotation_gain = 1.0
        return _PlaneTurn(axis, centroid, coefficients, bandwidth, cos_cone, law, params)

    def turn(self, normals: np.ndarray, T_scene_model: np.ndarray) -> float:
        """The turn about ``axis`` (rad, right-multiplied: ``R exp(turn axis)``) that ascends
        the correlation of the off-plane EGIs from the estimate ``T_scene_model``, given the
        current cloud's normals (as captured, cropped); 0 when the current view shows too
        few normals off its plane, or when its plane's normal (the mean of its normals
        within ``plane_cone`` of where the estimate puts it) is more than
        ``plane_turn_tilt`` away from there.

        Coarse to fine: the step at the registration's bandwidth (a Newton step where the
        correlation is concave along the axis, else the gradient law, at most
        ``max_rotation_step``); where that is an uncapped Newton step and the correlation at
        ``plane_turn_bandwidth`` is concave too, its Newton step instead, if also under the
        cap. The wide low-bandwidth peak reaches far; the sharp one is exact near the goal.
        """
        R = T_scene_model[:3, :3]
        expected = R @ self.axis  # where the estimate puts the plane's normal in the view
        sampled = normals[:: self.params.plane.plane_turn_stride]
        off = sampled[sampled @ expected <= self.cos_cone]
        if len(off) < _MIN_OFF_PLANE or len(off) == len(sampled):
            return 0.0
        plane = np.ones(len(sampled)) @ sampled - off.sum(axis=0)  # sum of the in-cone normals
        if plane @ expected < math.cos(self.params.plane.plane_turn_tilt) * np.linalg.norm(plane):
            return 0.0  # the tilt is still off: the turn would be measured about a wrong axis
        fine = egi_coefficients(off, self.bandwidth)
        coarse_count = self.params.registration.bandwidth**2  # degrees < B come first
        coarse = self._step(fine[:coarse_count], self.coefficients[:coarse_count], R)
        if not coarse.newton or coarse.capped:
            return coarse.turn
        if self.bandwidth > self.params.registration.bandwidth:
            sharp = self._step(fine, self.coefficients, R)
            if sharp.newton and not sharp.capped:
                return sharp.turn
        return coarse.turn

    def _step(
        self, scene_coefficients: np.ndarray, model_coefficients: np.ndarray, R: np.ndarray
    ) -> AxisRotationStep:
        """The registration's rotation law along ``axis`` at ``R`` (in the core)."""
        correlation = So3Correlation(scene_coefficients, model_coefficients)
        return rotation_step_about(correlation, R, self.axis, self.law)

    def turned(self, T_scene_model: np.ndarray, turn: float) -> np.ndarray:
        """``T_scene_model`` with its rotation turned by ``turn`` about ``axis`` around the
        reference's centroid (the registration's centre of rotation)."""
        T = np.array(T_scene_model, dtype=float)
        R = T[:3, :3]
        R_turned = R @ rotation_matrix(turn * self.axis)
        T[:3, 3] += (R - R_turned) @ self.centroid
        T[:3, :3] = R_turned
        return T
