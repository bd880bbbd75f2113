#include <spectral_vs/representation/voxel_grid.hpp>

#include "common/checks.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace spectral_vs {

using detail::fail;

std::size_t GridSpec::voxel_count() const {
  // Saturated: (2^30)^3 wrapped to 0.
  std::size_t count = 1;
  for (int axis = 0; axis < 3; ++axis) {
    const auto side = static_cast<std::size_t>(std::max(dims[axis], 0));
    if (__builtin_mul_overflow(count, side, &count)) return std::numeric_limits<std::size_t>::max();
  }
  return count;
}

namespace {

// Transform lengths on which FFTW's estimated plans are fast, measured here as the time
// of a forward + inverse real 3D transform per voxel (benchmarks/fft_sizes.cpp): 5-12 ns
// for these, 15-30 ns for other smooth lengths such as 24, 30, 40, 54, 60, 90, 96 and 120.
constexpr int kFastLengths[] = {2,  4,   6,   8,   10,  12,  16,  20,  32,  36,  48,  64,  72,
                                80, 100, 128, 160, 200, 256, 320, 400, 512, 640, 800, 1024};

}  // namespace

int fft_friendly_size(int n) {
  if (n < 1) fail("n must be >= 1, got ", n);
  if (n > kMaxGridIndex) fail("n must be <= ", kMaxGridIndex, ", got ", n);
  for (const int length : kFastLengths) {
    if (length >= n) return length;
  }
  for (int candidate = n;; ++candidate) {  // beyond the table: even, factors 2, 3, 5
    if (candidate % 2 != 0) continue;
    int rest = candidate;
    for (int prime : {2, 3, 5}) {
      while (rest % prime == 0) rest /= prime;
    }
    if (rest == 1) return candidate;
  }
}

void check_grid_limits(const GridLimits& limits) {
  if (limits.max_voxels < 1) fail("max_voxels must be >= 1 (a voxel budget), got 0");
  if (limits.max_voxels > kMaxGridBudget) {
    fail("max_voxels must be <= 2^32 = ", kMaxGridBudget, " (a 16 GB grid), got ",
         limits.max_voxels);
  }
}

namespace {

void check_spec(const GridSpec& spec, const GridLimits& limits) {
  detail::require_positive_finite(spec.resolution, "resolution");
  if (!spec.origin.allFinite()) fail("grid origin must be finite");
  if ((spec.dims.array() < 1).any()) fail("grid dims must be >= 1, got ", spec.dims.transpose());
  const double voxels = double(spec.dims.x()) * double(spec.dims.y()) * double(spec.dims.z());
  if (voxels > double(limits.max_voxels)) {
    fail("resolution: a grid of ", spec.dims.x(), " x ", spec.dims.y(), " x ", spec.dims.z(),
         " voxels at ", spec.resolution, " m exceeds the limit of ", limits.max_voxels,
         " voxels (GridLimits::max_voxels); use a coarser resolution");
  }
}

}  // namespace

GridSpec make_grid_spec(const Eigen::AlignedBox3d& box_a, const Eigen::AlignedBox3d& box_b,
                        double resolution, const GridLimits& limits) {
  detail::require_positive_finite(resolution, "resolution");
  for (const auto* box : {&box_a, &box_b}) {
    if (box->isEmpty() || !box->min().allFinite() || !box->max().allFinite()) {
      fail("bounding box must be finite and non-empty");
    }
  }
  const Eigen::AlignedBox3d both = box_a.merged(box_b);
  GridSpec spec;
  spec.resolution = resolution;
  // One empty voxel of margin on each side; snapped so grids of other clouds align.
  spec.origin = ((both.min() / resolution).array().floor() - 1.0).matrix() * resolution;
  const Eigen::Vector3d top =
      ((both.max() / resolution).array().floor() + 2.0).matrix() * resolution;
  for (int axis = 0; axis < 3; ++axis) {
    const double union_voxels = std::round((top[axis] - spec.origin[axis]) / resolution);
    const double a_voxels = std::floor(box_a.sizes()[axis] / resolution) + 1.0;
    const double b_voxels = std::floor(box_b.sizes()[axis] / resolution) + 1.0;
    const double needed = std::max(union_voxels, a_voxels + b_voxels + 1.0);
    if (needed > double(limits.max_voxels) || needed > double(kMaxGridIndex) / 2) {
      fail("resolution: ", resolution, " m needs ", needed, " voxels along axis ", axis,
           ", over the limit of ", limits.max_voxels, " voxels (GridLimits::max_voxels)");
    }
    spec.dims[axis] = fft_friendly_size(static_cast<int>(needed));
  }
  check_spec(spec, limits);
  return spec;
}

Eigen::AlignedBox3d bounding_box(const PointCloud& cloud) {
  require_non_empty(cloud, "cloud");
  return Eigen::AlignedBox3d(cloud.points().colwise().minCoeff().transpose(),
                             cloud.points().colwise().maxCoeff().transpose());
}

