#pragma once
// Internal to the verdict stage: the covariance on a scene's neighbour grid made once.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/verifier.hpp"

#include <vector>

namespace spectral_vs::detail {

/// pose_covariance with the scene's grid given (pairs within `max_distance`, at most the
/// grid's), the scene's typical size (metres) for the prior and the inflation k.
PoseCovariance covariance_at(const PointCloud& model, const IcpScene& scene, const Transform& T,
                             double max_distance, double scene_extent, double inflation);

/// The inverse of a rigid transform.
Transform rigid_inverse(const Transform& T);

/// The model's score against itself moved by S (model frame), seen from all sides.
class SelfFit {
 public:
  SelfFit(const PointCloud& model, double voxel_size);
  /// Whether the model maps onto itself by S: its score at least kSymmetricSelfFit.
  bool maps_onto_itself(const Transform& S) const;

 private:
  const PointCloud& model_;
  Verifier verifier_;
};

/// The alternatives that are the same answer up to the model's own symmetry (`symmetric`:
/// the model maps onto itself by the turn from the returned pose T to theirs), and
/// whether any other is left (the answer is then ambiguous). `pose_of` gives an
/// alternative's pose, in the frame of T.
template <class Alternative, class PoseOf>
bool mark_symmetric(std::vector<Alternative>& alternatives, const PointCloud& model,
                    double voxel_size, const Transform& T, PoseOf pose_of) {
  if (alternatives.empty()) return false;
  const SelfFit self_fit(model, voxel_size);
  const Transform T_inverse = rigid_inverse(T);
  bool ambiguous = false;
  for (Alternative& alternative : alternatives) {
    alternative.symmetric = self_fit.maps_onto_itself(T_inverse * pose_of(alternative));
    ambiguous = ambiguous || !alternative.symmetric;
  }
  return ambiguous;
}

/// The verdict read from its inputs and the pose's covariance: whether the pose is
/// determined at `centre` (the model's centroid, scene frame), the status, `reliable`,
/// and the confidence to report: 0 for bad_scale and no_support, whose scores the
/// calibration does not cover (a voxel ten times too large scores 1 and is wrong).
struct Conclusion {
  bool determined = false;
  Verdict status = Verdict::doubtful;
  bool reliable = false;
  double confidence = 0.0;
};
Conclusion conclude(VerdictInputs inputs, const PoseCovariance& covariance,
                    const Eigen::Vector3d& centre);

/// The verdict stage of align() and ModelAligner, last: `result` verified by `verifier`
/// (its score and alternatives' scores set) gets its calibrated confidence, covariance,
/// status and `reliable`; `converged` says whether the optimisation ended normally.
/// `model_extent`, `scene_extent`: typical sizes, metres. With `expect_resting` a pose
/// that does not rest (result.rests false) is floating.
void judge(AlignResult& result, const PointCloud& model, const Verifier& verifier,
           double model_extent, double scene_extent, bool expect_resting);

/// The verdict of a result whose verification was turned off: unverified, not reliable.
void leave_unjudged(AlignResult& result);

}  // namespace spectral_vs::detail
