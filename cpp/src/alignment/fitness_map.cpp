#include "alignment/fitness_map.hpp"

#include "alignment/scene_map.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <tuple>
#include <utility>

namespace spectral_vs::detail {

namespace {

// The index of voxel `v` in the block of `size` voxels from `low`, x slowest.
std::size_t local(const Eigen::Array3i& v, const Eigen::Array3i& low, const Eigen::Array3i& size) {
  const Eigen::Array3i c = v - low;
  return (std::size_t(c.x()) * std::size_t(size.y()) + std::size_t(c.y())) * std::size_t(size.z()) +
         std::size_t(c.z());
}

std::size_t count_of(const Eigen::Array3i& size) {
  return std::size_t(size.x()) * std::size_t(size.y()) * std::size_t(size.z());
}

}  // namespace

GridSpec FitnessMap::spec_of(const PointCloud& scene, double voxel_size, const GridLimits& limits) {
  return scene_map_spec(scene, voxel_size, limits);
}

void FitnessMap::set_scene(const PointCloud& scene, const GridSpec& spec, Coverage coverage) {
  scene_cloud_ = &scene;
  spec_ = spec;
  coverage_ = coverage;
  recorded_ = false;
}

double FitnessMap::fitness(const Points& points, const Points& normals) {
  const Eigen::Index n = points.rows();
  if (n == 0) return 0.0;
  // The model's voxels, and the block that holds them and their neighbours in the spec.
  voxel_.resize(std::size_t(n));
  Eigen::Array3i low = Eigen::Array3i::Constant(kMaxGridIndex),
                 high = Eigen::Array3i::Constant(-kMaxGridIndex);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3i v = spec_.index_of(points.row(i).transpose());
    voxel_[std::size_t(i)] = v;
    if (spec_.contains(v)) {
      low = low.min(v.array());
      high = high.max(v.array());
    }
  }
  std::size_t voxels = 0, supported = 0;
  if ((low <= high).all()) {
    low = (low - 1).max(0);
    high = (high + 1).min(spec_.dims.array() - 1);
    if (coverage_ == Coverage::around_model) {
      record_scene(low, high);
    } else if (!recorded_) {
      record_scene(Eigen::Array3i::Zero(), spec_.dims.array() - 1);
      recorded_ = true;
    }
    std::tie(voxels, supported) = count_inside(normals, low, high);
  }
  voxels += count_outside();
  return voxels ? double(supported) / double(voxels) : 0.0;
}

void FitnessMap::record_scene(const Eigen::Array3i& low, const Eigen::Array3i& high) {
  scene_low_ = low;
  scene_size_ = high - low + 1;
  scene_.assign(count_of(scene_size_), 0);
  const Points& scene_points = scene_cloud_->points();
  const Points& scene_normals = scene_cloud_->normals();
  for (Eigen::Index i = 0; i < scene_points.rows(); ++i) {
    const Eigen::Array3i v = spec_.index_of(scene_points.row(i).transpose()).array();
    if ((v < low).any() || (v > high).any()) continue;
    std::uint32_t mask = 0;
    normal_direction(scene_normals.row(i).transpose(), &mask);
    scene_[local(v, scene_low_, scene_size_)] |= mask;
  }
}

std::pair<std::size_t, std::size_t> FitnessMap::count_inside(const Points& normals,
                                                             const Eigen::Array3i& low,
                                                             const Eigen::Array3i& high) {
  const Eigen::Array3i size = high - low + 1;
  state_.assign(count_of(size), 0);
  near_.resize(count_of(size));
  std::size_t voxels = 0, supported = 0;
  // Each model voxel: supported when one of its points' nearest direction is among
  // those of the scene's normals within one voxel of it.
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    const Eigen::Vector3i& v = voxel_[std::size_t(i)];
    if (!spec_.contains(v)) continue;
    const std::size_t k = local(v.array(), low, size);
    std::uint8_t& state = state_[k];
    if (state == 0) {
      std::uint32_t near = 0;
      const Eigen::Array3i from = (v.array() - 1).max(low), to = (v.array() + 1).min(high);
      for (int x = from.x(); x <= to.x(); ++x)
        for (int y = from.y(); y <= to.y(); ++y)
          for (int z = from.z(); z <= to.z(); ++z)
            near |= scene_[local(Eigen::Array3i(x, y, z), scene_low_, scene_size_)];
      near_[k] = near;
      state = 1;
      ++voxels;
    }
    if (state == 1 && ((near_[k] >> normal_direction(normals.row(i).transpose())) & 1u)) {
      state = 2;
      ++supported;
    }
  }
  return {voxels, supported};
}

std::size_t FitnessMap::count_outside() {
  outside_.clear();
  for (const Eigen::Vector3i& v : voxel_) {
    if (!spec_.contains(v)) outside_.push_back(voxel_key(v.array()));
  }
  std::sort(outside_.begin(), outside_.end());
  return std::size_t(std::unique(outside_.begin(), outside_.end()) - outside_.begin());
}

}  // namespace spectral_vs::detail
