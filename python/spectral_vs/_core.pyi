"""Type stubs of the compiled module spectral_vs._core (bindings/*.cpp).

Written by hand, one section per bindings file, classes in the order of the C++
structs. Fields a binding exposes with ``def_readwrite`` (or a ``def_property`` with a
setter of the same type) are plain annotations; read-only fields are ``@property``.
Shapes and units are in the comments; arrays are float64 unless said otherwise.

tests/python/test_stubs.py fails when these stubs drift from the module: it runs
``python -m mypy.stubtest spectral_vs._core`` (names, classes, read-only fields) and
compares every signature with the one pybind11 records in the docstring (parameter
names, order, keyword-only markers and literal defaults; a default that is not a
literal is written ``...``). For a new binding, read what pybind11 records, e.g.
``spectral_vs._core.voxelize.__doc__`` or the property types in ``help(AlignParams)``,
or run ``pybind11-stubgen spectral_vs._core`` and copy the new lines here in this style.
"""

import os
from typing import Any, ClassVar, Literal, TypeAlias, overload

import numpy as np
import numpy.typing as npt

_Array: TypeAlias = npt.NDArray[np.float64]
_IntArray: TypeAlias = npt.NDArray[np.int32]
_Path: TypeAlias = str | os.PathLike[str]

# String settings (occupancy, method, ...) are typed str: the bindings check them and
# raise ValueError naming the valid choices, which the comments list.

# --- Representation (bindings/representation.cpp) ---------------------------

class PointCloud:
    """Points in metres with optional unit surface normals."""

    def __init__(
        self,
        points: npt.ArrayLike,  # (N, 3) float
        normals: npt.ArrayLike | None = None,  # (N, 3) float
        *,
        drop_non_finite: bool = False,
    ) -> None: ...
    def __len__(self) -> int: ...
    @property
    def points(self) -> _Array: ...  # (N, 3), read-only view, metres
    @property
    def normals(self) -> _Array | None: ...  # (N, 3) unit normals, read-only view
    @property
    def has_normals(self) -> bool: ...
    def centroid(self) -> _Array: ...  # (3,), metres
    def select(self, keep: npt.ArrayLike) -> PointCloud: ...  # keep: (N,) bool
    def transformed(self, T_target_source: npt.ArrayLike) -> PointCloud: ...  # (4, 4) rigid

