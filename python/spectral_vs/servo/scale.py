"""The servo's scale lengths, derived from the reference view when they are not given
(0): the voxel, the downsampling, the translation bounds of the registration, the depth
crop, the watchdog's jump, the occluder margin, the recovery's standoff and the arrival
check's zone. One rule, in
units of the reference's extent (:func:`spectral_vs.view_scale`'s: twice the median
distance of its points from their per-axis median); docs/servoing.md states it and the
values it gives on the simulated table. Accuracy targets (the stop rule's tolerances, the
re-engage bounds) and the robot's speed limits stay absolute: the user states them."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spectral_vs._core import PointCloud, view_scale

if TYPE_CHECKING:  # the settings read their scale from here (ServoParams.resolved)
    from spectral_vs.servo.settings import ServoParams

#: Voxels across the reference's extent (``view_scale``'s ``voxels_across``): the voxel is
#: ``max(extent / 37, 3 extent / sqrt(N))``, 15.0 mm on the simulated table (extent
#: 0.556 m, 71 k points), the 15 mm the servo was measured with.
VOXELS_ACROSS = 37.0
#: The depth crop: the reference's farthest point plus this many extents (1.50 m on the
#: simulated table, whose reference lies at 0.45-0.55 m): the reference itself is never
#: cropped, and a view turned toward the horizon loses the far floor and walls.
DEPTH_BEYOND_REFERENCE = 1.7
#: The other derived lengths, in extents (on the simulated table, 0.556 m: 0.300, 0.100,
#: 0.100, 0.050, 0.150 and 0.030 m, the absolute defaults the servo was measured with).
SHARE_OF_EXTENT: dict[str, float] = {
    "max_translation": 0.54,
    "tracking_translation": 0.18,
    "jump_limit_translation": 0.18,
    "occlusion_margin": 0.09,
    "recover_standoff": 0.27,
    "refute_translation": 0.054,
}
#: Every scale length of :class:`ServoParams`, with its group.
SCALE_LENGTHS: dict[str, str] = {
    "voxel_size": "registration",
    "downsample_size": "registration",
    "max_translation": "registration",
    "tracking_translation": "registration",
    "max_depth": "registration",
    "jump_limit_translation": "watchdog",
    "occlusion_margin": "faults",
    "recover_standoff": "recovery",
    "refute_translation": "relocalization",
}


@dataclass(frozen=True)
class ServoScale:
    """The scale lengths a :class:`~spectral_vs.servo.SpectralServo` resolved, m.

    Attributes
    ----------
    extent : float
        The reference's typical size (:func:`spectral_vs.view_scale`), m: the unit of the
        derived lengths. Measured on the reference within ``max_depth`` when that is
        given, else on the whole reference.
    points : int
        The reference's points it was measured on.
    voxel_size, downsample_size, max_translation, tracking_translation : float
        The lengths the servo uses, m (given or derived; :class:`ServoParams`).
    max_depth, jump_limit_translation, occlusion_margin, recover_standoff : float
        The same.
    refute_translation : float
        The same.
    derived : tuple of str
        The names of the lengths that were derived (given as 0).
    """

    extent: float
    points: int
    voxel_size: float
    downsample_size: float
    max_translation: float
    tracking_translation: float
    max_depth: float
    jump_limit_translation: float
    occlusion_margin: float
    recover_standoff: float
    refute_translation: float
    derived: tuple[str, ...]


#: Farthest a kept point may lie across the optical axis, in units of ``max_depth``: 2 is
#: 63 degrees off the axis at ``max_depth``, beyond any depth camera's field.
LATERAL_BEYOND_DEPTH = 2.0


def crop_to_depth(cloud: PointCloud, max_depth: float) -> PointCloud:
    """The points of ``cloud`` in front of the camera and within ``max_depth`` of it along
    its optical axis (and :data:`LATERAL_BEYOND_DEPTH` times that across it): a stray return
    kilometres off or behind the camera is no surface to register, and would size the
    grids by itself."""
    if not math.isfinite(max_depth) or len(cloud) == 0:
        return cloud
    points = np.asarray(cloud.points)
    depth = points[:, 2]
    lateral = LATERAL_BEYOND_DEPTH * max_depth
    # Reductions over the whole contiguous array are 8 times faster than over two columns.
    if depth.max() <= max_depth and depth.min() > 0 and -lateral <= points.min():
        if points.max() <= lateral:
            return cloud  # the usual case, without a mask
    x, y = points[:, 0], points[:, 1]
    keep = (depth <= max_depth) & (depth > 0) & (np.abs(x) <= lateral) & (np.abs(y) <= lateral)
    return cloud.select(keep)  # copied in the core


def derived_lengths(reference: PointCloud) -> dict[str, float]:
    """Every scale length derived from ``reference`` (camera frame, m), and its
    ``extent``: the rule of :data:`VOXELS_ACROSS`, :data:`DEPTH_BEYOND_REFERENCE` and
    :data:`SHARE_OF_EXTENT`."""
    if len(reference) == 0:
        raise ValueError("reference has no points: its scale cannot be derived")
    try:
        measured = view_scale(reference, reference, VOXELS_ACROSS)
        if not measured.extent > 0:
            raise ValueError("most of its points coincide")
    except ValueError as error:  # the points coincide: no extent
        raise ValueError(
            f"reference: its extent cannot be measured ({error}); give the scale lengths "
            f"({', '.join(SCALE_LENGTHS)}) explicitly"
        ) from error
    extent = float(measured.extent)
    lengths = {name: share * extent for name, share in SHARE_OF_EXTENT.items()}
    farthest = float(np.asarray(reference.points)[:, 2].max())
    lengths["max_depth"] = farthest + DEPTH_BEYOND_REFERENCE * extent
    lengths["voxel_size"] = float(measured.voxel_size)
    lengths["extent"] = extent
    return lengths


def resolve_scale(params: ServoParams, reference: PointCloud) -> tuple[ServoParams, ServoScale]:
    """A copy of ``params`` with every scale length given as 0 derived from ``reference``
    (as captured, camera frame, m), and the :class:`ServoScale` it resolved. The extent is
    measured within ``max_depth`` when that is given; ``downsample_size`` 0 is one voxel."""
    resolved = copy.copy(params)  # its own groups: ``params`` is left as given
    cropped = crop_to_depth(reference, resolved.max_depth) if resolved.max_depth else reference
    derived = derived_lengths(cropped)
    names = tuple(name for name in SCALE_LENGTHS if getattr(resolved, name) == 0)
    for name in names:
        if name != "downsample_size":
            setattr(resolved, name, derived[name])
    if resolved.downsample_size == 0:
        resolved.downsample_size = resolved.voxel_size
    scale = ServoScale(
        extent=derived["extent"],
        points=len(cropped),
        derived=names,
        **{name: float(getattr(resolved, name)) for name in SCALE_LENGTHS},
    )
    return resolved, scale
