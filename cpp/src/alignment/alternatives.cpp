#include "alignment/alternatives.hpp"

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/icp_refinement.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

// The model's near-symmetries: the best maxima of its EGI correlated with itself (the
// identity first, dropped). 24 holds the rotation group of a cube.
constexpr int kSelfCandidates = 24;
// Turns tried about a flat EGI axis (a mug's, a cylinder's): every 10 degrees, so that
// any turn is within 5 degrees of one of them.
constexpr double kAxisStep = 10.0 * M_PI / 180.0;
// Hypotheses of the global search tried as they are.
constexpr std::size_t kHypotheses = 8;
// Candidates refined by ICP, per alternative asked for: the best by inlier count first.
constexpr int kRefinedPerAlternative = 2;
// A candidate is dropped before the ICP below this share of the returned pose's inliers.
constexpr double kMinInlierShare = 0.5;

struct Candidate {
  Transform T = Transform::Identity();
  PoseVerification verification;
};

// T_scene_model composed with the turn R of the model about its centroid c.
Transform turned(const Transform& T, const Eigen::Matrix3d& R, const Eigen::Vector3d& c) {
  Transform A = Transform::Identity();
  A.topLeftCorner<3, 3>() = R;
  A.topRightCorner<3, 1>() = c - R * c;
  return T * A;
}

bool apart(const Transform& a, const Transform& b, const Eigen::Vector3d& centroid) {
  const double degrees =
      rotation_distance(a.topLeftCorner<3, 3>(), b.topLeftCorner<3, 3>()) * 180.0 / M_PI;
  const Eigen::Vector4d c(centroid.x(), centroid.y(), centroid.z(), 1.0);
  const double metres = ((a - b) * c).head<3>().norm();
  return degrees > kApartDegrees || metres > kApartMetres;
}

}  // namespace

void find_alternatives(const PointCloud& model, const Verifier& verifier,
                       const AlternativeSources& sources, const AlignParams& params,
                       AlignResult& result) {
  result.alternatives.clear();
  result.ambiguous = false;
  if (params.max_alternatives == 0) return;
  const Eigen::Vector3d c = model.centroid();
  const Transform& T = result.T_scene_model;

  std::vector<Transform> poses;
  try {
    So3Correlation self(sources.model_coefficients, sources.model_coefficients, sources.bandwidth,
                        true);
    So3SearchParams search;
    search.candidates = kSelfCandidates;
    search.threads = params.threads;
    RotationRefineParams refine;
    for (const RotationCandidate& candidate :
         so3_search(sources.model_coefficients, sources.model_coefficients, sources.bandwidth,
                    search)) {
      const Eigen::Matrix3d R = refine_rotation(self, candidate.R, refine).R;
      if (rotation_distance(R, Eigen::Matrix3d::Identity()) * 180.0 / M_PI > kApartDegrees)
        poses.push_back(turned(T, R, c));
    }
  } catch (const std::invalid_argument&) {
    // A uniform EGI (a sphere's): no rotation stands out.
  }
  if (sources.flat_axis) {
    const int turns = static_cast<int>(std::lround(2.0 * M_PI / kAxisStep));
    for (int k = 1; k < turns; ++k)
      poses.push_back(turned(T, exp_so3(double(k) * kAxisStep * *sources.flat_axis), c));
  }
  for (std::size_t h = 0; h < std::min(kHypotheses, sources.hypotheses.size()); ++h)
    poses.push_back(sources.hypotheses[h]);

  // The likeliest by inliers first (cheap), then refined as the returned pose was.
  std::vector<Candidate> candidates;
  for (const Transform& pose : poses) {
    if (!apart(pose, T, c)) continue;
    Candidate candidate{pose, verifier.verify(model, pose)};
    if (candidate.verification.inliers >= kMinInlierShare * result.inliers)
      candidates.push_back(candidate);
  }
  std::stable_sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
    return a.verification.inliers > b.verification.inliers;
  });
  candidates.resize(std::min<std::size_t>(
      candidates.size(), std::size_t(kRefinedPerAlternative * params.max_alternatives)));
  IcpSettings icp;
  icp.viewpoint = params.scene_viewpoint;
  for (Candidate& candidate : candidates) {
    for (const double distance : {1.0, 0.4}) {
      icp.max_distance = distance * params.voxel_size;
      const IcpOutcome outcome = refine_point_to_plane(model, verifier.grid(), candidate.T, icp);
      if (outcome.iterations > 0) candidate.T = outcome.T_scene_model;
    }
    candidate.verification = verifier.verify(model, candidate.T);
  }
  std::stable_sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
    return a.verification.confidence > b.verification.confidence;
  });
  for (const Candidate& candidate : candidates) {
    if (int(result.alternatives.size()) == params.max_alternatives) break;
    if (candidate.verification.confidence < result.confidence - kAlternativeMargin) break;
    if (!apart(candidate.T, T, c)) continue;
    const bool distinct = std::all_of(
        result.alternatives.begin(), result.alternatives.end(),
        [&](const AlignAlternative& kept) { return apart(candidate.T, kept.T_scene_model, c); });
    if (!distinct) continue;
    AlignAlternative alternative;
    alternative.T_scene_model = candidate.T;
    alternative.confidence = candidate.verification.confidence;
    alternative.inliers = candidate.verification.inliers;
    alternative.inlier_rmse = candidate.verification.inlier_rmse;
    alternative.rotation_apart = rotation_distance(candidate.T.topLeftCorner<3, 3>(),
                                                   T.topLeftCorner<3, 3>());
    const Eigen::Vector4d h(c.x(), c.y(), c.z(), 1.0);
    alternative.translation_apart = ((candidate.T - T) * h).head<3>().norm();
    result.alternatives.push_back(alternative);
  }
  result.ambiguous = !result.alternatives.empty();
}

}  // namespace spectral_vs::detail
