// voxel_downsample (preprocessing.hpp): a sort of the points by voxel, in double
// precision, without PCL.
#include <spectral_vs/representation/preprocessing.hpp>

#include "common/checks.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

// The largest voxel accepted, metres (as when this ran in PCL's float leaf size).
constexpr double kMaxVoxelSize = 1e6;

struct Keyed {
  std::uint64_t key;    // linear index of the voxel, x fastest
  std::uint32_t index;  // row of the point
};

// Stable LSD radix sort by key, 8 bits per pass, as many passes as the largest key needs.
void radix_sort(std::vector<Keyed>& items, std::vector<Keyed>& scratch, std::uint64_t max_key) {
  scratch.resize(items.size());
  for (int shift = 0; shift < 64 && (max_key >> shift) != 0; shift += 8) {
    std::array<std::size_t, 257> start{};
    for (const Keyed& item : items) ++start[((item.key >> shift) & 0xFF) + 1];
    for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
    for (const Keyed& item : items) scratch[start[(item.key >> shift) & 0xFF]++] = item;
    items.swap(scratch);
  }
}

}  // namespace

PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size) {
  require_non_empty(cloud, "cloud");
  detail::require_positive_finite(voxel_size, "voxel_size");
  if (voxel_size > kMaxVoxelSize)
    fail("voxel_size must be <= ", kMaxVoxelSize, " m, got ", voxel_size);
  if (cloud.size() > std::numeric_limits<std::uint32_t>::max()) {
    fail("cloud: ", cloud.size(), " points exceed the limit of ",
         std::numeric_limits<std::uint32_t>::max());
  }
  const Points& points = cloud.points();
  const Eigen::Vector3d low = points.colwise().minCoeff(), high = points.colwise().maxCoeff();
  // Voxels are the cubes [k, k + 1) voxel_size of a lattice through the origin.
  Eigen::Array3d first, dims;
  double voxels = 1.0;
  for (int axis = 0; axis < 3; ++axis) {
    first[axis] = std::floor(low[axis] / voxel_size);
    dims[axis] = std::floor(high[axis] / voxel_size) - first[axis] + 1.0;
    voxels *= dims[axis];
  }
  const double limit = static_cast<double>(std::numeric_limits<std::int32_t>::max());
  if (!(voxels <= limit)) {
    fail("voxel_size: ", voxel_size, " m is too small for a cloud of extent ",
         (high - low).transpose(), " m: ", voxels, " voxels exceed the limit of ", limit);
  }

  const std::size_t n = cloud.size();
  std::vector<Keyed> items(n), scratch;
  const auto nx = static_cast<std::uint64_t>(dims[0]), ny = static_cast<std::uint64_t>(dims[1]);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t cell[3];
    for (int axis = 0; axis < 3; ++axis) {
      const double k = std::floor(points(Eigen::Index(i), axis) / voxel_size) - first[axis];
      // Rounding can put a point one voxel past the box's last: clamp it back.
      cell[axis] = static_cast<std::uint64_t>(std::min(std::max(k, 0.0), dims[axis] - 1.0));
    }
    items[i] = {cell[0] + nx * (cell[1] + ny * cell[2]), static_cast<std::uint32_t>(i)};
  }
  radix_sort(items, scratch, static_cast<std::uint64_t>(voxels) - 1);

  // One output row per run of equal keys: the centroid (summed relative to the box's
  // corner, so that precision follows the cloud's size) and the mean normal.
  const bool with_normals = cloud.has_normals();
  Eigen::Index voxel_count = 0;
  for (std::size_t i = 0; i < n; ++i) voxel_count += (i == 0 || items[i].key != items[i - 1].key);
  Points out_points(voxel_count, 3), out_normals(with_normals ? voxel_count : 0, 3);
  Eigen::Index kept = 0;
  for (std::size_t begin = 0; begin < n;) {
    std::size_t end = begin;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero(), normal = Eigen::Vector3d::Zero();
    for (; end < n && items[end].key == items[begin].key; ++end) {
      const Eigen::Index row = items[end].index;
      sum += (points.row(row).transpose() - low);
      if (with_normals) normal += cloud.normals().row(row).transpose();
    }
    const double count = double(end - begin);
    begin = end;
    if (with_normals) {
      normal /= count;
      if (!(normal.norm() > 1e-6)) continue;  // opposite normals cancelled: no direction left
      out_normals.row(kept) = normal.normalized().transpose();
    }
    out_points.row(kept) = (low + sum / count).transpose();
    ++kept;
  }
  if (kept < voxel_count) {  // voxels whose normals cancelled
    out_points.conservativeResize(kept, Eigen::NoChange);
    if (with_normals) out_normals.conservativeResize(kept, Eigen::NoChange);
  }
  return PointCloud(std::move(out_points), std::move(out_normals));
}

}  // namespace spectral_vs
