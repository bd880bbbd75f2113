"""A simulated depth camera: PyBullet rendering, depth noise, and the organized depth image
turned into a point cloud with normals.

Frames: the camera frame is the usual vision frame (Z forward along the optical axis,
X right, Y down in the image). PyBullet's view matrix is OpenGL's (looking along -Z, Y
up): ``T_world_opengl = T_world_camera @ diag(1, -1, -1, 1)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pybullet

from spectral_vs._core import PointCloud, cloud_from_depth

#: Flip between the vision camera frame and PyBullet's OpenGL camera frame.
OPENGL_FROM_VISION = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole depth camera as PyBullet renders it.

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    vertical_fov_deg : float
        Vertical field of view, degrees (about 58 for the Ensenso N35 of the paper and a
        Kinect-class sensor).
    near, far : float
        Clipping planes, metres. Surfaces beyond ``far`` (or nothing at all) read as
        missing; surfaces nearer than ``near`` are clipped away.
    """

    width: int = 320
    height: int = 240
    vertical_fov_deg: float = 58.0
    near: float = 0.05
    far: float = 3.0

    def __post_init__(self) -> None:
        if self.width < 3 or self.height < 3:
            raise ValueError(
                f"width and height must be >= 3 pixels, got {self.width}x{self.height}"
            )
        if not 1.0 <= self.vertical_fov_deg <= 170.0:
            raise ValueError(f"vertical_fov_deg must be in [1, 170], got {self.vertical_fov_deg}")
        if not 0.0 < self.near < self.far:
            raise ValueError(f"need 0 < near < far, got near={self.near}, far={self.far}")

    @property
    def fy(self) -> float:
        """Focal length in pixels (square pixels: fx = fy)."""
        return 0.5 * self.height / math.tan(math.radians(self.vertical_fov_deg) / 2.0)

    @property
    def fx(self) -> float:
        """Horizontal focal length in pixels, equal to :attr:`fy`."""
        return self.fy

    @property
    def cx(self) -> float:
        """Column of the optical axis. PyBullet's TinyRenderer samples column u at
        x/z = (u - W/2) / fx (measured with PyBullet 3.2.7)."""
        return 0.5 * self.width

    @property
    def cy(self) -> float:
        """Row of the optical axis. TinyRenderer flips the rows of an OpenGL image whose
        centre row is H/2, so row v samples y/z = (v - (H/2 - 1)) / fy (measured)."""
        return 0.5 * self.height - 1.0

    def matrix(self) -> np.ndarray:
        """The 3 x 3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class DepthNoise:
    """Depth noise of a structured-light / stereo sensor: Gaussian along the ray with a
    standard deviation growing with depth, ``sigma(z) = sigma_0 + sigma_quadratic * z**2``,
    and a fraction of pixels with no measurement.

    Attributes
    ----------
    sigma_0 : float
        Constant part of the standard deviation, metres.
    sigma_quadratic : float
        Quadratic part, 1/m (0.0019 gives about 0.7 mm at 0.6 m and 1.9 mm at 1 m, the
        order of a Kinect-class sensor).
    missing_fraction : float
        Probability that a pixel reads as missing, in [0, 1).
    seed : int
        Seed of the noise generator; a new camera with the same seed draws the same noise.
    """

    sigma_0: float = 0.0
    sigma_quadratic: float = 0.0
    missing_fraction: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.sigma_0 < 0.0 or self.sigma_quadratic < 0.0:
            raise ValueError("sigma_0 and sigma_quadratic must be >= 0")
        if not 0.0 <= self.missing_fraction < 1.0:
            raise ValueError(f"missing_fraction must be in [0, 1), got {self.missing_fraction}")

    @classmethod
    def kinect(cls, seed: int = 0) -> DepthNoise:
        """A Kinect-class sensor: 0.5 mm + 1.9 mm/m^2 z^2 along the ray, 2% missing pixels."""
        return cls(sigma_0=0.0005, sigma_quadratic=0.0019, missing_fraction=0.02, seed=seed)

    @property
    def enabled(self) -> bool:
        """Whether any noise or missing pixels are configured."""
        return self.sigma_0 > 0.0 or self.sigma_quadratic > 0.0 or self.missing_fraction > 0.0

    def sigma(self, depth: np.ndarray) -> np.ndarray:
        """Standard deviation of the depth noise at ``depth`` (metres), metres."""
        return self.sigma_0 + self.sigma_quadratic * np.square(depth)

    def apply(self, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A noisy copy of a depth image (metres, NaN = missing)."""
        noisy = depth + self.sigma(depth) * rng.standard_normal(depth.shape)
        noisy[rng.random(depth.shape) < self.missing_fraction] = np.nan
        return noisy


