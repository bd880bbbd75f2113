#pragma once
// Internal to the aligner: the fitness of a pose (SceneMap::fitness) computed for one
// model at one pose only, with buffers kept from scene to scene (ModelAligner).

#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace spectral_vs::detail {

/// The fitness of SceneMap (scene_map.hpp), the same value, at a fraction of its cost
/// when it is wanted at one pose per scene: the scene's normal directions are recorded
/// only in the block of voxels around the model where it lies (the map of SceneMap spans
/// the whole scene), each scene point once instead of in its 27 neighbours, and the
/// model's voxels are counted in arrays kept between calls instead of sorted.
class FitnessMap {
 public:
  /// Checks that the scene's map at `voxel_size` fits `limits` (SceneMap's own check and
  /// message). @throws std::invalid_argument if it does not.
  static GridSpec spec_of(const PointCloud& scene, double voxel_size, const GridLimits& limits);

  /// SceneMap(scene, scene, voxel_size, limits).fitness(points, normals), where `spec`
  /// is spec_of(scene, voxel_size, limits).
  double fitness(const PointCloud& scene, const GridSpec& spec, const Points& points,
                 const Points& normals);

 private:
  std::vector<Eigen::Vector3i> voxel_;  // per model point: its voxel in the spec
  std::vector<std::uint32_t> scene_;    // per block voxel: directions of the scene's normals in it
  std::vector<std::uint32_t> near_;     // per block voxel: the same within one voxel (when seen)
  std::vector<std::uint8_t>
      state_;  // per block voxel: 0 no model point, 1 unsupported, 2 supported
  std::vector<std::uint64_t> outside_;  // keys of model voxels outside the spec
};

}  // namespace spectral_vs::detail
