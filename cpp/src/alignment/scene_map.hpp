#pragma once
// Internal to the aligner: the scene as the aligner searches it, and the voxel grids in
// which the model's translation is found (the translation sources of Algorithm 1).

#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "alignment/algorithm1.hpp"

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

namespace spectral_vs::detail {

/// ceil(length / voxel_size), the aligner's rule for the voxels of its grids.
/// @throws std::invalid_argument (naming max_voxels) over the limit, before any overflow.
int voxels_along(double length, double voxel_size, const GridLimits& limits);

/// The grid of the verification's voxel screen (FitnessMap) over `evidence`: its box and
/// two voxels on each side.
/// @throws std::invalid_argument over limits.max_voxels.
GridSpec scene_map_spec(const PointCloud& evidence, double voxel_size, const GridLimits& limits);

/// The bounded translation grid (AlignParams::local.max_translation): per axis the smaller of
/// the scene's box and the model's where it starts with max_translation of room past them
/// (once: the grid is circular), and the model's box grown by max_translation on both
/// sides (wrap-free for any shift up to max_translation, when the scene's box lies
/// within it on that axis); a voxel of margin, FFT-friendly sizes. With the scene cut to
/// `points_in_reach` the grid is at most the model's box and 2 max_translation: a view
/// far from the goal (a camera tilted toward the floor, 1.5 m deep) no longer grows it.
/// @throws std::invalid_argument over limits.max_voxels.
GridSpec bounded_translation_spec(const Eigen::AlignedBox3d& scene_box,
                                  const Eigen::AlignedBox3d& model_box, double max_translation,
                                  double voxel_size, const GridLimits& limits);

/// The scene as align() searches it: the scene points near a place, for windows (the
/// fitness of a pose is the verification's, verifier.hpp).
class SceneMap {
 public:
  /// `scene` is searched and windowed; it must outlive the map.
  explicit SceneMap(const PointCloud& scene) : scene_(&scene) {}

  const PointCloud& cloud() const { return *scene_; }

  /// Indices of the scene points inside the axis-aligned box.
  std::vector<Eigen::Index> points_in(const Eigen::AlignedBox3d& box) const;

 private:
  const PointCloud* scene_;
};

/// A cubic window of the scene around the model, on a grid only as large as the window:
/// the shift is bounded by the margin, which keeps the small grid free of wrap-around.
/// Re-placed (the scene re-voxelized and transformed) when the model leaves its centre.
/// On an axis where the scene is narrower than the cube (a model as large as the scene,
/// such as a room's depth frame, whose reach is a radius and the cube twice that on every
/// axis), the window holds the scene's extent and the margin instead, on a grid up to 10
/// times smaller: model points past it meet no scene point at any shift within the
/// margin (they would add to the model's spectrum, not to its match); overlap() still
/// counts them.
class TranslationWindow : public TranslationSource {
 public:
  /// A window of half-width `reach + margin` metres, placed around `centre`.
  TranslationWindow(const SceneMap& scene, double reach, double margin,
                    const Eigen::Vector3d& centre, double voxel_size, Occupancy occupancy,
                    const PhaseCorrelationParams& params, const GridLimits& limits);

  /// Centres the window on `centre`: re-voxelizes and transforms the scene inside it.
  void place(const Eigen::Vector3d& centre);
  /// Moves the window if `centre` is more than half the margin from its centre.
  void follow(const Eigen::Vector3d& centre);

  /// The shift of `moved` (model points in the scene) onto the scene, and J_t.
  TranslationEstimate estimate(const Points& moved) override;
  double translation_cost() const override;
  /// As Algorithm 1's source: follows the model's centre.
  void follow(const Eigen::Vector3d& centre, const Eigen::Vector3d&, bool) override {
    follow(centre);
  }
  std::optional<Eigen::Vector3i> window_dims() const override { return spec_.dims; }
  /// Normalised correlation of `moved`'s grid with the scene's at zero shift, in [0, 1]:
  /// smooth in sub-voxel motions, with trilinear voxels.
  double overlap(const Points& moved);

  const Eigen::Vector3d& centre() const { return centre_; }
  double half_width() const { return half_width_; }
  const Eigen::Vector3i& dims() const { return spec_.dims; }

 private:
  const SceneMap* scene_;
  Occupancy occupancy_;
  GridLimits limits_;
  double half_width_, margin_;
  Eigen::Vector3i max_shift_;
  Eigen::AlignedBox3d scene_box_;
  std::array<bool, 3> on_scene_{};  // axes on which the window holds the scene's extent
  GridSpec spec_;
  PhaseCorrelation phase_;
  Eigen::Vector3d centre_;
  VoxelGrid target_, moving_;
  double target_energy_ = 0.0;
};

/// The translation over the whole scene: a grid holding the scene grown by the model's
/// reach (the model may end anywhere in it) and the model's hull where it starts, with
/// room against wrap-around. At a coarse voxel it places the hypotheses of the global
/// search; at the alignment's voxel it is the paper's translation step.
class SceneTranslation : public TranslationSource {
 public:
  SceneTranslation(const SceneMap& scene, const Eigen::Vector3d& start, double reach,
                   double voxel_size, Occupancy occupancy, const PhaseCorrelationParams& params,
                   const GridLimits& limits);

  /// A bounded search: the grid holds the scene and the model's box where it starts,
  /// with `max_translation` metres of room past them (the grid is circular: room once
  /// serves shifts either way), and only shifts up to that far are sought. For two views
  /// of one scene (servoing) this grid is several times smaller than one grown by the
  /// model's reach.
  SceneTranslation(const SceneMap& scene, const Eigen::AlignedBox3d& model_box,
                   double max_translation, double voxel_size, Occupancy occupancy,
                   const PhaseCorrelationParams& params, const GridLimits& limits);

  TranslationEstimate estimate(const Points& moved) override;
  double translation_cost() const override;
  const GridSpec& spec() const { return spec_; }

 private:
  // The bounded search on the scene's points in reach of the model (points_in_reach).
  SceneTranslation(const Points& in_reach, const Eigen::AlignedBox3d& model_box,
                   double max_translation, double voxel_size, Occupancy occupancy,
                   const PhaseCorrelationParams& params, const GridLimits& limits);
  SceneTranslation(const SceneMap& scene, const GridSpec& spec,
                   const std::optional<Eigen::Vector3i>& max_shift, Occupancy occupancy,
                   const PhaseCorrelationParams& params, const GridLimits& limits);

  Occupancy occupancy_;
  GridLimits limits_;
  GridSpec spec_;
  PhaseCorrelation phase_;
  VoxelGrid target_, moving_;
  // Sum of the target's squared voxels, for J_t: summed at the first translation_cost()
  // (a caller that reads no J_t, as align_views, never pays for it).
  mutable std::optional<double> target_energy_;
  std::optional<Eigen::Vector3i> max_shift_;  // voxels; none: the whole grid
};

}  // namespace spectral_vs::detail
