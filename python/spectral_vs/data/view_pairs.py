"""Pairs of views of one scene for scene-to-scene registration (direct visual servoing
registers a reference view onto the current view).

Two sources of :class:`ViewPair`:

* :func:`make_view_pair` / :func:`view_pairs` cut two overlapping pixel windows out of one
  real organized scan (:func:`spectral_vs.load_organized`), keep disjoint pixels in the two
  (even ``u + v`` in the reference, odd in the current: no point is in both views) and move
  the current by a known, seeded rigid transform.
* :func:`~spectral_vs.data.rendered_pairs.sim_view_pairs` renders the wrist camera of the
  simulated iiwa (:mod:`spectral_vs.sim`) at its home pose (reference) and at seeded
  start poses (current), with the simulation's camera poses as the ground truth.

The real scans are found in :func:`~spectral_vs.data.scans.data_dir`:
``$SPECTRAL_VS_DATA``, else ``../shared/data`` (relative to the working directory);
:data:`~spectral_vs.data.scans.SCANS` names the two used here.

Normals of the scan pairs are plane fits over the ``normal_neighbors`` nearest points of the
view itself (:func:`spectral_vs.estimate_normals` with ``k_neighbors``), turned toward the
view's sensor. A neighbour count rather than a radius because the point spacing grows with
the depth: from about 2.4 mm at 1 m (table top, every other pixel of a 640 x 480 Kinect
image) to 50 mm at 9.8 m (the room at 320 x 240); a fixed radius that suits the near points
leaves the far ones without neighbours, and ``estimate_normals`` drops those.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from spectral_vs._core import PointCloud, estimate_normals, load_organized, rotation_angle
from spectral_vs.data.scan_windows import place_windows, window_view
from spectral_vs.data.scans import SCANS

#: Default window share (each window's share of the image area) of the scan pairs. At 0.5
#: every overlap down to 0.34 fits in the image (see :func:`make_view_pair`).
WINDOW_SHARE = 0.5
#: Default range of the overlap share (intersection of the two windows over one window's
#: area) that :func:`view_pairs` draws from.
OVERLAP_RANGE = (0.4, 0.8)
#: Default range of the rotation angle of ``T_current_scan``, degrees.
ROTATION_RANGE_DEG = (5.0, 60.0)
#: Default largest translation of ``T_current_scan``, metres.
MAX_TRANSLATION = 0.15
#: Default neighbour count of the normals of the scan pairs.
NORMAL_NEIGHBORS = 20
#: Fewest points a view may have.
MIN_POINTS = 100


@dataclass(frozen=True, eq=False)
class ViewPair:
    """Two views of one scene and the transform between their camera frames.

    Attributes
    ----------
    name : str
        The scene: a key of :data:`SCANS` (or the scan file's stem), or ``"sim"``.
    reference : PointCloud
        The reference view in its camera frame (sensor at the origin), metres, normals
        toward the sensor.
    current : PointCloud
        The current view in its camera frame, metres, normals toward its sensor.
    T_current_reference : ndarray, shape (4, 4)
        Ground truth: maps reference coordinates into the current's frame.
    current_viewpoint : ndarray, shape (3,)
        The current's sensor origin in the current's frame, metres (for scan pairs the
        translation of ``T_current_reference``; the origin for rendered pairs).
    overlap : float or None
        Share of a window's pixels that lie in the other window (scan pairs; the windows
        have equal sizes), None for rendered pairs.
    image_size : tuple of int
        (width, height) of the image the views come from, pixels (after downscaling).
    window_size : tuple of int or None
        (width, height) of each window, pixels (scan pairs).
    reference_window, current_window : tuple of int or None
        (u0, v0) of each window's first column and row, pixels (scan pairs).
    reference_pixels, current_pixels : ndarray of int, shape (N, 2), or None
        (u, v) pixel of every point of each view in the (downscaled) image, in the order of
        the points (scan pairs).
    """

    name: str
    reference: PointCloud
    current: PointCloud
    T_current_reference: np.ndarray
    current_viewpoint: np.ndarray
    overlap: float | None
    image_size: tuple[int, int]
    window_size: tuple[int, int] | None = None
    reference_window: tuple[int, int] | None = None
    current_window: tuple[int, int] | None = None
    reference_pixels: np.ndarray | None = None
    current_pixels: np.ndarray | None = None

    @property
    def rotation_deg(self) -> float:
        """Rotation angle of :attr:`T_current_reference`, degrees."""
        return rotation_angle_deg(self.T_current_reference[:3, :3])

    @property
    def translation(self) -> float:
        """Length of the translation of :attr:`T_current_reference`, metres."""
        return float(np.linalg.norm(self.T_current_reference[:3, 3]))


def rotation_angle_deg(R: npt.ArrayLike) -> float:
    """Angle of a rotation matrix, degrees (in [0, 180])."""
    return math.degrees(rotation_angle(np.asarray(R, dtype=float)))


def random_transform(
    rng: np.random.Generator,
    rotation_range_deg: tuple[float, float] = ROTATION_RANGE_DEG,
    max_translation: float = MAX_TRANSLATION,
) -> np.ndarray:
    """A seeded random rigid transform: rotation by an angle uniform in
    ``rotation_range_deg`` about a uniformly random axis, translation of a length uniform in
    [0, ``max_translation``] metres along a uniformly random direction.

    Returns
    -------
    ndarray, shape (4, 4)
    """
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = math.radians(rng.uniform(*rotation_range_deg))
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)
    direction = rng.normal(size=3)
    T[:3, 3] = rng.uniform(0.0, max_translation) * direction / np.linalg.norm(direction)
    return T


def _organized(scan: str | os.PathLike[str] | npt.ArrayLike) -> tuple[np.ndarray, str]:
    """The (H, W, 3) points of ``scan`` (a file or an array) and its name."""
    if isinstance(scan, str | os.PathLike):
        path = Path(scan)
        stems = {Path(file).stem: key for key, file in SCANS.items()}
        name = stems.get(path.stem, path.stem)
        points = load_organized(path)
    else:
        name, points = "scan", np.asarray(scan, dtype=float)
    if points.ndim != 3 or points.shape[2] != 3 or min(points.shape[:2]) < 2:
        raise ValueError(
            "scan must be an organized cloud of (height, width, 3) points with height and "
            f"width >= 2, got shape {points.shape}"
        )
    return points, name


def _with_normals(
    points: np.ndarray, pixels: np.ndarray, viewpoint: np.ndarray, neighbors: int
) -> tuple[PointCloud, np.ndarray]:
    """The view with normals over ``neighbors`` points toward ``viewpoint``, and the pixels
    of the points kept (estimate_normals drops points without a plane)."""
    cloud = estimate_normals(PointCloud(points), k_neighbors=neighbors, viewpoint=viewpoint)
    if len(cloud) != len(points):  # match the kept points back (coordinates are copied)
        index = {tuple(p): i for i, p in enumerate(points)}
        pixels = pixels[[index[tuple(p)] for p in cloud.points]]
    return cloud, pixels


def _check_view_pair_arguments(
    window_share: float,
    overlap: float,
    downscale: int,
    rotation_range_deg: tuple[float, float],
    max_translation: float,
    normal_neighbors: int,
) -> None:
    """make_view_pair's ranges; a ValueError naming the first argument outside its range."""
    if not 0.0 < window_share <= 1.0:
        raise ValueError(f"window_share must be in (0, 1], got {window_share}")
    if not 0.0 < overlap <= 1.0:
        raise ValueError(f"overlap must be in (0, 1], got {overlap}")
    if downscale < 1:
        raise ValueError(f"downscale must be >= 1, got {downscale}")
    low, high = rotation_range_deg
    if not 0.0 <= low <= high <= 180.0:
        raise ValueError(
            f"rotation_range_deg must be (low, high) with 0 <= low <= high <= 180, "
            f"got {rotation_range_deg}"
        )
    if not 0.0 <= max_translation < math.inf:
        raise ValueError(f"max_translation must be finite and >= 0, got {max_translation}")
    if normal_neighbors < 3:
        raise ValueError(f"normal_neighbors must be >= 3, got {normal_neighbors}")


