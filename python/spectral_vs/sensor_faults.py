"""Sensor-fault tests of the servo (docs/servoing.md, "Sensor faults"): a fingerprint that
tells a repeated frame, and the test that finds surfaces nearer to the camera than any
surface of the reference could be (a hand passing in front of the camera).

:class:`spectral_vs.servo.SpectralServo` uses both at every step; they are free functions so
that a reader, or another controller, can use one without the rest of the servo.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

#: Points of a frame that its fingerprint hashes besides its size and sums: evenly spaced.
FINGERPRINT_SAMPLES = 256

#: Bin of the ray directions with which :func:`near_occluders` measures the share of the
#: reference an occluder hides, in units of the image plane at unit depth (``x / z``,
#: ``y / z``): 0.05 is about 2.9 degrees, 25 mm across at 0.5 m.
OCCLUSION_CELL = 0.05

#: The bins reach this far from the optical axis (``x / z``, ``y / z``): 2 is 63 degrees,
#: beyond the field of view of the simulated camera (58 by 75 degrees).
_MAX_TANGENT = 2.0

#: Least share of a bin's returns that must be occluders for the bin to count as covered.
_LEAST_COVER = 0.25
#: Current points (an evenly strided subsample) from which those shares are counted.
_COVER_SAMPLE = 20000

#: Points at or behind this depth (m) have no ray direction.
_MIN_DEPTH = 1e-3


def frame_fingerprint(points: np.ndarray) -> bytes:
    """A digest that is the same for the same frame delivered twice.

    Hashes the point count, the sum of all coordinates, the sum of their bit patterns
    (every bit of every point enters it) and :data:`FINGERPRINT_SAMPLES` evenly spaced
    points, bit for bit: two captures of a real sensor differ in their noise, two renders
    of a simulation wherever the camera moved. About 0.1-0.2 ms for a 71 k-point capture.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        The frame's points, m.

    Returns
    -------
    bytes
        A 16-byte digest.
    """
    points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    digest = hashlib.blake2b(digest_size=16)
    digest.update(np.int64(len(points)).tobytes())
    if len(points):
        # Every bit of every coordinate: the wrapping sum of their 64-bit patterns (an
        # integer sum needs no BLAS; (N, 3).sum(axis=0) of the floats took 20 times longer).
        digest.update(points.ravel().view(np.int64).sum().tobytes())
        digest.update(points.ravel().sum().tobytes())
        rows = np.linspace(0, len(points) - 1, min(FINGERPRINT_SAMPLES, len(points)))
        digest.update(points[rows.astype(np.int64)].tobytes())
    return digest.digest()


def _bins(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Ray bins of camera-frame points: row and column indices, the mask of points that
    have one (in front of the camera, within :data:`_MAX_TANGENT`), and the grid's side."""
    half = math.ceil(_MAX_TANGENT / cell)
    z = points[:, 2]
    front = z > _MIN_DEPTH
    safe = np.where(front, z, 1.0)
    column = np.floor(points[:, 0] / safe / cell).astype(np.int64) + half
    row = np.floor(points[:, 1] / safe / cell).astype(np.int64) + half
    inside = front & (column >= 0) & (column < 2 * half) & (row >= 0) & (row < 2 * half)
    return row, column, inside, 2 * half


def near_occluders(
    current: np.ndarray,
    reference: np.ndarray,
    T_current_reference: np.ndarray,
    margin: float,
    cell: float = OCCLUSION_CELL,
) -> tuple[np.ndarray, float]:
    """The current points nearer to the camera than any surface of the reference could be.

    The reference is placed in the current camera frame by the estimate
    ``T_current_reference``; a current point more than ``margin`` nearer to the camera
    (along the optical axis) than the nearest of the placed reference's points is an
    occluder: something between the camera and the reference's scene, such as a hand. The
    test needs the estimate's depth only, not its alignment across the view: the edges
    of objects, a view that has drifted off the reference's, or a scene that jumped
    sideways (the watchdog's case) give no occluder.

    Parameters
    ----------
    current : ndarray, shape (N, 3)
        The current cloud, current camera frame, m.
    reference : ndarray, shape (M, 3)
        The reference cloud (a subsample serves), reference camera frame, m.
    T_current_reference : ndarray, shape (4, 4)
        Pose of the reference camera frame in the current one (the servo's predicted
        ``T_current_desired``).
    margin : float
        Depth by which a point must be nearer than the reference's nearest point, m (> 0):
        it covers the estimate's error and the depth noise.
    cell : float
        Bin of the ray directions (image-plane units at unit depth, > 0) for ``hidden``.

    Returns
    -------
    occluders : ndarray of bool, shape (N,)
        The current points that are occluders.
    hidden : float
        Share of the placed reference's points in front of the camera whose rays (binned
        by ``cell``) the occluders cover, in [0, 1]: the part of the reference the
        occluders hide, by which the registration's fitness is expected to drop. A bin is
        covered by the share of the current points in it that are occluders, from a
        quarter on, so that scattered stray returns hide nothing.

    Raises
    ------
    ValueError
        If ``margin`` or ``cell`` is not > 0, or the arrays are not (N, 3).
    """
    if not margin > 0:
        raise ValueError(f"margin must be > 0 m, got {margin}")
    if not (cell > 0 and math.isfinite(cell)):
        raise ValueError(f"cell must be finite and > 0, got {cell}")
    current = np.asarray(current, dtype=float)
    reference = np.asarray(reference, dtype=float)
    for name, array in (("current", current), ("reference", reference)):
        if array.ndim != 2 or array.shape[1] != 3:
            raise ValueError(f"{name} must be an (N, 3) array, got shape {array.shape}")
    T = np.asarray(T_current_reference, dtype=float)
    placed = reference @ T[:3, :3].T + T[:3, 3]
    front = placed[:, 2] > _MIN_DEPTH
    if not front.any() or len(current) == 0:
        return np.zeros(len(current), dtype=bool), 0.0
    occluders = current[:, 2] < placed[front, 2].min() - margin
    if not occluders.any():
        return occluders, 0.0
    row, column, inside, side = _bins(placed, cell)
    # The shares per bin from an evenly strided subsample: a bin holds hundreds of returns.
    stride = max(1, len(current) // _COVER_SAMPLE)
    occluders_sampled = occluders[::stride]
    c_row, c_column, c_inside, _ = _bins(current[::stride], cell)
    # A bin is covered by the share of the current returns along its rays that are
    # occluders, counted from a quarter on: an occluder fills its bins (its edge a part of
    # them), while stray returns (a sensor's speckle at random depths) are a few points
    # among the many of the surface behind.
    cells = c_row * side + c_column
    returns = np.bincount(cells[c_inside], minlength=side * side)
    blocked = np.bincount(cells[c_inside & occluders_sampled], minlength=side * side)
    covered = blocked / np.maximum(returns, 1)
    covered = np.where(covered >= _LEAST_COVER, covered, 0.0).reshape(side, side)
    seen = inside & front
    hidden = float(covered[row[seen], column[seen]].mean()) if seen.any() else 0.0
    return occluders, hidden


__all__ = ["FINGERPRINT_SAMPLES", "OCCLUSION_CELL", "frame_fingerprint", "near_occluders"]
