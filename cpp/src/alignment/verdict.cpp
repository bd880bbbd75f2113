// The verdict stage: the score calibrated, read against one threshold and named; the
// pose's covariance from the point-to-plane fit.
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/scale.hpp"
#include "alignment/verdict_detail.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <map>
#include <vector>

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
#include "alignment/normal_directions.hpp"

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

namespace {

// Residuals are grouped in cubic cells of this many pair distances (voxels): the
// normals are fitted over 2 voxels around each point and the grids sample the surface at
// a voxel, so neighbours within about 4 voxels share their errors, and such a cell is
// one observation rather than its many points.
constexpr double kClusterVoxels = 4.0;

struct PointToPlaneFit {
  PoseCovariance information = PoseCovariance::Zero();  // sum J J^T
  PoseCovariance meat = PoseCovariance::Zero();         // sum over cells of g g^T, g = sum J r
  double squared_sum = 0.0;
  int pairs = 0;
  int cells = 0;
};

// The cell of a pair: its scene point q's position across its normal n (q less its
// component along n), in cells of `cell` metres, and n's dominant signed axis. Not q
// itself: a cell's wall along a surface would split its points by the sign of their
// residuals, which then no longer average out within a cell.
std::array<std::int64_t, 4> cell_of(const Eigen::Vector3d& q, const Eigen::Vector3d& n,
                                    double cell) {
  const Eigen::Vector3d across = q - n.dot(q) * n;
  Eigen::Index axis = 0;
  n.cwiseAbs().maxCoeff(&axis);
  return {std::int64_t(std::floor(across.x() / cell)), std::int64_t(std::floor(across.y() / cell)),
          std::int64_t(std::floor(across.z() / cell)),
          std::int64_t(2 * axis + (n(axis) < 0.0 ? 1 : 0))};
}

PointToPlaneFit point_to_plane_fit(const PointCloud& model, const IcpScene& scene,
                                   const Transform& T, double max_distance) {
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  const Points& scene_points = scene.cloud().points();
  const Points& scene_normals = scene.cloud().normals();
  const double cell = kClusterVoxels * max_distance;
  std::map<std::array<std::int64_t, 4>, Eigen::Matrix<double, 6, 1>> gradients;
  PointToPlaneFit fit;
  for (Eigen::Index i = 0; i < model.points().rows(); ++i) {
    const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
    const Eigen::Vector3d n = R * model.normals().row(i).transpose();
    const Eigen::Index j = scene.nearest(p, n, max_distance, kAgreeingCosine);
    if (j < 0) continue;
    const Eigen::Vector3d normal = scene_normals.row(j).transpose();
    const double residual = normal.dot(p - scene_points.row(j).transpose());
    Eigen::Matrix<double, 6, 1> J;
    J << p.cross(normal), normal;
    fit.information.selfadjointView<Eigen::Lower>().rankUpdate(J);
    const std::array<std::int64_t, 4> key = cell_of(scene_points.row(j).transpose(), normal, cell);
    auto [entry, added] = gradients.try_emplace(key, Eigen::Matrix<double, 6, 1>::Zero());
    entry->second += J * residual;
    fit.squared_sum += residual * residual;
    ++fit.pairs;
  }
  fit.information = fit.information.selfadjointView<Eigen::Lower>();
  for (const auto& [key, g] : gradients) fit.meat.noalias() += g * g.transpose();
  fit.cells = int(gradients.size());
  return fit;
}

}  // namespace

