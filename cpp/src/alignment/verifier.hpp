#pragma once
// Stage: verification. The one place where a pose is scored against a scene: align(),
// ModelAligner and align_views() rank their hypotheses and judge their answers through
// it (docs/trust.md, "The score").
//
// It answers at two costs, from one scene and one sensor:
//   fitness()  the screen that ranks hypotheses, called hundreds of times a search: the
//              share of the model's voxels (a scene seen from all sides, FitnessMap) or
//              of its pixels (a single view, RangeImage::check) on a scanned surface
//              turned the same way;
//   verify()   the check behind the verdict, point by point (PoseVerification): the
//              share of what the sensor would see of the model that lies on the tangent
//              plane of a scene point turned the same way, less what it saw through.
// Ranking by verify()'s score instead was measured on the calibration set's 181
// model-to-scan problems: 134 right against 136, one more wrong answer taken as
// reliable, 25% more CPU time (docs/trust.md, "One verification stage").

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verification.hpp>

#include "alignment/fitness_map.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/range_image.hpp"

#include <optional>

namespace spectral_vs::detail {

class Verifier {
 public:
  /// `viewpoint`: the sensor origin of a single-view scene, or none for a scene seen from
  /// all sides. `screen`: the grid of the voxel screen (FitnessMap::spec_of, checked
  /// against the caller's limits) and where it records the scene; needed by fitness() of
  /// a scene seen from all sides only (a verifier that only verifies takes none).
  /// The scene must outlive the verifier. Each part is built at its first use; a verifier
  /// is used by one thread at a time.
  Verifier(const PointCloud& scene, double voxel_size,
           const std::optional<Eigen::Vector3d>& viewpoint,
           const std::optional<GridSpec>& screen = std::nullopt,
           FitnessMap::Coverage coverage = FitnessMap::Coverage::whole_scene);

  /// The screen: the fitness of model points and normals already moved into the scene,
  /// with depths within `tolerance` metres for a single view, in [0, 1].
  /// @pre a viewpoint or a screen grid was given.
  double fitness(const Points& points, const Points& normals, double tolerance) const;
  /// The single view's pixel check behind fitness() (half-voxel pixels).
  /// @pre a viewpoint was given.
  ViewCheck check(const Points& points, const Points& normals, double tolerance,
                  RangeImage::Distance distance = RangeImage::Distance::depth) const;

  /// The check behind the verdict (PoseVerification) of the model at T_scene_model.
  PoseVerification verify(const PointCloud& model, const Transform& T_scene_model) const;

  double voxel_size() const { return voxel_size_; }
  /// The scene in cells of kInlierVoxels voxels, for pairs within that distance (the
  /// inliers, the ICP's pairs): a query looks at 27 times less space than in grid().
  const IcpScene& fine_grid() const;

 private:
  // The scene's nearest-point grid for pairs within kVisibilityVoxels voxels.
  const IcpScene& grid() const;
  const RangeImage& screen_image() const;
  const RangeImage& verify_image() const;

  const PointCloud* scene_;
  double voxel_size_;
  std::optional<Eigen::Vector3d> viewpoint_;
  std::optional<GridSpec> screen_spec_;
  FitnessMap::Coverage coverage_;
  // Built at their first use (the servo's tracking never verifies; verify_pose never ranks).
  mutable std::optional<FitnessMap> map_;
  mutable std::optional<RangeImage> screen_image_, verify_image_;
  mutable std::optional<IcpScene> grid_, fine_grid_;
};

/// Copies the verification's figures into the result (confidence, inliers, RMSE, d).
void set_verification(AlignResult& result, const PoseVerification& verification);

}  // namespace spectral_vs::detail
