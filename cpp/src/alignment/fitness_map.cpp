#include "alignment/fitness_map.hpp"

#include "alignment/normal_directions.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/scene_map.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
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
  if ((low <= high).all()) {
    if (coverage_ == Coverage::around_model) {
      record_scene((low - 1).max(0), (high + 1).min(spec_.dims.array() - 1));
    } else if (!recorded_) {
      record_scene(Eigen::Array3i::Zero(), spec_.dims.array() - 1);
      recorded_ = true;
    }
  }
  const auto [voxels, supported] = count(normals);
  return voxels ? double(supported) / double(voxels) : 0.0;
}

void FitnessMap::record_scene(const Eigen::Array3i& low, const Eigen::Array3i& high) {
  scene_low_ = low;
  scene_size_ = high - low + 1;
  scene_.assign(count_of(scene_size_), 0);
  const bool spread = coverage_ == Coverage::whole_scene;
  const Points& scene_points = scene_cloud_->points();
  const Points& scene_normals = scene_cloud_->normals();
  for (Eigen::Index i = 0; i < scene_points.rows(); ++i) {
    const Eigen::Array3i v = spec_.index_of(scene_points.row(i).transpose()).array();
    if ((v < low).any() || (v > high).any()) continue;
    std::uint32_t mask = 0;
    normal_direction(scene_normals.row(i).transpose(), &mask);
    if (!spread) {
      scene_[local(v, scene_low_, scene_size_)] |= mask;
      continue;
    }
    const Eigen::Array3i from = (v - 1).max(low), to = (v + 1).min(high);
    for (int x = from.x(); x <= to.x(); ++x)
      for (int y = from.y(); y <= to.y(); ++y) {
        std::uint32_t* row = &scene_[local(Eigen::Array3i(x, y, from.z()), low, scene_size_)];
        for (int z = 0; z <= to.z() - from.z(); ++z) row[z] |= mask;
      }
  }
}

std::pair<std::size_t, std::size_t> FitnessMap::count(const Points& normals) {
  // (voxel, nearest direction) of every model point, sorted by voxel: keys of the voxels
  // inside the spec are their linear indices, those outside (unsupported) their voxel_key
  // with the top bit set.
  constexpr std::uint64_t kOutside = std::uint64_t(1) << 63;
  const Eigen::Array3i dims = spec_.dims.array();
  seen_.clear();
  for (std::size_t i = 0; i < voxel_.size(); ++i) {
    const Eigen::Vector3i& v = voxel_[i];
    const std::uint64_t key = spec_.contains(v)
                                  ? std::uint64_t(local(v.array(), Eigen::Array3i::Zero(), dims))
                                  : kOutside | voxel_key(v.array());
    seen_.emplace_back(key, normal_direction(normals.row(Eigen::Index(i)).transpose()));
  }
  std::sort(seen_.begin(), seen_.end());
  // Each model voxel: supported when one of its points' direction is among those of the
  // scene's normals within one voxel of it.
  const Eigen::Array3i scene_high = scene_low_ + scene_size_ - 1;
  std::size_t voxels = 0, supported = 0;
  for (std::size_t i = 0; i < seen_.size();) {
    const std::uint64_t key = seen_[i].first;
    std::uint32_t near = 0;
    if (!(key & kOutside) && coverage_ == Coverage::whole_scene) {
      near = scene_[std::size_t(key)];  // spread over the neighbours when recorded
    } else if (!(key & kOutside)) {
      const Eigen::Array3i v(int(key / std::uint64_t(dims.y() * dims.z())),
                             int(key / std::uint64_t(dims.z()) % std::uint64_t(dims.y())),
                             int(key % std::uint64_t(dims.z())));
      const Eigen::Array3i from = (v - 1).max(scene_low_), to = (v + 1).min(scene_high);
      for (int x = from.x(); x <= to.x(); ++x)
        for (int y = from.y(); y <= to.y(); ++y) {
          const std::uint32_t* row =
              &scene_[local(Eigen::Array3i(x, y, from.z()), scene_low_, scene_size_)];
          for (int z = 0; z <= to.z() - from.z(); ++z) near |= row[z];
        }
    }
    bool support = false;
    for (; i < seen_.size() && seen_[i].first == key; ++i)
      support |= (near >> seen_[i].second) & 1u;
    ++voxels;
    supported += support;
  }
  return {voxels, supported};
}

}  // namespace spectral_vs::detail
