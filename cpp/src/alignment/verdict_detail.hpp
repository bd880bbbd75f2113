#pragma once
// Internal to the verdict stage: the covariance on a scene's neighbour grid made once.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/verifier.hpp"

namespace spectral_vs::detail {

/// pose_covariance with the scene's grid given (pairs within `max_distance`, at most the
/// grid's), the scene's typical size (metres) for the prior and the inflation k.
PoseCovariance covariance_at(const PointCloud& model, const IcpScene& scene, const Transform& T,
                             double max_distance, double scene_extent, double inflation);

/// The confidence an answer of `status` reports: 0 for bad_scale and no_support, whose
/// scores the calibration does not cover (a voxel ten times too large scores 1 and is
/// wrong), `confidence` otherwise.
double gated_confidence(Verdict status, double confidence);

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

/// The verdict stage of align() and ModelAligner, last: `result` verified by `verifier`
/// (its score and alternatives' scores set) gets its calibrated confidence, covariance,
/// status and `reliable`; `converged` says whether the optimisation ended normally.
/// `model_extent`, `scene_extent`: typical sizes, metres.
void judge(AlignResult& result, const PointCloud& model, const Verifier& verifier,
           double model_extent, double scene_extent);

/// The verdict of a result whose verification was turned off: unverified, not reliable.
void leave_unjudged(AlignResult& result);

}  // namespace spectral_vs::detail