@dataclass(frozen=True)
class NormalParams:
    """Normals from the organized depth image.

    The normal of pixel (v, u) is the cross product of the central differences of the
    back-projected points ``normal_step`` pixels away along the rows and the columns,
    summed over a ``window`` x ``window`` neighbourhood (an area-weighted average that
    tames depth noise), normalised and oriented toward the camera. Pixels whose
    neighbours are missing or lie across a depth jump larger than ``max_depth_jump``
    times their depth are dropped (silhouette edges have no reliable normal).

    Attributes
    ----------
    normal_step : int
        Half-baseline of the differences, pixels (>= 1).
    window : int
        Side of the averaging window, pixels (odd, >= 1).
    max_depth_jump : float
        Largest relative depth change to a stencil neighbour (fraction of the depth).
    stride : int
        Keep every ``stride``-th pixel along rows and columns (1 = all).
    """

    normal_step: int = 2
    window: int = 5
    max_depth_jump: float = 0.05
    stride: int = 1

    def __post_init__(self) -> None:
        if self.normal_step < 1:
            raise ValueError(f"normal_step must be >= 1, got {self.normal_step}")
        if self.window < 1 or self.window % 2 == 0:
            raise ValueError(f"window must be odd and >= 1, got {self.window}")
        if self.max_depth_jump <= 0.0:
            raise ValueError(f"max_depth_jump must be > 0, got {self.max_depth_jump}")
        if self.stride < 1:
            raise ValueError(f"stride must be >= 1, got {self.stride}")


@dataclass(frozen=True)
class CameraParams:
    """Everything about the simulated depth camera except where it is mounted.

    Attributes
    ----------
    intrinsics : CameraIntrinsics
        Image size, field of view and clipping planes.
    noise : DepthNoise
        Depth noise and missing pixels (none by default).
    normals : NormalParams
        How normals are computed from the organized depth image, and the pixel stride.
        Every pixel by default: a stride of 2 quarters the points to convert and
        downsample (1.5 ms less per servo step) but left the servo's final rotation error
        at a median of 0.53 instead of 0.2 degrees (docs/servoing.md).
    """

    intrinsics: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    noise: DepthNoise = field(default_factory=DepthNoise)
    normals: NormalParams = field(default_factory=NormalParams)


# --- Rendering ---------------------------------------------------------------------------


def view_matrix(T_world_camera: np.ndarray) -> list[float]:
    """PyBullet's view matrix (column-major OpenGL) for a vision camera at ``T_world_camera``.

    Parameters
    ----------
    T_world_camera : ndarray, shape (4, 4)
        Pose of the vision camera frame (Z forward, X right, Y down) in the world.

    Returns
    -------
    list of float
        The 16 entries of T_opengl_world in column-major order.
    """
    T_opengl_world = np.linalg.inv(np.asarray(T_world_camera, dtype=float) @ OPENGL_FROM_VISION)
    return T_opengl_world.T.reshape(-1).tolist()