namespace {

// The voxel at `index` (inside the grid), marked as occupied.
float& occupied_cell(VoxelGrid& grid, const Eigen::Vector3i& index) {
  const auto& dims = grid.spec.dims;
  grid.occupied_min = grid.occupied_min.cwiseMin(index);
  grid.occupied_max = grid.occupied_max.cwiseMax(index);
  return grid
      .values[(static_cast<std::size_t>(index.x()) * dims.y() + index.y()) * dims.z() + index.z()];
}

void splat_trilinear(VoxelGrid& grid, const Eigen::Vector3d& p) {
  // Weights relative to the 8 voxel centres around p (centre of voxel i: origin + (i + 0.5) r).
  const Eigen::Vector3d u =
      (p - grid.spec.origin) / grid.spec.resolution - Eigen::Vector3d::Constant(0.5);
  const Eigen::Vector3d lower = u.array().floor();
  const Eigen::Vector3d f = u - lower;
  const Eigen::Vector3i base = lower.cast<int>();
  const auto& dims = grid.spec.dims;
  if ((base.array() >= 0).all() && (base.array() + 1 < dims.array()).all()) {
    // The common case, all 8 corners inside: one bounds update, strided writes.
    grid.occupied_min = grid.occupied_min.cwiseMin(base);
    // A corner at f = 0 gets weight 0 and stays outside the box.
    grid.occupied_max = grid.occupied_max.cwiseMax(base + (f.array() > 0.0).cast<int>().matrix());
    const std::size_t sy = dims.z(), sx = std::size_t(dims.y()) * dims.z();
    float* cell = grid.values.data() + base.x() * sx + base.y() * sy + base.z();
    const double wx[2] = {1.0 - f.x(), f.x()}, wy[2] = {1.0 - f.y(), f.y()},
                 wz[2] = {1.0 - f.z(), f.z()};
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 2; ++k)
          cell[i * sx + j * sy + k] += static_cast<float>(wx[i] * wy[j] * wz[k]);
    return;
  }
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3i step((corner >> 2) & 1, (corner >> 1) & 1, corner & 1);
    double weight = 1.0;
    for (int axis = 0; axis < 3; ++axis) weight *= step[axis] ? f[axis] : 1.0 - f[axis];
    const Eigen::Vector3i index = base + step;
    if (weight > 0.0 && grid.spec.contains(index)) {
      occupied_cell(grid, index) += static_cast<float>(weight);
    }
  }
}

// Zeroes `grid` for a new voxelization. A grid already of this spec is zero outside its
// occupied box, so only that box is cleared: small moving clouds in a large grid cost
// their own size per iteration, not the grid's.
void reset(VoxelGrid& grid, const GridSpec& spec) {
  const bool same = grid.spec.dims == spec.dims && grid.values.size() == spec.voxel_count();
  grid.spec = spec;
  if (!same) {
    grid.values.assign(spec.voxel_count(), 0.0f);
  } else if (!grid.empty()) {
    const std::size_t ny = spec.dims.y(), nz = spec.dims.z();
    const Eigen::Vector3i& lo = grid.occupied_min;
    const Eigen::Vector3i& hi = grid.occupied_max;
    for (int i = lo.x(); i <= hi.x(); ++i)
      for (int j = lo.y(); j <= hi.y(); ++j)
        std::fill_n(grid.values.begin() + (i * ny + j) * nz + lo.z(), hi.z() - lo.z() + 1, 0.0f);
  }
  grid.points_outside = 0;
  grid.occupied_min = spec.dims;
  grid.occupied_max = Eigen::Vector3i::Constant(-1);
}

}  // namespace

void voxelize_into(const Points& points, const GridSpec& spec, Occupancy occupancy, VoxelGrid& grid,
                   const GridLimits& limits) {
  check_grid_limits(limits);  // a grid is allocated here; make_grid_spec allocates none
  check_spec(spec, limits);
  reset(grid, spec);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = points.row(i).transpose();
    const Eigen::Vector3i index = spec.index_of(p);
    if (!spec.contains(index)) {
      ++grid.points_outside;
      continue;
    }
    switch (occupancy) {
      case Occupancy::binary:
        occupied_cell(grid, index) = 1.0f;
        break;
      case Occupancy::count:
        occupied_cell(grid, index) += 1.0f;
        break;
      case Occupancy::trilinear:
        splat_trilinear(grid, p);
        break;
    }
  }
}

VoxelGrid voxelize(const PointCloud& cloud, const GridSpec& spec, Occupancy occupancy,
                   const GridLimits& limits) {
  require_non_empty(cloud, "cloud");
  VoxelGrid grid;
  voxelize_into(cloud.points(), spec, occupancy, grid, limits);
  return grid;
}

}  // namespace spectral_vs