class CloudFileInfo:
    """What a point cloud file held before loading."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def points_in_file(self) -> int: ...
    @property
    def non_finite_dropped(self) -> int: ...
    @property
    def had_normals(self) -> bool: ...

def load_cloud_with_info(path: _Path) -> tuple[PointCloud, CloudFileInfo]: ...
def load_organized(path: _Path) -> _Array: ...  # (height, width, 3), NaN: no return
def save_cloud(path: _Path, cloud: PointCloud, encoding: str = "binary_compressed") -> None: ...

class DominantPlane:
    """A dominant plane (dominant_plane): n . x = offset on it."""

    @property
    def normal(self) -> _Array: ...  # (3,), unit
    @property
    def offset(self) -> float: ...  # m
    @property
    def count(self) -> int: ...
    @property
    def share(self) -> float: ...  # [0, 1]
    @property
    def extent(self) -> float: ...  # m

def dominant_direction(
    normals: npt.ArrayLike,
    direction_cone: float = 0.17453292519943295,  # 10 degrees
    member_cone: float = 0.3490658503988659,  # 20 degrees
) -> tuple[_Array, float]: ...
def dominant_plane(
    cloud: PointCloud,
    direction_cone: float = 0.17453292519943295,
    member_cone: float = 0.3490658503988659,
    offset_bin: float = 0.01,
    band: float = 0.015,
    min_share: float = 0.2,
) -> DominantPlane | None: ...
def voxel_downsample(cloud: PointCloud, voxel_size: float) -> PointCloud: ...
def prepare_cloud(
    cloud: PointCloud,
    voxel_size: float,  # metres: downsampled to half of it, normals over twice it
    downsample: bool = True,
    viewpoint: npt.ArrayLike = ...,  # (3,), metres; the origin by default
    argument: str = "cloud",  # the name every error gives the cloud
) -> PointCloud: ...
def estimate_normals(
    cloud: PointCloud,
    radius: float = 0.015,  # metres
    k_neighbors: int = 0,
    viewpoint: npt.ArrayLike = ...,  # (3,), metres; the origin by default
    orientation: str = "toward_viewpoint",  # or "outward"
    threads: int = 1,
) -> PointCloud: ...

class GridSpec:
    """Origin (m), resolution (m) and dims (voxels) of a voxel grid."""

    def __init__(self, origin: npt.ArrayLike, resolution: float, dims: npt.ArrayLike) -> None: ...
    @property
    def origin(self) -> _Array: ...  # (3,), metres
    @property
    def resolution(self) -> float: ...
    @property
    def dims(self) -> _IntArray: ...  # (3,), voxels
    @property
    def voxel_count(self) -> int: ...
    def index_of(self, point: npt.ArrayLike) -> _IntArray: ...  # (3,)

def fft_friendly_size(n: int) -> int: ...
def make_grid_spec(
    cloud_a: PointCloud, cloud_b: PointCloud, resolution: float, max_voxels: int = 16777216
) -> GridSpec: ...

class VoxelGrid:
    """Voxel values on a GridSpec (eq. 1-2)."""

    @property
    def spec(self) -> GridSpec: ...
    @property
    def values(self) -> npt.NDArray[np.float32]: ...  # (nx, ny, nz), read-only view
    @property
    def points_outside(self) -> int: ...
    @property
    def occupied_min(self) -> _IntArray: ...  # (3,)
    @property
    def occupied_max(self) -> _IntArray: ...  # (3,)

def voxelize(
    cloud: PointCloud,
    spec: GridSpec,
    occupancy: str = "binary",  # "binary", "count" or "trilinear"
    max_voxels: int = 16777216,
) -> VoxelGrid: ...
def egi(
    cloud_or_normals: PointCloud | npt.ArrayLike,  # normals: (N, 3)
    bandwidth: int,
    weights: npt.ArrayLike | None = None,  # (N,)
) -> _Array: ...  # (2B, 2B)
def egi_cell(normal: npt.ArrayLike, bandwidth: int) -> _IntArray: ...  # (2,): (j, k)
def sphere_grid(bandwidth: int) -> tuple[_Array, _Array]: ...  # theta_j (2B,), phi_k (2B,)

# --- Depth images (bindings/depth_image.cpp) ------------------------------
class OrganizedCloud:
    """The cloud of a depth image pixel by pixel (of the strided image), camera frame."""

    @property
    def height(self) -> int: ...
    @property
    def width(self) -> int: ...
    @property
    def points(self) -> _Array: ...  # (height, width, 3) metres, NaN: invalid pixel
    @property
    def normals(self) -> _Array | None: ...  # (height, width, 3), NaN: no normal
    @property
    def has_normals(self) -> bool: ...
    @property
    def valid(self) -> npt.NDArray[np.bool_]: ...  # (height, width): the rows of valid_cloud()
    def valid_cloud(self) -> PointCloud: ...

class InputWarning(UserWarning):
    """Input that is accepted but probably not what was meant, named by its argument: a
    depth_scale that puts most depths outside 0.05-50 m, a viewpoint inside the cloud it
    orients normals toward."""

class DepthScaleCheck:
    """How the depths of an image fall at a depth scale (``check_depth_scale``)."""

    @property
    def depth_scale(self) -> float: ...  # sensor units per metre
    @property
    def valid(self) -> int: ...  # pixels whose depth is finite and > 0
    @property
    def plausible(self) -> int: ...  # of them, within 0.05-50 m
    @property
    def ok(self) -> bool: ...

def check_depth_scale(
    depth: npt.ArrayLike,  # (height, width): uint16 sensor units or float32/64 metres
    *,
    depth_scale: float | None = None,  # units per metre; None: 1000 (uint16), 1 (float)
) -> DepthScaleCheck: ...
@overload
def cloud_from_depth(
    depth: npt.ArrayLike,  # (height, width): uint16 sensor units or float32/64 metres
    K: npt.ArrayLike,  # (3, 3) camera matrix, pixels
    *,
    depth_scale: float | None = None,  # units per metre; None: 1000 (uint16), 1 (float)
    min_depth: float = 0.0,  # metres
    max_depth: float = ...,  # metres, inf: no truncation
    stride: int = 1,
    organized: Literal[False] = False,
    normals: bool = True,
    normal_step: int = 2,  # pixels
    window: int = 5,  # pixels, odd
    max_depth_jump: float = 0.05,  # fraction of the depth
) -> PointCloud: ...
@overload
def cloud_from_depth(
    depth: npt.ArrayLike,
    K: npt.ArrayLike,
    *,
    depth_scale: float | None = None,
    min_depth: float = 0.0,
    max_depth: float = ...,
    stride: int = 1,
    organized: Literal[True],
    normals: bool = True,
    normal_step: int = 2,
    window: int = 5,
    max_depth_jump: float = 0.05,
) -> OrganizedCloud: ...

# --- Translation (bindings/translation.cpp) ----------------------------------

class TranslationEstimate:
    """Shift of a moving grid onto a target: target(x) ~ moving(x - shift)."""

    @property
    def shift(self) -> _Array: ...  # (3,), metres
    @property
    def shift_voxels(self) -> _Array: ...  # (3,), voxels
    @property
    def peak_voxels(self) -> _IntArray: ...  # (3,), voxels
    @property
    def peak(self) -> float: ...  # in [0, 1]

class PhaseCorrelation:
    """Phase correlation (eq. 7) against a cached target on a fixed grid."""

    def __init__(
        self,
        spec: GridSpec,
        subvoxel: bool = True,
        subvoxel_band: float = 0.25,  # cycles per voxel
        threads: int = 1,
        max_voxels: int = 16777216,
    ) -> None: ...
    def set_target(self, target: VoxelGrid) -> None: ...
    def estimate(
        self,
        moving: VoxelGrid,
        max_shift_voxels: npt.ArrayLike | None = None,  # (3,) int, voxels per axis
    ) -> TranslationEstimate: ...
    @property
    def has_target(self) -> bool: ...
    @property
    def spec(self) -> GridSpec: ...

def phase_correlation(
    grid_a: VoxelGrid | npt.ArrayLike,  # or a 3-D array
    grid_b: VoxelGrid | npt.ArrayLike,
    subvoxel: bool = True,
    subvoxel_band: float = 0.25,
    max_voxels: int = 16777216,
) -> TranslationEstimate: ...  # shift (metres), shift_voxels, peak_voxels, peak
def translation_cost(
    moving: VoxelGrid | npt.ArrayLike,
    target: VoxelGrid | npt.ArrayLike,
    shift_voxels: npt.ArrayLike,  # (3,) int, voxels
) -> float: ...

# --- Rotation (bindings/rotation.cpp) ----------------------------------------
# Coefficient arrays are flat, shape (B**2,), entry l*l + l + m.

def sh_index(l: int, m: int) -> int: ...
def real_spherical_harmonics(direction: npt.ArrayLike, lmax: int) -> _Array: ...  # ((lmax+1)**2,)
def sh_coefficients(grid: npt.ArrayLike, bandwidth: int) -> _Array: ...  # grid (2B, 2B) -> (B**2,)
def sh_synthesis(coefficients: npt.ArrayLike, bandwidth: int) -> _Array: ...  # -> (2B, 2B)
def wigner_real(R: npt.ArrayLike, lmax: int) -> list[_Array]: ...  # U^l, (2l+1, 2l+1)
def wigner_generators(
    lmax: int,
) -> tuple[list[_Array], list[_Array], list[_Array]]: ...  # (u_x, u_y, u_z)
def egi_coefficients(
    normals_or_cloud: PointCloud | npt.ArrayLike,  # normals: (N, 3)
    bandwidth: int,
    method: str = "projection",  # or "histogram"
    weights: npt.ArrayLike | None = None,  # (N,)
) -> _Array: ...  # (B**2,)
def smooth_coefficients(coefficients: npt.ArrayLike, bandwidth: int, sigma: float) -> _Array: ...

class So3Correlation:
    """The correlation C(R) of two EGI coefficient vectors, with re-used buffers."""

    def __init__(
        self,
        target_coefficients: npt.ArrayLike,
        model_coefficients: npt.ArrayLike,
        normalised: bool = True,
    ) -> None: ...
    @overload
    def evaluate(
        self, R: npt.ArrayLike, hessian: Literal[False] = False
    ) -> tuple[float, _Array]: ...  # C, gradient (3,)
    @overload
    def evaluate(
        self, R: npt.ArrayLike, hessian: Literal[True]
    ) -> tuple[float, _Array, _Array]: ...  # C, gradient (3,), Hessian (3, 3)
    @overload
    def evaluate(
        self, R: npt.ArrayLike, hessian: bool = False
    ) -> tuple[float, _Array] | tuple[float, _Array, _Array]: ...
    @property
    def bandwidth(self) -> int: ...
    @property
    def normalised(self) -> bool: ...

def so3_exp(rotation_vector: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def so3_log(R: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
def rotation_angle(R: npt.ArrayLike) -> float: ...
@overload
def so3_correlation(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    R: npt.ArrayLike,  # (3, 3) rotation
    normalised: bool = True,
    hessian: Literal[False] = False,
) -> tuple[float, _Array]: ...
@overload
def so3_correlation(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    R: npt.ArrayLike,
    normalised: bool = True,
    *,
    hessian: Literal[True],
) -> tuple[float, _Array, _Array]: ...
@overload
def so3_correlation(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    R: npt.ArrayLike,
    normalised: bool = True,
    hessian: bool = False,
) -> tuple[float, _Array] | tuple[float, _Array, _Array]: ...
def rotation_cost(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    R: npt.ArrayLike,
    normalised: bool = True,
) -> float: ...
def so3_search(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    bandwidth: int,
    k: int = 8,
    threads: int = 1,
    normalised: bool = True,
) -> list[tuple[_Array, float]]: ...  # (R (3, 3), C), best first

class RotationRefineResult:
    """Outcome of refine_rotation."""

    @property
    def R(self) -> _Array: ...  # (3, 3)
    @property
    def correlation(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def converged(self) -> bool: ...

def refine_rotation(
    target_coefficients: npt.ArrayLike,
    model_coefficients: npt.ArrayLike,
    R0: npt.ArrayLike,  # (3, 3) rotation
    gain: float = 0.05,  # radians per unit of gradient
    max_iterations: int = 100,
    gradient_tolerance: float = 1e-06,
    newton: bool = True,
    max_step: float = 0.25,  # radians
    normalised: bool = True,
) -> RotationRefineResult: ...
def _rotation_timings(bandwidth: int, repeats: int) -> dict[str, float]: ...

# --- Alignment (bindings/alignment.cpp) --------------------------------------

class SceneParams:
    """The scene and its representation (AlignParams.scene), with the C++ struct's units."""

    def __init__(
        self,
        *,
        voxel_size: float = ...,
        bandwidth: int = ...,
        occupancy: str = ...,
        egi_method: str = ...,
        sensor_origin: npt.ArrayLike = ...,
        scene_view: str = ...,
        suppress_support_plane: bool = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> SceneParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> SceneParams: ...
    voxel_size: float  # metres, 0: derived from the model (alignment_voxel_size)
    bandwidth: int
    occupancy: str  # "trilinear", "binary" or "count"
    egi_method: str  # "projection" or "histogram"
    @property
    def sensor_origin(self) -> _Array: ...  # (3,) metres
    @sensor_origin.setter
    def sensor_origin(self, value: npt.ArrayLike) -> None: ...
    scene_view: str  # "auto", "single_view" or "all_sides"
    suppress_support_plane: bool

class LocalParams:
    """Algorithm 1 (AlignParams.local), with the C++ struct's units."""

    def __init__(
        self,
        *,
        translation_gain: float = ...,
        rotation_gain: float = ...,
        rotation_step: str = ...,
        max_rotation_step: float = ...,
        tolerance: float = ...,
        max_iterations: int = ...,
        subvoxel: bool = ...,
        max_translation: float = ...,
        local_icp: bool = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> LocalParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> LocalParams: ...
    translation_gain: float
    rotation_gain: float
    rotation_step: str  # "newton" or "gradient"
    max_rotation_step: float  # radians
    tolerance: float
    max_iterations: int
    subvoxel: bool
    max_translation: float  # metres, 0: unbounded
    local_icp: bool

class GlobalSearchParams:
    """The global search (AlignParams.search), with the C++ struct's units."""

    def __init__(
        self,
        *,
        global_search: bool = ...,
        hypotheses: int = ...,
        refinements: int = ...,
        search_voxel_size: float = ...,
        window_margin: float = ...,
        guess_angle_deg: float = ...,
        guess_distance: float = ...,
        max_parts: int = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> GlobalSearchParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> GlobalSearchParams: ...
    global_search: bool
    hypotheses: int
    refinements: int
    search_voxel_size: float  # metres, 0: automatic
    window_margin: float  # metres, 0: automatic
    guess_angle_deg: float  # degrees, 0: no limit
    guess_distance: float  # metres, 0: no limit
    max_parts: int  # >= 1

class RefinementParams:
    """The refinement of the search's hypotheses (AlignParams.refinement)."""

    def __init__(
        self,
        *,
        refinement_iterations: int = ...,
        polish: bool = ...,
        icp_refinement: bool = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> RefinementParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> RefinementParams: ...
    refinement_iterations: int
    polish: bool
    icp_refinement: bool

class VerificationParams:
    """The check of the result and its alternatives (AlignParams.verification)."""

    def __init__(
        self,
        *,
        verify: bool = ...,
        max_alternatives: int = ...,
        reselect_margin: float = ...,
        expect_resting: bool = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> VerificationParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> VerificationParams: ...
    verify: bool  # without global search; False: confidence, inliers stay 0
    max_alternatives: int
    reselect_margin: float  # confidence, in [0, 1]; 1: never reselect
    expect_resting: bool  # False: a pose above the table is not floating

class AlignParams:
    """Settings of spectral_vs.align, grouped by stage (scene, local, search, refinement,
    verification); every field of a group is also a field here under the same name."""

    def __init__(
        self,
        *,
        scene: SceneParams = ...,
        voxel_size: float = ...,
        bandwidth: int = ...,
        occupancy: str = ...,
        egi_method: str = ...,
        sensor_origin: npt.ArrayLike = ...,
        scene_view: str = ...,
        suppress_support_plane: bool = ...,
        local: LocalParams = ...,
        translation_gain: float = ...,
        rotation_gain: float = ...,
        rotation_step: str = ...,
        max_rotation_step: float = ...,
        tolerance: float = ...,
        max_iterations: int = ...,
        subvoxel: bool = ...,
        max_translation: float = ...,
        local_icp: bool = ...,
        search: GlobalSearchParams = ...,
        global_search: bool = ...,
        hypotheses: int = ...,
        refinements: int = ...,
        search_voxel_size: float = ...,
        window_margin: float = ...,
        guess_angle_deg: float = ...,
        guess_distance: float = ...,
        max_parts: int = ...,
        refinement: RefinementParams = ...,
        refinement_iterations: int = ...,
        polish: bool = ...,
        icp_refinement: bool = ...,
        verification: VerificationParams = ...,
        verify: bool = ...,
        max_alternatives: int = ...,
        reselect_margin: float = ...,
        expect_resting: bool = ...,
        initial_guess: npt.ArrayLike = ...,
        threads: int = ...,
        max_seconds: float = ...,
        max_voxels: int = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> AlignParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> AlignParams: ...
    @property
    def scene(self) -> SceneParams: ...
    @scene.setter
    def scene(self, value: SceneParams) -> None: ...
    @property
    def local(self) -> LocalParams: ...
    @local.setter
    def local(self, value: LocalParams) -> None: ...
    @property
    def search(self) -> GlobalSearchParams: ...
    @search.setter
    def search(self, value: GlobalSearchParams) -> None: ...
    @property
    def refinement(self) -> RefinementParams: ...
    @refinement.setter
    def refinement(self, value: RefinementParams) -> None: ...
    @property
    def verification(self) -> VerificationParams: ...
    @verification.setter
    def verification(self, value: VerificationParams) -> None: ...
    # The groups' fields, read and written in their group.
    voxel_size: float  # metres, 0: derived from the model (alignment_voxel_size)
    bandwidth: int
    occupancy: str  # "trilinear", "binary" or "count"
    egi_method: str  # "projection" or "histogram"
    @property
    def sensor_origin(self) -> _Array: ...  # (3,) metres
    @sensor_origin.setter
    def sensor_origin(self, value: npt.ArrayLike) -> None: ...
    scene_view: str  # "auto", "single_view" or "all_sides"
    suppress_support_plane: bool
    translation_gain: float
    rotation_gain: float
    rotation_step: str  # "newton" or "gradient"
    max_rotation_step: float  # radians
    tolerance: float
    max_iterations: int
    subvoxel: bool
    max_translation: float  # metres, 0: unbounded
    local_icp: bool
    global_search: bool
    hypotheses: int
    refinements: int
    search_voxel_size: float  # metres, 0: automatic
    window_margin: float  # metres, 0: automatic
    guess_angle_deg: float  # degrees, 0: no limit
    guess_distance: float  # metres, 0: no limit
    max_parts: int  # >= 1
    refinement_iterations: int
    polish: bool
    icp_refinement: bool
    verify: bool  # without global search; False: confidence, inliers stay 0
    max_alternatives: int
    reselect_margin: float  # confidence, in [0, 1]; 1: never reselect
    expect_resting: bool  # False: a pose above the table is not floating
    # The top-level fields.
    @property
    def initial_guess(self) -> _Array: ...  # (4, 4) T_scene_model
    @initial_guess.setter
    def initial_guess(self, value: npt.ArrayLike) -> None: ...
    threads: int
    max_seconds: float  # seconds, 0: no limit
    max_voxels: int

class AlignIteration:
    """One iteration of Algorithm 1, after its update."""

    @property
    def translation_cost(self) -> float: ...
    @property
    def rotation_cost(self) -> float: ...
    @property
    def translation_step(self) -> float: ...  # voxels
    @property
    def rotation_gradient(self) -> float: ...
    @property
    def correlation(self) -> float: ...
    @property
    def translation_peak(self) -> float: ...
    @property
    def seconds(self) -> float: ...
    @property
    def T_scene_model(self) -> _Array: ...  # (4, 4)

class AlignTimings:
    """Where the time of one align() went, by stage, seconds of the wall clock (with
    threads=1, its CPU time)."""

    @property
    def preparation(self) -> float: ...
    @property
    def rotation_search(self) -> float: ...
    @property
    def placement(self) -> float: ...
    @property
    def algorithm1(self) -> float: ...
    @property
    def icp(self) -> float: ...
    @property
    def alternatives(self) -> float: ...
    @property
    def verdict(self) -> float: ...
    @property
    def total(self) -> float: ...
    def as_dict(self) -> dict[str, float]: ...

class AlignResult:
    """Outcome of align()."""

    @property
    def T_scene_model(self) -> _Array: ...  # (4, 4)
    @property
    def converged(self) -> bool: ...
    @property
    # "converged", "max_iterations", "max_seconds", "kept_start", "reselected"
    def stop_reason(self) -> str: ...
    @property
    def iterations(self) -> int: ...
    @property
    def fitness(self) -> float: ...
    @property
    def correlation(self) -> float: ...
    @property
    def translation_peak(self) -> float: ...
    @property
    def hypothesis(self) -> int: ...
    @property
    def search_voxel_size(self) -> float: ...  # metres
    @property
    def window_dims(self) -> _IntArray: ...  # (3,)
    @property
    def polish_evaluations(self) -> int: ...
    @property
    def icp_iterations(self) -> int: ...
    @property
    def refinements_run(self) -> int: ...
    @property
    def history(self) -> list[AlignIteration]: ...
    @property
    def voxel_size(self) -> float: ...  # metres
    @property
    def single_view(self) -> bool: ...
    @property
    def timings(self) -> AlignTimings: ...
    @property
    def reliable(self) -> bool: ...
    @property
    # "reliable", "ambiguous", "doubtful", "floating", "undetermined", "no_support", "max_seconds",
    # "bad_scale", "unverified"
    def status(self) -> str: ...
    @property
    def determined(self) -> bool: ...
    @property
    def rests(self) -> bool: ...  # False: a support plane was found and the pose floats
    @property
    def confidence(self) -> float: ...  # calibrated, in [0, 1]
    @property
    def score(self) -> float: ...  # uncalibrated, in [0, 1]
    @property
    def covariance(self) -> _Array: ...  # (6, 6): rotation vector (rad), translation (m)
    @property
    def inliers(self) -> int: ...
    @property
    def inlier_fraction(self) -> float: ...
    @property
    def inlier_rmse(self) -> float: ...  # metres
    @property
    def inlier_distance(self) -> float: ...  # metres
    @property
    def alternatives(self) -> list[AlignAlternative]: ...
    @property
    def ambiguous(self) -> bool: ...

class AlignAlternative:
    """Another pose that the scene supports about as well as the returned one."""

    @property
    def T_scene_model(self) -> _Array: ...  # (4, 4)
    @property
    def confidence(self) -> float: ...
    @property
    def score(self) -> float: ...
    @property
    def inliers(self) -> int: ...
    @property
    def inlier_rmse(self) -> float: ...  # metres
    @property
    def rotation_apart(self) -> float: ...  # radians
    @property
    def translation_apart(self) -> float: ...  # metres
    @property
    def symmetric(self) -> bool: ...

class PoseVerification:
    """The scene's support of one model pose (verify_pose)."""

    @property
    def inlier_distance(self) -> float: ...  # metres
    @property
    def inliers(self) -> int: ...
    @property
    def inlier_rmse(self) -> float: ...  # metres
    @property
    def inlier_fraction(self) -> float: ...
    @property
    def visible(self) -> int: ...
    @property
    def tight(self) -> int: ...
    @property
    def seen_through(self) -> int: ...
    @property
    def hidden(self) -> int: ...
    @property
    def confidence(self) -> float: ...

CONFIDENCE_THRESHOLD: float
RELIABLE_CONFIDENCE: float

def field_share(
    reference_points: npt.ArrayLike,
    T_current_reference: npt.ArrayLike,
    current_points: npt.ArrayLike,
    max_depth: float = ...,
) -> float: ...
def step_score(
    visible_fitness: float,
    carried: bool,
    reference_points: npt.ArrayLike,
    T_current_reference: npt.ArrayLike,
    current_points: npt.ArrayLike,
    relocalize_fitness: float,
    min_field_share: float = 0.3,
    max_depth: float = ...,
) -> tuple[float, float]: ...
def calibrated_confidence(
    score: float, kind: Literal["align", "views", "servo", "servo_carried"]
) -> float: ...
def covariance_inflation(kind: Literal["align", "views"]) -> float: ...
def pose_covariance(
    model: PointCloud, scene: PointCloud, T_scene_model: Any, voxel_size: float
) -> _Array: ...  # (6, 6)
def _verify_pose(
    model: PointCloud,
    scene: PointCloud,
    T_scene_model: Any,
    voxel_size: float,
    viewpoint: _Array | None,
) -> PoseVerification: ...

class AxisRotationStep:
    """One rotation step of Algorithm 1 about one axis (rotation_step_about)."""

    @property
    def turn(self) -> float: ...  # rad about the axis
    @property
    def slope(self) -> float: ...  # dC/dtheta, per rad
    @property
    def curvature(self) -> float: ...  # d2C/dtheta2, per rad^2
    @property
    def newton(self) -> bool: ...
    @property
    def capped(self) -> bool: ...

def rotation_step_about(
    correlation: So3Correlation, R: npt.ArrayLike, axis: npt.ArrayLike, params: AlignParams
) -> AxisRotationStep: ...
def _align(model: PointCloud, scene: PointCloud, params: AlignParams) -> AlignResult: ...

# --- One model onto many scenes (bindings/model_aligner.cpp) -----------------

class ModelAlignerTimings:
    """Where the time of the last ModelAligner.align went, seconds."""

    @property
    def scene_coefficients(self) -> float: ...
    @property
    def scene_map(self) -> float: ...
    @property
    def translation_grid(self) -> float: ...
    @property
    def rotation(self) -> float: ...
    @property
    def translation(self) -> float: ...
    @property
    def records(self) -> float: ...
    @property
    def fitness(self) -> float: ...
    @property
    def icp(self) -> float: ...
    @property
    def total(self) -> float: ...

class ModelAligner:
    """One model aligned onto many scenes with the same settings."""

    def __init__(self, model: PointCloud, params: AlignParams) -> None: ...
    def align(
        self, scene: PointCloud, initial_guess: npt.ArrayLike | None = None
    ) -> AlignResult: ...
    @property
    def params(self) -> AlignParams: ...
    @property
    def model(self) -> PointCloud: ...
    @property
    def model_coefficients(self) -> _Array: ...  # (bandwidth**2,)
    @property
    def last_timings(self) -> ModelAlignerTimings: ...

class PlaneTurn:
    """The turn about a reference view's dominant plane (a table top)."""

    @staticmethod
    def of(
        reference: PointCloud,
        *,
        plane_cone: float = 0.3490658503988659,
        min_plane_share: float = 0.3,
        stride: int = 4,
        bandwidth: int = 16,
        fine_bandwidth: int = 16,
        max_tilt: float = 0.08726646259971647,
        law: AlignParams = ...,
    ) -> PlaneTurn | None: ...
    def turn(self, current: PointCloud, T_current_reference: npt.ArrayLike) -> float: ...
    @property
    def axis(self) -> _Array: ...  # (3,)

# --- Two views of one scene (bindings/view_aligner.cpp) ---------------------

class ViewScale:
    """The lengths a registration works at, metres."""

    @property
    def voxel_size(self) -> float: ...
    @property
    def search_voxel_size(self) -> float: ...
    @property
    def extent(self) -> float: ...

def view_scale(
    reference: PointCloud, current: PointCloud, voxels_across: float = 32.0
) -> ViewScale: ...

class SingleViewEvidence:
    """The evidence that a scene is a single view from a point."""

    @property
    def visible(self) -> float: ...
    @property
    def single_view(self) -> bool: ...

SINGLE_VIEW_THRESHOLD: float

def detect_single_view(
    scene: PointCloud, sensor_origin: npt.ArrayLike, tolerance: float
) -> SingleViewEvidence: ...
def alignment_voxel_size(model: PointCloud, scene: PointCloud) -> float: ...

class ViewAlignParams:
    """Settings of align_views; every length 0 by default: derived from the views."""

    def __init__(
        self,
        *,
        voxel_size: float = ...,
        search_voxel_size: float = ...,
        voxels_across: float = ...,
        downsample: bool = ...,
        bandwidth: int = ...,
        hypotheses: int = ...,
        refinements: int = ...,
        refinement_iterations: int = ...,
        icp_refinement: bool = ...,
        window_search_below: float = ...,
        sensor_origin: npt.ArrayLike = ...,
        max_seconds: float = ...,
        threads: int = ...,
        occupancy: str = ...,
        egi_method: str = ...,
        max_voxels: int = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> ViewAlignParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> ViewAlignParams: ...
    voxel_size: float  # metres; 0: derived
    search_voxel_size: float  # metres; 0: twice the voxel
    voxels_across: float
    downsample: bool
    bandwidth: int
    hypotheses: int
    refinements: int
    refinement_iterations: int
    icp_refinement: bool
    window_search_below: float  # a support score in [0, 1]; 0: never
    @property
    def sensor_origin(self) -> _Array: ...  # (3,) metres
    @sensor_origin.setter
    def sensor_origin(self, value: npt.ArrayLike) -> None: ...
    max_seconds: float
    threads: int
    occupancy: str  # "trilinear", "binary" or "count"
    egi_method: str  # "projection" or "histogram"
    max_voxels: int

class ViewSupport:
    """How well the current view supports a pose of the reference."""

    @property
    def confirmed(self) -> int: ...
    @property
    def contradicted(self) -> int: ...
    @property
    def hidden(self) -> int: ...
    @property
    def reference_pixels(self) -> int: ...
    @property
    def fitness(self) -> float: ...
    @property
    def overlap(self) -> float: ...
    @property
    def score(self) -> float: ...

class ViewAlternative:
    """Another pose of the reference that the current view supports about as well."""

    @property
    def T_current_reference(self) -> _Array: ...  # (4, 4)
    @property
    def confidence(self) -> float: ...
    @property
    def score(self) -> float: ...
    @property
    def rotation_apart(self) -> float: ...  # radians
    @property
    def translation_apart(self) -> float: ...  # metres
    @property
    def symmetric(self) -> bool: ...

class ViewAlignTimings:
    """Where the time of one align_views() went, by stage, seconds of the wall clock (with
    threads=1, its CPU time)."""

    @property
    def preparation(self) -> float: ...
    @property
    def hypotheses(self) -> float: ...
    @property
    def refinement(self) -> float: ...
    @property
    def window_search(self) -> float: ...
    @property
    def verdict(self) -> float: ...
    @property
    def total(self) -> float: ...
    def as_dict(self) -> dict[str, float]: ...

class ViewAlignResult:
    """Outcome of align_views."""

    @property
    def T_current_reference(self) -> _Array: ...  # (4, 4)
    @property
    def reliable(self) -> bool: ...
    @property
    # "reliable", "ambiguous", "doubtful", "undetermined", "no_support", "max_seconds", "bad_scale"
    def status(self) -> str: ...
    @property
    def determined(self) -> bool: ...
    @property
    def confidence(self) -> float: ...  # calibrated, in [0, 1]
    @property
    def score(self) -> float: ...  # uncalibrated, in [0, 1]
    @property
    def covariance(self) -> _Array: ...  # (6, 6): rotation vector (rad), translation (m)
    @property
    def alternatives(self) -> list[ViewAlternative]: ...
    @property
    def ambiguous(self) -> bool: ...
    @property
    def inliers(self) -> int: ...
    @property
    def inlier_fraction(self) -> float: ...
    @property
    def inlier_rmse(self) -> float: ...  # metres
    @property
    def inlier_distance(self) -> float: ...  # metres
    @property
    def converged(self) -> bool: ...
    @property
    def support(self) -> ViewSupport: ...
    @property
    def correlation(self) -> float: ...
    @property
    def scale(self) -> ViewScale: ...
    @property
    def hypothesis(self) -> int: ...
    @property
    def icp_iterations(self) -> int: ...
    @property
    def windows(self) -> int: ...  # windows of the window search; 0: it did not run
    @property
    def hypotheses(self) -> list[tuple[_Array, ViewSupport]]: ...
    @property
    def timings(self) -> ViewAlignTimings: ...

def view_support(
    reference: PointCloud,
    current: PointCloud,
    T_current_reference: npt.ArrayLike,
    params: ViewAlignParams = ...,
) -> ViewSupport: ...
def align_views(
    reference: PointCloud,
    current: PointCloud,
    params: ViewAlignParams = ...,
    prior: npt.ArrayLike | None = None,
) -> ViewAlignResult: ...

# --- Kinematics (bindings/kinematics.cpp) ------------------------------------

class DampingParams:
    """Damping of the least-squares pseudo-inverse."""

    def __init__(
        self,
        *,
        singular_value_threshold: float = ...,
        max_damping: float = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> DampingParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> DampingParams: ...
    singular_value_threshold: float
    max_damping: float

class DampedSolution:
    """x = J^+ b with the damping that was used."""

    @property
    def x(self) -> _Array: ...
    @property
    def damping(self) -> float: ...
    @property
    def min_singular_value(self) -> float: ...

def damped_least_squares(
    J: npt.ArrayLike, b: npt.ArrayLike, params: DampingParams = ...
) -> DampedSolution: ...

class VelocityCommandParams:
    """Settings of Kinematics.joint_velocities."""

    def __init__(
        self,
        *,
        dt: float = ...,
        position_margin: float = ...,
        max_joint_speed: float = ...,
        damping: DampingParams = ...,
        limit_avoidance_gain: float = ...,
        limit_avoidance_exponent: float = ...,
    ) -> None: ...
    def __eq__(self, other: object) -> bool: ...
    __hash__: ClassVar[None]  # type: ignore[assignment]
    def __copy__(self) -> VelocityCommandParams: ...
    def __deepcopy__(self, memo: dict[Any, Any]) -> VelocityCommandParams: ...
    dt: float
    position_margin: float
    max_joint_speed: float
    damping: DampingParams
    limit_avoidance_gain: float
    limit_avoidance_exponent: float

class VelocityCommand:
    """A joint velocity command and how the limits shaped it."""

    @property
    def q_dot(self) -> _Array: ...  # (n,), rad/s (m/s)
    @property
    def damping(self) -> float: ...
    @property
    def min_singular_value(self) -> float: ...
    @property
    def velocity_scale(self) -> float: ...
    @property
    def position_limited(self) -> list[int]: ...

class Kinematics:
    """A serial chain of a URDF with a camera rigidly mounted on its tip link."""

    def __init__(
        self,
        urdf_path: _Path,
        base_link: str,
        tip_link: str,
        T_tip_camera: npt.ArrayLike | None = None,  # (4, 4), identity by default
    ) -> None: ...
    @staticmethod
    def from_urdf_string(
        urdf_xml: str, base_link: str, tip_link: str, T_tip_camera: npt.ArrayLike | None = None
    ) -> Kinematics: ...
    @property
    def joint_count(self) -> int: ...
    @property
    def joint_names(self) -> list[str]: ...
    @property
    def lower_limits(self) -> _Array: ...  # (n,)
    @property
    def upper_limits(self) -> _Array: ...  # (n,)
    @property
    def velocity_limits(self) -> _Array: ...  # (n,)
    @property
    def base_link(self) -> str: ...
    @property
    def tip_link(self) -> str: ...
    @property
    def T_tip_camera(self) -> _Array: ...  # (4, 4)
    def tip_pose(self, q: npt.ArrayLike) -> _Array: ...  # (4, 4) T_base_tip
    def forward(self, q: npt.ArrayLike) -> _Array: ...  # (4, 4) T_base_camera
    def jacobian(self, q: npt.ArrayLike) -> _Array: ...  # (6, n)
    def joint_velocities(
        self,
        q: npt.ArrayLike,  # (n,)
        camera_twist: npt.ArrayLike,  # (6,): v (m/s), omega (rad/s), camera frame
        params: VelocityCommandParams = ...,
    ) -> VelocityCommand: ...
