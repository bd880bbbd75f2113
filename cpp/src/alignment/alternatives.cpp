#include "alignment/alternatives.hpp"

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/normal_directions.hpp"
#include "alignment/point_sets.hpp"

#include <Eigen/Dense>
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
// Hypotheses of the global search tried as they are. 16: in clutter the right pose of a
// flat box or a blob can rank past the 8th by fitness, and the reselection returns it
// once it is an alternative. Against 8: tuning clutter 262 -> 265 of 280 (12 and 24
// alike), thin objects 123 -> 124 of 126 (12: 123; 24: 123, one gained, one lost);
// single views, full models, the bunny scan and the milk scene unchanged; CPU time
// within 1% (docs/experiments.md, "Thin objects").
constexpr std::size_t kHypotheses = 16;
// Candidates refined by ICP, per alternative asked for: the best by inlier count first.
constexpr int kRefinedPerAlternative = 2;
// A candidate is dropped before the ICP below this share of the returned pose's inliers.
constexpr double kMinInlierShare = 0.5;

struct Candidate {
  Transform T = Transform::Identity();
  PoseVerification verification;
  bool turn = false;   // a turn about the flat axis: its rotation is kept (see below)
  double angle = 0.0;  // of the turn, radians
};

// A turn about the flat axis is an alternative only where the confidence is flat along
// the turn: the pose turned half as far may score at most this much more. A body of
// revolution scores alike at every turn; an object that is not one (a duck at a coarse
// voxel) falls off from the returned pose, and a turn that only keeps within the margin
// of it is the tail of that one peak, not a second pose.
constexpr double kTurnFlatness = 0.01;

// Point-to-plane steps of the translation alone. A turn about a flat EGI axis is refined
// so: a full ICP slides along the surface's free turn (a mug whose handle is hidden) and
// would leave the turns tried every kAxisStep unevenly spread; the translation takes
// up the turn of the model about its centroid rather than its axis.
constexpr int kTranslationSteps = 10;

Transform refine_translation(const PointCloud& model, const IcpScene& scene, Transform T,
                             double max_distance, const std::optional<Eigen::Vector3d>& viewpoint) {
  const Eigen::Index stride = std::max<Eigen::Index>(1, model.points().rows() / 1500);
  for (int step = 0; step < kTranslationSteps; ++step) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    int pairs = 0;
    for (Eigen::Index i = 0; i < model.points().rows(); i += stride) {
      const Eigen::Vector3d p =
          T.topLeftCorner<3, 3>() * model.points().row(i).transpose() + T.topRightCorner<3, 1>();
      const Eigen::Vector3d n = T.topLeftCorner<3, 3>() * model.normals().row(i).transpose();
      if (viewpoint && n.dot(*viewpoint - p) <= 0.0) continue;
      const Eigen::Index j = scene.nearest(p, n, max_distance, kAgreeingCosine);
      if (j < 0) continue;
      const Eigen::Vector3d q = scene.cloud().points().row(j).transpose();
      const Eigen::Vector3d m = scene.cloud().normals().row(j).transpose();
      A += m * m.transpose();
      b += m * m.dot(q - p);
      ++pairs;
    }
    if (pairs < 6) break;
    const Eigen::Vector3d shift = A.completeOrthogonalDecomposition().solve(b);
    T.topRightCorner<3, 1>() += shift;
    if (shift.norm() < 2e-5) break;
  }
  return T;
}

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

// Whether the confidence is flat along the turn from the returned pose T to the turned
// candidate: the pose turned half as far (the short way), refined in translation as the
// candidate was, scores at most kTurnFlatness more than the candidate.
bool flat_along_turn(const PointCloud& model, const Verifier& verifier, const Candidate& candidate,
                     const Transform& T, const Eigen::Vector3d& c, const Eigen::Vector3d& axis,
                     double voxel_size, const std::optional<Eigen::Vector3d>& viewpoint) {
  const double angle = candidate.angle > M_PI ? candidate.angle - 2.0 * M_PI : candidate.angle;
  const Transform half =
      refine_translation(model, verifier.fine_grid(), turned(T, exp_so3(0.5 * angle * axis), c),
                         voxel_size, viewpoint);
  return verifier.verify(model, half).confidence <=
         candidate.verification.confidence + kTurnFlatness;
}

