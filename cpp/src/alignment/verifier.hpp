#pragma once
// Internal to the aligner: verify_pose for many poses of one model in one scene, the
// scene's nearest-point grid made once.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verification.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/range_image.hpp"

#include <optional>

namespace spectral_vs::detail {

class Verifier {
 public:
  /// `viewpoint`: the sensor origin of a single-view scene, or none for a scene seen from
  /// all sides. The scene must outlive the verifier.
  Verifier(const PointCloud& scene, double voxel_size,
           const std::optional<Eigen::Vector3d>& viewpoint);

  PoseVerification verify(const PointCloud& model, const Transform& T_scene_model) const;
  /// The scene's nearest-point grid for pairs within kVisibilityVoxels voxels.
  const IcpScene& grid() const { return grid_; }
  /// The same scene in cells of kInlierVoxels voxels, for pairs within that distance (the
  /// inliers, the ICP's pairs): a query looks at 27 times less space than in grid().
  const IcpScene& fine_grid() const { return fine_grid_; }

 private:
  double voxel_size_;
  std::optional<RangeImage> view_;
  IcpScene grid_;
  IcpScene fine_grid_;
};

/// Copies the verification's figures into the result (confidence, inliers, RMSE, d).
void set_verification(AlignResult& result, const PoseVerification& verification);

}  // namespace spectral_vs::detail
