#pragma once
/// @file voxel_grid.hpp
/// The voxel grid f_t of eq. (1)-(2): the representation used for translation.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <cstddef>
#include <vector>

namespace spectral_vs {

/// Largest voxel index magnitude along an axis: `GridSpec::index_of` clamps to
/// [-kMaxGridIndex, kMaxGridIndex], and no grid has more voxels than this along an axis.
inline constexpr int kMaxGridIndex = 1 << 30;

/// Where a grid lies and how fine it is. Voxel (i, j, k) covers
/// origin + r * [i, i+1) x [j, j+1) x [k, k+1): the index of a point p is
/// floor((p - origin) / r). (The paper's integer division truncates toward zero,
/// which makes the voxel around zero twice as wide; floor does not.)
struct GridSpec {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< Corner of voxel (0, 0, 0), metres.
  double resolution = 0.008;                         ///< Voxel edge r, metres.
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();    ///< Voxels along x, y, z.

  std::size_t voxel_count() const;  ///< dims.x dims.y dims.z, saturated at SIZE_MAX.
  /// floor((p - origin) / resolution), possibly outside [0, dims), clamped to
  /// +-kMaxGridIndex (-kMaxGridIndex for a NaN coordinate).
  Eigen::Vector3i index_of(const Eigen::Vector3d& p) const;
  bool contains(const Eigen::Vector3i& index) const;
};

// Inline: called for every point of every voxelization and fitness check.
inline Eigen::Vector3i GridSpec::index_of(const Eigen::Vector3d& p) const {
  // Clamped before the conversion, which is undefined beyond the range of int: a point
  // a million metres off a millimetre grid is far outside it, not wrapped back in.
  Eigen::Vector3i index;
  for (int axis = 0; axis < 3; ++axis) {
    const double v = std::floor((p[axis] - origin[axis]) / resolution);
    const double limit = kMaxGridIndex;
    index[axis] = v >= -limit ? (v <= limit ? static_cast<int>(v) : kMaxGridIndex) : -kMaxGridIndex;
  }
  return index;
}

inline bool GridSpec::contains(const Eigen::Vector3i& index) const {
  return (index.array() >= 0).all() && (index.array() < dims.array()).all();
}

/// Memory guard for every grid the library allocates: a grid over the limit is refused
/// with std::invalid_argument naming `max_voxels` before any of it is allocated. A voxel
/// grid takes 4 bytes per voxel, a phase correlation on it about 20 more.
struct GridLimits {
  /// Refuse grids with more voxels. The default, 2^24 (256^3), keeps an alignment's grids
  /// within about 1 GB (peak 0.94 GB measured at 2^24 voxels); it was 2^27, with which one
  /// scene with a stray point 2 m away took 3.7 GB and 16 s at 5 mm voxels.
  std::size_t max_voxels = std::size_t{256} * 256 * 256;
};

/// The largest budget: 2^32 voxels, a 16 GB grid of floats, more than the FFT buffers
/// beside it leave of most machines (a larger one gave std::bad_alloc, not an error).
inline constexpr std::size_t kMaxGridBudget = std::size_t{1} << 32;

/// @throws std::invalid_argument unless 1 <= limits.max_voxels <= kMaxGridBudget. Every
/// call that allocates a grid (voxelize, PhaseCorrelation, align, align_views) checks them
/// first; make_grid_spec, which allocates none, takes any budget.
void check_grid_limits(const GridLimits& limits);

/// Smallest transform length n' >= n on which FFTW's estimated (deterministic) plans are
/// fast: a measured table up to 1024 (lengths such as 16, 20, 32, 48, 64, 80, 100, 128;
/// not 60 or 96, which took twice the time per voxel of 64 or 100), then the even
/// products of 2, 3 and 5. Returns 2 for n <= 2.
/// @throws std::invalid_argument for n > kMaxGridIndex.
int fft_friendly_size(int n);

/// A grid holding two clouds' bounding boxes in which the circular correlation of
/// their voxel grids equals the linear one: along each axis the grid has at least
/// extent_a + extent_b + 1 voxels and covers the union of both boxes. The origin is
/// snapped to a multiple of `resolution` so that grids of different clouds align.
/// @throws std::invalid_argument for an empty or non-finite box, a non-finite or
///         non-positive resolution, or a grid over `limits.max_voxels` (the message
///         gives the dimensions and the limit).
GridSpec make_grid_spec(const Eigen::AlignedBox3d& box_a, const Eigen::AlignedBox3d& box_b,
                        double resolution, const GridLimits& limits = {});

/// Axis-aligned bounding box of a cloud's points. @throws if empty.
Eigen::AlignedBox3d bounding_box(const PointCloud& cloud);

/// What a voxel holds.
enum class Occupancy {
  binary,     ///< 1 if at least one point falls in the voxel (eq. 2, the paper's choice).
  count,      ///< Number of points in the voxel.
  trilinear,  ///< Each point spread over the 8 nearest voxel centres with trilinear weights:
              ///< a grid that moves smoothly with sub-voxel motion.
};

/// Dense grid of voxel values, x-major: value(i, j, k) = values[(i * ny + j) * nz + k].
struct VoxelGrid {
  GridSpec spec;
  std::vector<float> values;
  std::size_t points_outside = 0;  ///< Points that fell outside the grid and were ignored.
  /// Smallest and largest index of a non-zero voxel per axis (min > max when empty).
  Eigen::Vector3i occupied_min = Eigen::Vector3i::Constant(1);
  Eigen::Vector3i occupied_max = Eigen::Vector3i::Constant(0);

  bool empty() const { return (occupied_min.array() > occupied_max.array()).any(); }
  float at(int i, int j, int k) const {
    return values[(static_cast<std::size_t>(i) * spec.dims.y() + j) * spec.dims.z() + k];
  }
};

/// Voxelizes `points` into `grid`, re-using its memory when the spec is unchanged. Then
/// only the previous occupied box is cleared: a grid filled by hand must be zero outside
/// its occupied box, as every grid made here is.
/// @throws std::invalid_argument if the spec is invalid or over `limits`.
void voxelize_into(const Points& points, const GridSpec& spec, Occupancy occupancy, VoxelGrid& grid,
                   const GridLimits& limits = {});

/// Voxelizes a cloud. @throws std::invalid_argument if the cloud is empty.
VoxelGrid voxelize(const PointCloud& cloud, const GridSpec& spec,
                   Occupancy occupancy = Occupancy::binary, const GridLimits& limits = {});

}  // namespace spectral_vs