// The screening of the candidates before their refinement, which is most of this stage's
// time (nearest-point queries of up to 60 ICP steps on 1,500 model points each): each is
// first refined alike on the sparse model (every kSparseStride-th point, a fraction of the
// cost) and dropped when it falls onto the returned pose or its sparse confidence stays
// more than kScreenMargin below the returned pose's. An alternative scores within
// kAlternativeMargin of the returned pose on the whole model; the sparse confidence is
// within about 0.01 of the whole model's (a few hundred points; measured on a full mug's
// turns), so twice the margin keeps every such pose; a wrong candidate of an asymmetric
// object scores far below. The sparse ICP takes at most kScreenIterations steps per
// distance: a pose that can be an alternative starts near one (a symmetry of the model).
constexpr double kScreenMargin = 2.0 * kAlternativeMargin;
constexpr int kScreenIterations = 10;

// The screened pose of `candidate` if it passes, else none. The whole model's refinement of
// one that does starts from its pose as it was, not from the sparse one's refinement.
std::optional<Transform> passes_screening(const PointCloud& sparse, const Verifier& verifier,
                                          const Candidate& candidate, const Transform& T,
                                          const Eigen::Vector3d& c, double sparse_confidence,
                                          double voxel_size,
                                          const std::optional<Eigen::Vector3d>& viewpoint) {
  const Transform screened =
      candidate.turn
          ? refine_translation(sparse, verifier.fine_grid(), candidate.T, voxel_size, viewpoint)
          : refine_by_icp(sparse, verifier, candidate.T, voxel_size, viewpoint, kScreenIterations);
  if (!apart(screened, T, c)) return std::nullopt;
  if (verifier.verify(sparse, screened).confidence < sparse_confidence - kScreenMargin)
    return std::nullopt;
  return screened;
}

// The poses tried as alternatives to T (a pose of the model, whose centroid is c): T
// turned by the model's near-symmetries, by steps about its flat EGI axis, and the
// global search's first hypotheses as they are.
std::vector<Candidate> proposed_poses(const Transform& T, const Eigen::Vector3d& c,
                                      const AlternativeSources& sources) {
  std::vector<Candidate> poses;
  for (const Eigen::Matrix3d& R : sources.symmetries)
    poses.push_back({turned(T, R, c), {}, false, 0.0});
  if (sources.flat_axis) {
    const int count = static_cast<int>(std::lround(2.0 * M_PI / kAxisStep));
    for (int k = 1; k < count; ++k) {
      const double angle = double(k) * kAxisStep;
      poses.push_back({turned(T, exp_so3(angle * *sources.flat_axis), c), {}, true, angle});
    }
  }
  for (std::size_t h = 0; h < std::min(kHypotheses, sources.hypotheses.size()); ++h) {
    poses.push_back({sources.hypotheses[h], {}, false, 0.0});
  }
  return poses;
}

// A kept candidate as the result reports it, with how far it is from T.
AlignAlternative alternative_of(const Candidate& candidate, const Transform& T,
                                const Eigen::Vector3d& c) {
  AlignAlternative alternative;
  alternative.T_scene_model = candidate.T;
  alternative.confidence = candidate.verification.confidence;
  alternative.inliers = candidate.verification.inliers;
  alternative.inlier_rmse = candidate.verification.inlier_rmse;
  alternative.rotation_apart =
      rotation_distance(candidate.T.topLeftCorner<3, 3>(), T.topLeftCorner<3, 3>());
  const Eigen::Vector4d h(c.x(), c.y(), c.z(), 1.0);
  alternative.translation_apart = ((candidate.T - T) * h).head<3>().norm();
  return alternative;
}

}  // namespace

Transform refine_by_icp(const PointCloud& model, const Verifier& verifier, const Transform& T,
                        double voxel_size, const std::optional<Eigen::Vector3d>& viewpoint,
                        int max_iterations) {
  IcpSettings icp;
  icp.viewpoint = viewpoint;
  icp.max_iterations = max_iterations;
  return refine_in_two_stages(model, verifier.fine_grid(), T, voxel_size, icp).T_scene_model;
}

