#pragma once
// Internal to the verdict stage, the last of both modes: one verdict (judge_pose) of a
// verified pose, whichever mode verified it, and its pieces.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/verifier.hpp"

#include <utility>
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

/// What the verdict reads of a verified pose, in either mode.
struct VerdictCase {
  double score = 0.0;  ///< The verification's score, in [0, 1].
  RegistrationKind kind = RegistrationKind::model_to_scene;  ///< Its calibration map.
  Transform T = Transform::Identity();  ///< The pose: the verified cloud in the scene.
  double inlier_distance = 0.0;         ///< Metres: the pairs of the covariance's fit.
  double voxel_size = 0.0;              ///< Metres: the alignment's voxel.
  double model_extent = 0.0;            ///< Typical size of what was aligned, metres (its scale).
  double scene_extent = 0.0;            ///< Typical size of the scene, metres (the prior).
  bool supported = false;               ///< Some point of the answer is supported by the scene.
  bool timed_out = false;               ///< The time budget ran out before the search ended.
  bool rests = true;                    ///< Not floating (or resting not expected).
};

/// The verdict of a VerdictCase.
struct Judgement {
  PoseCovariance covariance = PoseCovariance::Identity();
  bool ambiguous = false;  ///< An alternative is not the same answer up to a symmetry.
  Conclusion conclusion;   ///< determined, status, reliable, the confidence to report.
};

/// The verdict given whether the alternatives leave the answer `ambiguous`: `verified` is
/// the cloud the verification checked at c.T (align: the model; align_views: the
/// reference's sample), `grid` the verification's neighbour grid of the scene.
Judgement judge_pose(const VerdictCase& c, const PointCloud& verified, const IcpScene& grid,
                     bool ambiguous);

/// The one verdict of both modes: the symmetric alternatives marked (`pose_of` gives an
/// alternative's pose), the calibrated confidence, the covariance of the point-to-plane
/// fit, the status and `reliable`.
template <class Alternative, class PoseOf>
Judgement judge_pose(const VerdictCase& c, const PointCloud& verified, const IcpScene& grid,
                     std::vector<Alternative>& alternatives, PoseOf pose_of) {
  const bool ambiguous =
      mark_symmetric(alternatives, verified, c.voxel_size, c.T, std::move(pose_of));
  return judge_pose(c, verified, grid, ambiguous);
}

/// A Judgement written into a result of either mode (AlignResult, ViewAlignResult).
template <class Result>
void write_judgement(const Judgement& judgement, Result& result) {
  result.covariance = judgement.covariance;
  result.ambiguous = judgement.ambiguous;
  result.determined = judgement.conclusion.determined;
  result.status = judgement.conclusion.status;
  result.reliable = judgement.conclusion.reliable;
  result.confidence = judgement.conclusion.confidence;
}

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
