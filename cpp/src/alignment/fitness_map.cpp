#include "alignment/fitness_map.hpp"

#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace spectral_vs::detail {

namespace {

// The 26 directions to the neighbours of a voxel and the 50-degree cone of SceneMap
// (scene_map.cpp): the same table, order and arithmetic, so the same fitness.
const std::array<Eigen::Vector3d, 26>& directions() {
  static const std::array<Eigen::Vector3d, 26> table = [] {
    std::array<Eigen::Vector3d, 26> d;
    int n = 0;
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z) {
          if (x || y || z) d[n++] = Eigen::Vector3d(x, y, z).normalized();
        }
    return d;
  }();
  return table;
}

constexpr double kCone = 0.6428;  // cos(50 degrees)

// The nearest direction (the first of equals) and, in `mask`, every direction within the
// cone together with the nearest.
int nearest_direction(const Eigen::Vector3d& normal, std::uint32_t* mask = nullptr) {
  const auto& table = directions();
  int best = 0;
  double best_dot = -2.0;
  std::uint32_t within = 0;
  for (int i = 0; i < 26; ++i) {
    const double dot = table[std::size_t(i)].dot(normal);
    if (dot > best_dot) {
      best_dot = dot;
      best = i;
    }
    if (dot > kCone) within |= 1u << i;
  }
  if (mask) *mask = within | (1u << best);
  return best;
}

int voxels_along(double length, double voxel_size, const GridLimits& limits) {
  const double n = std::ceil(length / voxel_size);
  const double limit = std::min(double(limits.max_voxels), double(kMaxGridIndex) / 2);
  if (!(n <= limit)) {
    fail("voxel_size: ", length, " m is ", n, " voxels of ", voxel_size,
         " m along an axis, over the limit of ", limit, " voxels (max_voxels)");
  }
  return static_cast<int>(n);
}

}  // namespace

GridSpec FitnessMap::spec_of(const PointCloud& scene, double voxel_size, const GridLimits& limits) {
  const Eigen::AlignedBox3d box = bounding_box(scene);
  GridSpec spec;
  spec.resolution = voxel_size;
  spec.origin = ((box.min() / voxel_size).array().floor() - 2.0).matrix() * voxel_size;
  for (int axis = 0; axis < 3; ++axis) {
    spec.dims[axis] = voxels_along(box.max()[axis] - spec.origin[axis], voxel_size, limits) + 3;
  }
  if (spec.voxel_count() > limits.max_voxels) {
    fail("voxel_size: the scene spans ", spec.dims.transpose(), " voxels at ", voxel_size,
         " m, which exceeds the limit of ", limits.max_voxels, " voxels (max_voxels)");
  }
  return spec;
}

double FitnessMap::fitness(const PointCloud& scene, const GridSpec& spec, const Points& points,
                           const Points& normals) {
  const Eigen::Index n = points.rows();
  if (n == 0) return 0.0;
  // The model's voxels, and the block that holds them and their neighbours in the spec.
  voxel_.resize(std::size_t(n));
  Eigen::Array3i low = Eigen::Array3i::Constant(kMaxGridIndex),
                 high = Eigen::Array3i::Constant(-kMaxGridIndex);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3i v = spec.index_of(points.row(i).transpose());
    voxel_[std::size_t(i)] = v;
    if (spec.contains(v)) {
      low = low.min(v.array());
      high = high.max(v.array());
    }
  }
  std::size_t voxels = 0, supported = 0;
  outside_.clear();
  if ((low <= high).all()) {
    low = (low - 1).max(0);
    high = (high + 1).min(spec.dims.array() - 1);
    const Eigen::Array3i size = high - low + 1;
    const std::size_t count = std::size_t(size.x()) * std::size_t(size.y()) * std::size_t(size.z());
    const auto local = [&](const Eigen::Array3i& v) {
      const Eigen::Array3i c = v - low;
      return (std::size_t(c.x()) * std::size_t(size.y()) + std::size_t(c.y())) *
                 std::size_t(size.z()) +
             std::size_t(c.z());
    };
    scene_.assign(count, 0);
    state_.assign(count, 0);
    near_.resize(count);
    // The scene's points in the block, each in its own voxel.
    const Points& scene_points = scene.points();
    const Points& scene_normals = scene.normals();
    for (Eigen::Index i = 0; i < scene_points.rows(); ++i) {
      const Eigen::Array3i v = spec.index_of(scene_points.row(i).transpose()).array();
      if ((v < low).any() || (v > high).any()) continue;
      std::uint32_t mask = 0;
      nearest_direction(scene_normals.row(i).transpose(), &mask);
      scene_[local(v)] |= mask;
    }
    // Each model voxel: supported when one of its points' nearest direction is among
    // those of the scene's normals within one voxel of it (SceneMap's 27 neighbours).
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Vector3i& v = voxel_[std::size_t(i)];
      if (!spec.contains(v)) continue;
      const std::size_t k = local(v.array());
      std::uint8_t& state = state_[k];
      if (state == 0) {
        std::uint32_t near = 0;
        const Eigen::Array3i from = (v.array() - 1).max(low), to = (v.array() + 1).min(high);
        for (int x = from.x(); x <= to.x(); ++x)
          for (int y = from.y(); y <= to.y(); ++y)
            for (int z = from.z(); z <= to.z(); ++z) near |= scene_[local(Eigen::Array3i(x, y, z))];
        near_[k] = near;
        state = 1;
        ++voxels;
      }
      if (state == 1 && ((near_[k] >> nearest_direction(normals.row(i).transpose())) & 1u)) {
        state = 2;
        ++supported;
      }
    }
  }
  // Model voxels outside the spec count, unsupported, once each (keys as SceneMap's).
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3i& v = voxel_[std::size_t(i)];
    if (spec.contains(v)) continue;
    const Eigen::Array3i c = (v.array() + (1 << 20)).max(0).min((1 << 21) - 1);
    outside_.push_back((std::uint64_t(c.x()) << 42) | (std::uint64_t(c.y()) << 21) |
                       std::uint64_t(c.z()));
  }
  std::sort(outside_.begin(), outside_.end());
  voxels += std::size_t(std::unique(outside_.begin(), outside_.end()) - outside_.begin());
  return voxels ? double(supported) / double(voxels) : 0.0;
}

}  // namespace spectral_vs::detail
