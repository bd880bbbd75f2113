#include <spectral_vs/representation/voxel_grid.hpp>

#include "common/checks.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs {

using detail::fail;

std::size_t GridSpec::voxel_count() const {
  return static_cast<std::size_t>(std::max(dims.x(), 0)) * static_cast<std::size_t>(std::max(dims.y(), 0)) *
         static_cast<std::size_t>(std::max(dims.z(), 0));
}

Eigen::Vector3i GridSpec::index_of(const Eigen::Vector3d& p) const {
  return ((p - origin) / resolution).array().floor().cast<int>();
}

bool GridSpec::contains(const Eigen::Vector3i& index) const {
  return (index.array() >= 0).all() && (index.array() < dims.array()).all();
}

int fft_friendly_size(int n) {
  for (int candidate = std::max(n, 2);; ++candidate) {
    if (candidate % 2 != 0) continue;  // even: the real-to-complex transform's fast path
    int rest = candidate;
    for (int prime : {2, 3, 5}) {
      while (rest % prime == 0) rest /= prime;
    }
    if (rest == 1) return candidate;
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
  const Eigen::Vector3d top = ((both.max() / resolution).array().floor() + 2.0).matrix() * resolution;
  for (int axis = 0; axis < 3; ++axis) {
    const double union_voxels = std::round((top[axis] - spec.origin[axis]) / resolution);
    const double a_voxels = std::floor(box_a.sizes()[axis] / resolution) + 1.0;
    const double b_voxels = std::floor(box_b.sizes()[axis] / resolution) + 1.0;
    const double needed = std::max(union_voxels, a_voxels + b_voxels + 1.0);
    if (needed > double(limits.max_voxels)) {
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
  return grid.values[(static_cast<std::size_t>(index.x()) * dims.y() + index.y()) * dims.z() +
                     index.z()];
}

void splat_trilinear(VoxelGrid& grid, const Eigen::Vector3d& p) {
  // Weights relative to the 8 voxel centres around p (centre of voxel i: origin + (i + 0.5) r).
  const Eigen::Vector3d u = (p - grid.spec.origin) / grid.spec.resolution - Eigen::Vector3d::Constant(0.5);
  const Eigen::Vector3d lower = u.array().floor();
  const Eigen::Vector3d f = u - lower;
  const Eigen::Vector3i base = lower.cast<int>();
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

}  // namespace

void voxelize_into(const Points& points, const GridSpec& spec, Occupancy occupancy,
                   VoxelGrid& grid, const GridLimits& limits) {
  check_spec(spec, limits);
  grid.spec = spec;
  grid.values.assign(spec.voxel_count(), 0.0f);
  grid.points_outside = 0;
  grid.occupied_min = spec.dims;
  grid.occupied_max = Eigen::Vector3i::Constant(-1);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = points.row(i).transpose();
    const Eigen::Vector3i index = spec.index_of(p);
    if (!spec.contains(index)) {
      ++grid.points_outside;
      continue;
    }
    switch (occupancy) {
      case Occupancy::binary: occupied_cell(grid, index) = 1.0f; break;
      case Occupancy::count: occupied_cell(grid, index) += 1.0f; break;
      case Occupancy::trilinear: splat_trilinear(grid, p); break;
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