def _two_views(
    image: np.ndarray,
    corners: tuple[tuple[int, int], tuple[int, int]],
    window: tuple[int, int],
    T: np.ndarray,
    normal_neighbors: int,
) -> tuple[tuple[PointCloud, np.ndarray], tuple[PointCloud, np.ndarray]]:
    """The reference (even pixels of its window) and the current (odd pixels, moved by T),
    each with normals facing its sensor and its pixels."""
    ref_points, ref_pixels = window_view(image, corners[0], window, parity=0)
    cur_points, cur_pixels = window_view(image, corners[1], window, parity=1)
    for label, view in (("reference", ref_points), ("current", cur_points)):
        if len(view) < MIN_POINTS:
            raise ValueError(
                f"scan gives the {label} view {len(view)} finite points, fewer than "
                f"{MIN_POINTS}: too few returns in its window"
            )
    cur_points = cur_points @ T[:3, :3].T + T[:3, 3]
    reference = _with_normals(ref_points, ref_pixels, np.zeros(3), normal_neighbors)
    return reference, _with_normals(cur_points, cur_pixels, T[:3, 3].copy(), normal_neighbors)


def make_view_pair(
    scan: str | os.PathLike[str] | npt.ArrayLike,
    *,
    window_share: float = WINDOW_SHARE,
    overlap: float = 0.6,
    downscale: int = 1,
    rotation_range_deg: tuple[float, float] = ROTATION_RANGE_DEG,
    max_translation: float = MAX_TRANSLATION,
    normal_neighbors: int = NORMAL_NEIGHBORS,
    seed: int | Sequence[int] = 0,
) -> ViewPair:
    """Two disjoint, overlapping views of one organized scan, the current moved.

    The image (every ``downscale``-th pixel along rows and columns of the scan) holds two
    windows of equal size, each ``window_share`` of its area with the image's aspect ratio,
    placed at random so that ``overlap`` of a window's pixels lie in the other. The
    reference keeps the finite points of its window's pixels with even ``u + v`` in the
    scan's camera frame; the current keeps those of its window with odd ``u + v`` and is
    moved by a random ``T_current_scan`` (:func:`random_transform`), so that its sensor
    origin is the translation of ``T_current_scan`` and the ground truth
    ``T_current_reference`` is ``T_current_scan``.

    Parameters
    ----------
    scan : str, path or array_like, shape (H, W, 3)
        A ``.pcd`` file read by :func:`spectral_vs.load_organized`, or its points, metres
        (NaN where the sensor had no return).
    window_share : float
        Share of the image area in each window, in (0, 1].
    overlap : float
        Share of a window's area inside the other window, in (0, 1]; with windows of share
        ``s`` it must be at least about ``(2 - 1/sqrt(s))^2`` for both to fit (0.34 at 0.5,
        0.5 at 0.6).
    downscale : int
        Keep every ``downscale``-th pixel along rows and columns first (2: 640 x 480 to
        320 x 240), >= 1.
    rotation_range_deg : tuple of float
        Range of the rotation angle of ``T_current_scan``, degrees, within [0, 180].
    max_translation : float
        Largest translation of ``T_current_scan``, metres, >= 0.
    normal_neighbors : int
        Neighbours of each normal's plane fit, >= 3.
    seed : int or sequence of int
        Seed of the windows and the transform (``numpy.random.default_rng``).

    Returns
    -------
    ViewPair

    Raises
    ------
    ValueError
        If ``scan`` is not organized, an argument is outside its range, the overlap does
        not fit the windows, or a view has fewer than :data:`MIN_POINTS` points.
    """
    _check_view_pair_arguments(
        window_share, overlap, downscale, rotation_range_deg, max_translation, normal_neighbors
    )
    points, name = _organized(scan)
    image = points[::downscale, ::downscale]
    H, W = image.shape[:2]
    rng = np.random.default_rng(seed)
    window, corners = place_windows(rng, (W, H), window_share, overlap)
    du, dv = corners[1][0] - corners[0][0], corners[1][1] - corners[0][1]
    T = random_transform(rng, rotation_range_deg, max_translation)

    (reference, ref_pixels), (current, cur_pixels) = _two_views(
        image, corners, window, T, normal_neighbors
    )
    viewpoint = T[:3, 3].copy()
    shared = (window[0] - abs(du)) * (window[1] - abs(dv)) / (window[0] * window[1])
    return ViewPair(
        name=name,
        reference=reference,
        current=current,
        T_current_reference=T,
        current_viewpoint=viewpoint,
        overlap=shared,
        image_size=(W, H),
        window_size=window,
        reference_window=corners[0],
        current_window=corners[1],
        reference_pixels=ref_pixels,
        current_pixels=cur_pixels,
    )


