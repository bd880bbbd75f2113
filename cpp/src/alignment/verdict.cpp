// The verdict stage: the score calibrated, read against one threshold and named; the
// pose's covariance from the point-to-plane fit.
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/verdict_detail.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <iterator>

namespace spectral_vs {

namespace {

// One knot of a calibration map: a verification score and the share of right answers
// at it.
struct Knot {
  double score;
  double probability;
};

// The calibration maps, fitted on the calibration set by benchmarks/verdict_benchmark.py
// (isotonic regression of right against score, reduced to knots): see docs/trust.md.
#include "alignment/calibration_maps.inc"

template <std::size_t N>
double interpolate(const Knot (&map)[N], double score) {
  const Knot* first = std::begin(map);
  const Knot* last = std::end(map);
  if (score <= first->score) return first->probability;
  const Knot* upper = std::upper_bound(first, last, score,
                                       [](double s, const Knot& knot) { return s < knot.score; });
  if (upper == last) return (last - 1)->probability;
  const Knot& lower = *(upper - 1);
  const double share = (score - lower.score) / (upper->score - lower.score);
  return lower.probability + share * (upper->probability - lower.probability);
}

// The calibration map of `kind` at `score` (in [0, 1]).
double map_probability(RegistrationKind kind, double score) {
  switch (kind) {
    case RegistrationKind::model_to_scene:
      return interpolate(kObjectMap, score);
    case RegistrationKind::view_to_view:
      return interpolate(kViewMap, score);
    case RegistrationKind::servo_step:
      return interpolate(kServoMap, score);
    case RegistrationKind::servo_carried:
      return interpolate(kServoCarriedMap, score);
  }
  return 0.0;
}

}  // namespace

double calibrated_confidence(double score, RegistrationKind kind) {
  if (!std::isfinite(score)) return 0.0;
  return std::clamp(map_probability(kind, std::clamp(score, 0.0, 1.0)), 0.0, 1.0);
}

double covariance_inflation(RegistrationKind kind) {
  switch (kind) {
    case RegistrationKind::model_to_scene:
      return kObjectInflation;
    case RegistrationKind::view_to_view:
      return kViewInflation;
    case RegistrationKind::servo_step:
    case RegistrationKind::servo_carried:
      break;
  }
  detail::fail(
      "kind: the servo's steps have no covariance (only align() and align_views() "
      "results have one)");
}

bool voxel_in_range(double voxel_size, double extent) {
  return extent > 0.0 && voxel_size <= kMaxVoxelShare * extent &&
         voxel_size >= kMinVoxelShare * extent;
}

bool pose_determined(const PoseCovariance& covariance, const Eigen::Vector3d& centre) {
  const Eigen::Matrix3d rotation = covariance.topLeftCorner<3, 3>();
  // The centroid moved by exp(delta): c + omega x c + v = c - hat(c) omega + v.
  Eigen::Matrix<double, 3, 6> J;
  J << -hat(centre), Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d at_centre = J * covariance * J.transpose();
  const double worst_turn = std::sqrt(std::max(
      0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(rotation).eigenvalues().maxCoeff()));
  const double worst_shift = std::sqrt(std::max(
      0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(at_centre).eigenvalues().maxCoeff()));
  return 2.0 * worst_turn <= kRightDegrees * M_PI / 180.0 && 2.0 * worst_shift <= kRightMetres;
}

Verdict verdict_of(const VerdictInputs& in) {
  if (in.timed_out) return Verdict::max_seconds;
  if (!in.scale_ok) return Verdict::bad_scale;
  if (!in.supported) return Verdict::no_support;
  if (in.confidence < kReliableConfidence) return Verdict::doubtful;
  if (!in.rests) return Verdict::floating;
  if (!in.determined) return Verdict::undetermined;
  if (in.ambiguous) return Verdict::ambiguous;
  return Verdict::reliable;
}

const char* verdict_name(Verdict verdict) {
  switch (verdict) {
    case Verdict::reliable:
      return "reliable";
    case Verdict::ambiguous:
      return "ambiguous";
    case Verdict::doubtful:
      return "doubtful";
    case Verdict::undetermined:
      return "undetermined";
    case Verdict::floating:
      return "floating";
    case Verdict::no_support:
      return "no_support";
    case Verdict::max_seconds:
      return "max_seconds";
    case Verdict::bad_scale:
      return "bad_scale";
    case Verdict::unverified:
      return "unverified";
  }
  return "doubtful";
}

namespace detail {

Transform rigid_inverse(const Transform& T) {
  Transform inverse = Transform::Identity();
  inverse.topLeftCorner<3, 3>() = T.topLeftCorner<3, 3>().transpose();
  inverse.topRightCorner<3, 1>() = -T.topLeftCorner<3, 3>().transpose() * T.topRightCorner<3, 1>();
  return inverse;
}

SelfFit::SelfFit(const PointCloud& model, double voxel_size)
    : model_(model), verifier_(model, voxel_size, std::nullopt) {}

bool SelfFit::maps_onto_itself(const Transform& S) const {
  return verifier_.verify(model_, S).confidence >= kSymmetricSelfFit;
}

bool ended_normally(AlignStopReason reason) {
  return reason == AlignStopReason::converged || reason == AlignStopReason::kept_start ||
         reason == AlignStopReason::reselected;
}

Conclusion conclude(VerdictInputs inputs, const PoseCovariance& covariance,
                    const Eigen::Vector3d& centre) {
  Conclusion out;
  out.determined = inputs.determined = pose_determined(covariance, centre);
  out.status = verdict_of(inputs);
  out.reliable = out.status == Verdict::reliable;
  const bool gated = out.status == Verdict::bad_scale || out.status == Verdict::no_support;
  out.confidence = gated ? 0.0 : inputs.confidence;
  return out;
}

Judgement judge_pose(const VerdictCase& c, const PointCloud& verified, const IcpScene& grid,
                     bool ambiguous) {
  Judgement judgement;
  judgement.ambiguous = ambiguous;
  judgement.covariance = covariance_at(verified, grid, c.T, c.inlier_distance, c.scene_extent,
                                       covariance_inflation(c.kind));
  VerdictInputs inputs;
  inputs.confidence = calibrated_confidence(c.score, c.kind);
  inputs.ambiguous = ambiguous;
  inputs.supported = c.supported;
  inputs.timed_out = c.timed_out;
  inputs.scale_ok = voxel_in_range(c.voxel_size, c.model_extent);
  inputs.rests = c.rests;
  judgement.conclusion =
      conclude(inputs, judgement.covariance,
               c.T.topLeftCorner<3, 3>() * verified.centroid() + c.T.topRightCorner<3, 1>());
  return judgement;
}

void judge(AlignResult& result, const PointCloud& model, const Verifier& verifier,
           double model_extent, double scene_extent, bool expect_resting) {
  result.converged = ended_normally(result.stop_reason);
  result.score = result.confidence;
  for (AlignAlternative& alternative : result.alternatives) {
    alternative.score = alternative.confidence;
    alternative.confidence =
        calibrated_confidence(alternative.score, RegistrationKind::model_to_scene);
  }
  const Eigen::Index points = model.points().rows();
  result.inlier_fraction = points ? double(result.inliers) / double(points) : 0.0;
  VerdictCase c;
  c.score = result.score;
  c.kind = RegistrationKind::model_to_scene;
  c.T = result.T_scene_model;
  c.inlier_distance = result.inlier_distance;
  c.voxel_size = result.voxel_size;
  c.model_extent = model_extent;
  c.scene_extent = scene_extent;
  c.supported = result.inliers > 0;
  c.timed_out = result.stop_reason == AlignStopReason::max_seconds;
  c.rests = result.rests || !expect_resting;
  write_judgement(judge_pose(c, model, verifier.fine_grid(), result.alternatives,
                             [](const AlignAlternative& a) { return a.T_scene_model; }),
                  result);
}

void leave_unjudged(AlignResult& result) {
  result.converged = ended_normally(result.stop_reason);
  result.status = Verdict::unverified;
  result.reliable = false;
}

}  // namespace detail

}  // namespace spectral_vs
