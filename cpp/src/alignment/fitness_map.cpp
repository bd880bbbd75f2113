#include "alignment/fitness_map.hpp"

#include "alignment/scene_map.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace spectral_vs::detail {

GridSpec FitnessMap::spec_of(const PointCloud& scene, double voxel_size, const GridLimits& limits) {
  return scene_map_spec(scene, voxel_size, limits);
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
      normal_direction(scene_normals.row(i).transpose(), &mask);
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
      if (state == 1 && ((near_[k] >> normal_direction(normals.row(i).transpose())) & 1u)) {
        state = 2;
        ++supported;
      }
    }
  }
  // Model voxels outside the spec count, unsupported, once each (keys as SceneMap's).
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3i& v = voxel_[std::size_t(i)];
    if (spec.contains(v)) continue;
    outside_.push_back(voxel_key(v.array()));
  }
  std::sort(outside_.begin(), outside_.end());
  voxels += std::size_t(std::unique(outside_.begin(), outside_.end()) - outside_.begin());
  return voxels ? double(supported) / double(voxels) : 0.0;
}

}  // namespace spectral_vs::detail