def view_pairs(
    scan: str | os.PathLike[str] | npt.ArrayLike,
    count: int,
    *,
    seed: int = 0,
    overlap_range: tuple[float, float] = OVERLAP_RANGE,
    **options,
) -> list[ViewPair]:
    """``count`` seeded pairs of one scan, the overlap of each uniform in
    ``overlap_range``.

    Pair ``i`` is ``make_view_pair(scan, overlap=..., seed=(seed, i), **options)``, so the
    first ``k`` pairs of a longer list are the pairs of a shorter one.

    Parameters
    ----------
    scan : str, path or array_like, shape (H, W, 3)
        As for :func:`make_view_pair`.
    count : int
        Number of pairs, >= 1.
    seed : int
        Seed of the list.
    overlap_range : tuple of float
        (low, high) of the overlap shares, within (0, 1].
    **options
        Other keyword arguments of :func:`make_view_pair` (``window_share``,
        ``downscale``, ...).

    Returns
    -------
    list of ViewPair

    Raises
    ------
    ValueError
        If ``count`` < 1, ``overlap_range`` is not within (0, 1], or as
        :func:`make_view_pair`.
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    low, high = overlap_range
    if not 0.0 < low <= high <= 1.0:
        raise ValueError(
            f"overlap_range must be (low, high) with 0 < low <= high <= 1, got {overlap_range}"
        )
    points, name = _organized(scan)
    pairs = []
    for i in range(count):
        overlap = float(np.random.default_rng([seed, i, 1]).uniform(low, high))
        pair = make_view_pair(points, overlap=overlap, seed=(seed, i), **options)
        pairs.append(dataclasses.replace(pair, name=name))
    return pairs


__all__ = [
    "MAX_TRANSLATION",
    "NORMAL_NEIGHBORS",
    "OVERLAP_RANGE",
    "ROTATION_RANGE_DEG",
    "WINDOW_SHARE",
    "ViewPair",
    "make_view_pair",
    "random_transform",
    "rotation_angle_deg",
    "view_pairs",
]