def linearize_depth(buffer: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Metric planar depth (metres) from an OpenGL depth buffer in [0, 1]; NaN where
    nothing was hit (buffer = 1, the far plane).

    Parameters
    ----------
    buffer : ndarray, shape (H, W)
        Non-linear depth buffer as PyBullet returns it.
    intrinsics : CameraIntrinsics
        Its ``near`` and ``far`` planes undo the projection.

    Returns
    -------
    ndarray, shape (H, W)
        Depth along the optical axis, metres.
    """
    near, far = intrinsics.near, intrinsics.far
    buffer = np.asarray(buffer, dtype=np.float64)
    depth = far * near / (far - (far - near) * buffer)
    depth[buffer >= 1.0] = np.nan
    return depth


def render_depth(client, T_world_camera: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Render the planar depth image (H, W) in metres, NaN where nothing is seen.

    Parameters
    ----------
    client
        A ``pybullet_utils.bullet_client.BulletClient`` (or the ``pybullet`` module).
    T_world_camera : ndarray, shape (4, 4)
        Pose of the vision camera frame in the world.
    intrinsics : CameraIntrinsics

    Returns
    -------
    ndarray, shape (height, width)
        Depth along the optical axis, metres; NaN beyond ``far`` or where nothing is hit.
    """
    w, h = intrinsics.width, intrinsics.height
    projection = client.computeProjectionMatrixFOV(
        fov=intrinsics.vertical_fov_deg,
        aspect=w / h,
        nearVal=intrinsics.near,
        farVal=intrinsics.far,
    )
    image = client.getCameraImage(
        w,
        h,
        viewMatrix=view_matrix(T_world_camera),
        projectionMatrix=projection,
        renderer=pybullet.ER_TINY_RENDERER,
        flags=pybullet.ER_NO_SEGMENTATION_MASK,
    )
    return linearize_depth(np.reshape(image[3], (h, w)), intrinsics)


# --- Depth image -> cloud ----------------------------------------------------------------


def back_project(depth: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Organized points (H, W, 3) in the camera frame from a planar depth image (metres).

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Depth along the optical axis, metres; NaN propagates to the points.
    intrinsics : CameraIntrinsics
        The pinhole model (focal lengths and principal point).

    Returns
    -------
    ndarray, shape (H, W, 3)
        Point of each pixel, metres, camera frame.
    """
    h, w = depth.shape
    u = (np.arange(w) - intrinsics.cx) / intrinsics.fx
    v = (np.arange(h) - intrinsics.cy) / intrinsics.fy
    points = np.empty((h, w, 3))
    points[..., 0] = depth * u[np.newaxis, :]
    points[..., 1] = depth * v[:, np.newaxis]
    points[..., 2] = depth
    return points


def depth_to_cloud(
    depth: np.ndarray, intrinsics: CameraIntrinsics, params: NormalParams = NormalParams()
) -> PointCloud:
    """The point cloud with normals of a planar depth image (metres, NaN = missing), in
    the camera frame; pixels without a point or a reliable normal are dropped.

    What a real camera's frame goes through: :func:`spectral_vs.cloud_from_depth` with the
    camera matrix :meth:`CameraIntrinsics.matrix` (double precision; the tests check it
    against a NumPy reference, ``tests/python/reference_normals.py``).
    A frame that saw nothing (every pixel missing) gives an empty cloud, which a servo
    treats as a sensor outage, rather than ``cloud_from_depth``'s error.

    Parameters
    ----------
    depth : ndarray, shape (height, width)
        Depth along the optical axis, metres, as from :func:`render_depth`.
    intrinsics : CameraIntrinsics
        The camera that took it; its size must match ``depth``.
    params : NormalParams
        Normal estimation and the pixel ``stride``.

    Returns
    -------
    PointCloud
        Points and unit normals oriented toward the camera, camera frame.

    Raises
    ------
    ValueError
        If ``depth`` does not have the shape (height, width) of ``intrinsics``.
    """
    depth = np.asarray(depth, dtype=np.float64)
    expected = (intrinsics.height, intrinsics.width)
    if depth.shape != expected:
        raise ValueError(f"depth must have shape {expected} (height, width), got {depth.shape}")
    if not np.any(np.isfinite(depth) & (depth > 0.0)):  # no valid pixel
        return PointCloud(np.empty((0, 3)), np.empty((0, 3)))
    return cloud_from_depth(
        depth,
        intrinsics.matrix(),
        normal_step=params.normal_step,
        window=params.window,
        max_depth_jump=params.max_depth_jump,
        stride=params.stride,
    )