std::vector<Eigen::Matrix3d> model_symmetries(const ShCoefficients& model_coefficients,
                                              int bandwidth, int threads) {
  std::vector<Eigen::Matrix3d> symmetries;
  try {
    So3Correlation self(model_coefficients, model_coefficients, bandwidth, true);
    So3SearchParams search;
    search.candidates = kSelfCandidates;
    search.threads = threads;
    RotationRefineParams refine;
    for (const RotationCandidate& candidate :
         so3_search(model_coefficients, model_coefficients, bandwidth, search)) {
      const Eigen::Matrix3d R = refine_rotation(self, candidate.R, refine).R;
      if (rotation_distance(R, Eigen::Matrix3d::Identity()) * 180.0 / M_PI > kApartDegrees)
        symmetries.push_back(R);
    }
  } catch (const std::invalid_argument&) {
    // A uniform EGI (a sphere's): no rotation stands out.
  }
  return symmetries;
}

std::vector<AlignAlternative> find_alternatives(const PointCloud& model, const Verifier& verifier,
                                                const AlternativeSources& sources,
                                                const VerificationParams& verification,
                                                double voxel_size,
                                                const std::optional<Eigen::Vector3d>& viewpoint,
                                                const Transform& T, double confidence) {
  std::vector<AlignAlternative> alternatives;
  if (verification.max_alternatives == 0) return alternatives;
  const Eigen::Vector3d c = model.centroid();

  const std::vector<Candidate> proposed = proposed_poses(T, c, sources);

  // The likeliest by inliers first, counted on every kSparseStride-th model point (the
  // nearest-point queries of every candidate are most of this stage's time), then refined
  // as the returned pose was.
  const PointCloud sparse = every_nth(model, kSparseStride);
  const PoseVerification sparse_returned = verifier.verify(sparse, T);
  const int sparse_inliers = sparse_returned.inliers;
  std::vector<Candidate> candidates;
  for (Candidate candidate : proposed) {
    if (!apart(candidate.T, T, c)) continue;
    candidate.verification = verifier.verify(sparse, candidate.T);
    if (candidate.verification.inliers >= kMinInlierShare * sparse_inliers)
      candidates.push_back(candidate);
  }
  std::stable_sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
    return a.verification.inliers > b.verification.inliers;
  });
  candidates.resize(std::min<std::size_t>(
      candidates.size(), std::size_t(kRefinedPerAlternative * verification.max_alternatives)));
  const double sparse_confidence = sparse_returned.confidence;
  // A candidate whose screened pose falls onto an earlier one's (the same symmetry proposed
  // twice, or a hypothesis that is one) is not refined on the whole model: it is that pose
  // again. On 210 tuning cases (full, single views, clutter) the same successes, ambiguous
  // poses and truths among the alternatives, at 14% / 10% / 3% less CPU time (a box's
  // candidates: 10 refined before, 3 now, the 3 it reports).
  std::vector<Candidate> screened;
  std::vector<Transform> screened_at;
  for (const Candidate& candidate : candidates) {
    const std::optional<Transform> at = passes_screening(sparse, verifier, candidate, T, c,
                                                         sparse_confidence, voxel_size, viewpoint);
    const auto same = [&](const Transform& kept) { return !apart(*at, kept, c); };
    if (!at || std::any_of(screened_at.begin(), screened_at.end(), same)) continue;
    screened.push_back(candidate);
    screened_at.push_back(*at);
  }
  candidates = std::move(screened);
  for (Candidate& candidate : candidates) {
    if (candidate.turn) {
      candidate.T =
          refine_translation(model, verifier.fine_grid(), candidate.T, voxel_size, viewpoint);
      candidate.verification = verifier.verify(model, candidate.T);
      continue;
    }
    candidate.T = refine_by_icp(model, verifier, candidate.T, voxel_size, viewpoint);
    candidate.verification = verifier.verify(model, candidate.T);
  }
  std::stable_sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
    return a.verification.confidence > b.verification.confidence;
  });
  for (const Candidate& candidate : candidates) {
    if (int(alternatives.size()) == verification.max_alternatives) break;
    if (candidate.verification.confidence < confidence - kAlternativeMargin) break;
    if (!apart(candidate.T, T, c)) continue;
    if (candidate.turn && !flat_along_turn(model, verifier, candidate, T, c, *sources.flat_axis,
                                           voxel_size, viewpoint))
      continue;
    const bool distinct = std::all_of(
        alternatives.begin(), alternatives.end(),
        [&](const AlignAlternative& kept) { return apart(candidate.T, kept.T_scene_model, c); });
    if (!distinct) continue;
    alternatives.push_back(alternative_of(candidate, T, c));
  }
  return alternatives;
}

}  // namespace spectral_vs::detail