PoseCovariance covariance_at(const PointCloud& model, const IcpScene& scene, const Transform& T,
                             double max_distance, double scene_extent, double inflation) {
  const PointToPlaneFit fit = point_to_plane_fit(model, scene, T, max_distance);
  // The prior: one standard deviation of pi radians and of the scene's size.
  const double size = std::max(scene_extent, max_distance);
  PoseCovariance prior = PoseCovariance::Zero();
  prior.diagonal() << Eigen::Vector3d::Constant(1.0 / (M_PI * M_PI)),
      Eigen::Vector3d::Constant(1.0 / (size * size));
  if (fit.pairs <= 6) return prior.inverse();
  // The residuals' variance, floored at a hundredth of the pairs' distance: an exact copy
  // (a zero residual) is not infinitely precise.
  const double floor_variance = std::pow(0.01 * max_distance, 2);
  // The cluster-robust (sandwich) covariance H^-1 M H^-1 on the directions the surfaces
  // constrain, M the cells' gradients' scatter (with the small-sample factor c / (c - 6)
  // when there are more cells than unknowns) plus the floor: its information there is
  // H (M + floor H)^-1 H, and the prior's alone elsewhere.
  const Eigen::SelfAdjointEigenSolver<PoseCovariance> directions(fit.information);
  const double largest = directions.eigenvalues().maxCoeff();
  const double small_sample = fit.cells > 6 ? double(fit.cells) / double(fit.cells - 6) : 1.0;
  PoseCovariance information = prior;
  std::vector<int> constrained;
  for (int i = 0; i < 6; ++i)
    if (directions.eigenvalues()(i) > 1e-9 * largest) constrained.push_back(i);
  const int rank = int(constrained.size());
  if (rank > 0) {
    Eigen::MatrixXd V(6, rank);
    Eigen::VectorXd lambda(rank);
    for (int c = 0; c < rank; ++c) {
      V.col(c) = directions.eigenvectors().col(constrained[std::size_t(c)]);
      lambda(c) = directions.eigenvalues()(constrained[std::size_t(c)]);
    }
    const Eigen::MatrixXd meat = small_sample * V.transpose() * fit.meat * V +
                                 Eigen::MatrixXd(floor_variance * lambda.asDiagonal());
    const Eigen::MatrixXd inner =
        lambda.asDiagonal() * meat.llt().solve(Eigen::MatrixXd(lambda.asDiagonal()));
    information += V * (0.5 * (inner + inner.transpose())) * V.transpose() / inflation;
  }
  const Eigen::SelfAdjointEigenSolver<PoseCovariance> solver(information);
  const Eigen::Matrix<double, 6, 1> inverse = solver.eigenvalues().cwiseInverse();
  return solver.eigenvectors() * inverse.asDiagonal() * solver.eigenvectors().transpose();
}

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

void judge(AlignResult& result, const PointCloud& model, const Verifier& verifier,
           double model_extent, double scene_extent, bool expect_resting) {
  result.converged = ended_normally(result.stop_reason);
  result.score = result.confidence;
  result.confidence = calibrated_confidence(result.score, RegistrationKind::model_to_scene);
  for (AlignAlternative& alternative : result.alternatives) {
    alternative.score = alternative.confidence;
    alternative.confidence =
        calibrated_confidence(alternative.score, RegistrationKind::model_to_scene);
  }
  result.ambiguous =
      mark_symmetric(result.alternatives, model, result.voxel_size, result.T_scene_model,
                     [](const AlignAlternative& a) { return a.T_scene_model; });
  const Eigen::Index points = model.points().rows();
  result.inlier_fraction = points ? double(result.inliers) / double(points) : 0.0;
  result.covariance =
      covariance_at(model, verifier.fine_grid(), result.T_scene_model, result.inlier_distance,
                    scene_extent, covariance_inflation(RegistrationKind::model_to_scene));
  VerdictInputs inputs;
  inputs.confidence = result.confidence;
  inputs.ambiguous = result.ambiguous;
  inputs.supported = result.inliers > 0;
  inputs.timed_out = result.stop_reason == AlignStopReason::max_seconds;
  inputs.scale_ok = voxel_in_range(result.voxel_size, model_extent);
  inputs.rests = result.rests || !expect_resting;
  const Conclusion c = conclude(inputs, result.covariance,
                                result.T_scene_model.topLeftCorner<3, 3>() * model.centroid() +
                                    result.T_scene_model.topRightCorner<3, 1>());
  result.determined = c.determined;
  result.status = c.status;
  result.reliable = c.reliable;
  result.confidence = c.confidence;
}

void leave_unjudged(AlignResult& result) {
  result.converged = ended_normally(result.stop_reason);
  result.status = Verdict::unverified;
  result.reliable = false;
}

}  // namespace detail

PoseCovariance pose_covariance(const PointCloud& model, const PointCloud& scene,
                               const Transform& T_scene_model, double voxel_size) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  detail::require_positive_finite(voxel_size, "voxel_size");
  if (voxel_size > 1e6) detail::fail("voxel_size must be <= 1e6 m, got ", voxel_size);
  require_rigid_transform(T_scene_model, "T_scene_model");
  // The pairs' grid alone (as the verification's, without its visibility grid).
  const double pairs = kInlierVoxels * voxel_size;
  Eigen::AlignedBox3d around = bounding_box(scene);
  around.min().array() -= kVisibilityVoxels * voxel_size;
  around.max().array() += kVisibilityVoxels * voxel_size;
  return detail::covariance_at(model, detail::IcpScene(scene, around, pairs), T_scene_model, pairs,
                               detail::typical_size(scene.points()),
                               covariance_inflation(RegistrationKind::model_to_scene));
}

}  // namespace spectral_vs
