#pragma once
// Internal to the aligner: the verification's screen of a scene seen from all sides
// (verifier.hpp), at many poses per scene (align()) or one (ModelAligner).

#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

namespace spectral_vs::detail {

/// Fraction of the occupied voxels of a moved model that lie within one voxel of a scene
/// point whose normal is within about 50 degrees of theirs, in [0, 1]; model voxels
/// outside the scene's grid count, unsupported. The model's voxels are found by sorting
/// its points by voxel; a scene point's normal directions are recorded in the 27 voxels
/// around its own (whole_scene: a model voxel then reads one) or in its own only
/// (around_model: a model voxel reads the 27 around it).
class FitnessMap {
 public:
  /// Where the scene's directions are recorded: over the whole grid, once, on the first
  /// call (many poses per scene: align()), or at each call only in the block of voxels
  /// around the model (one pose per scene: ModelAligner, whose scene spans far more than
  /// the model).
  enum class Coverage { whole_scene, around_model };

  /// The grid of the map of `scene` at `voxel_size`: its box and two voxels on each side.
  /// @throws std::invalid_argument (naming max_voxels) if it exceeds `limits`.
  static GridSpec spec_of(const PointCloud& scene, double voxel_size, const GridLimits& limits);

  /// Scores against `scene` on `spec` (spec_of) from now on. `scene` is kept by
  /// reference: it must outlive the calls of fitness().
  void set_scene(const PointCloud& scene, const GridSpec& spec, Coverage coverage);

  /// The fitness of model points and normals (already moved into the scene); buffers are
  /// kept between calls.
  double fitness(const Points& points, const Points& normals);

 private:
  // Records the directions of the scene's points in the voxels from `low` to `high`
  // (spread over the neighbours for whole_scene).
  void record_scene(const Eigen::Array3i& low, const Eigen::Array3i& high);
  // The model's occupied voxels (voxel_) and how many of them are supported.
  std::pair<std::size_t, std::size_t> count(const Points& normals);

  const PointCloud* scene_cloud_ = nullptr;
  GridSpec spec_;
  Coverage coverage_ = Coverage::around_model;
  bool recorded_ = false;  // whole_scene: the directions are recorded
  // The voxels the directions are recorded in: from scene_low_, scene_size_ of them.
  Eigen::Array3i scene_low_ = Eigen::Array3i::Zero(), scene_size_ = Eigen::Array3i::Zero();
  std::vector<Eigen::Vector3i> voxel_;  // per model point: its voxel in the spec
  std::vector<std::uint32_t> scene_;    // per recorded voxel: directions of the scene's normals
  // Scratch: (voxel key, nearest direction) of every model point, sorted by voxel.
  std::vector<std::pair<std::uint64_t, int>> seen_;
};

}  // namespace spectral_vs::detail
