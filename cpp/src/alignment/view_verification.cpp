// Stage of align_views(): verification. The returned pose's score against the current
// view and its alternatives among the checked hypotheses; the verdict on them is the one
// of both modes (judge_pose, verdict_detail.hpp).

#include <spectral_vs/alignment/verdict.hpp>
#include <spectral_vs/rotation/so3.hpp>

#include "alignment/point_sets.hpp"
#include "alignment/scale.hpp"
#include "alignment/verdict_detail.hpp"
#include "alignment/view_stages.hpp"

#include <cmath>

namespace spectral_vs::detail::views {

namespace {

// The verification: reference points it checks, at most (a stride over the prepared
// reference: the score is a share, which 8000 points measure to about 1%); hypotheses
// refined as candidate alternatives, of those whose coarse support is at least
// kAlternativeSupportShare of the best one's; the margin of score within which one is an
// alternative (as align()'s); the alternatives kept.
constexpr Eigen::Index kVerdictPoints = 8000;
constexpr int kAlternativeCandidates = 4;
constexpr double kAlternativeSupportShare = 0.5;
constexpr double kViewAlternativeMargin = 0.05;
constexpr std::size_t kMaxViewAlternatives = 3;
// Poses apart: over this rotation, or over a voxel between the reference's centroids.
constexpr double kApartRadians = 5.0 * M_PI / 180.0;

// Stage: verification, then the verdict. The reference (at most kVerdictPoints of it)
// verified against the current view from its sensor; the alternatives are the
// best-supported other hypotheses, refined by the ICP and scored alike.
class ViewVerification {
 public:
  explicit ViewVerification(const Views& views)
      : views_(views),
        sample_(every_nth(views.reference)),
        verifier_(views.verifier),
        centroid_(sample_.centroid()) {}

  // The score of a pose (ViewAlignResult::score) and its verification.
  // Two checks multiplied: the reference's points against the current view (confirmed /
  // sqrt(visible x checked)), and its structure against the current's depth image (the
  // support's fitness at a quarter voxel). The first tells a pose that lays the
  // reference where the current saw surfaces; the second, one that only lays a plane
  // (a table, a floor) on a plane. On the calibration set the product ranked right and
  // wrong answers better (ROC AUC 0.997) than either alone (0.92, 0.98).
  double score(const Transform& T, double support_fitness,
               PoseVerification* verification = nullptr) const {
    const PoseVerification v = verifier_.verify(sample_, T);
    if (verification) *verification = v;
    if (v.visible == 0) return 0.0;
    return double(v.tight) / std::sqrt(double(v.visible) * double(sample_.points().rows())) *
           support_fitness;
  }

  void judge(ViewAlignResult& result, const std::vector<Hypothesis>& checked,
             bool timed_out) const {
    PoseVerification v;
    result.score = score(result.T_current_reference, result.support.fitness, &v);
    result.inliers = v.inliers;
    result.inlier_fraction = v.inlier_fraction;
    result.inlier_rmse = v.inlier_rmse;
    result.inlier_distance = v.inlier_distance;
    if (!timed_out) add_alternatives(result, checked);
    detail::VerdictCase c;
    c.score = result.score;
    c.kind = RegistrationKind::view_to_view;
    c.T = result.T_current_reference;
    c.inlier_distance = v.inlier_distance;
    c.voxel_size = views_.scale.voxel_size;
    c.model_extent = detail::typical_size(views_.reference.points());
    c.scene_extent = detail::typical_size(views_.current.points());
    c.supported = result.support.confirmed > 0 && v.tight > 0;
    c.timed_out = timed_out;
    detail::write_judgement(
        detail::judge_pose(c, sample_, verifier_.fine_grid(), result.alternatives,
                           [](const ViewAlternative& a) { return a.T_current_reference; }),
        result);
  }

 private:
  // At most kVerdictPoints of the cloud, at a fixed stride.
  static PointCloud every_nth(const PointCloud& cloud) {
    const Eigen::Index count = cloud.points().rows();
    const Eigen::Index stride =
        std::max<Eigen::Index>(1, (count + kVerdictPoints - 1) / kVerdictPoints);
    std::vector<Eigen::Index> rows;
    for (Eigen::Index i = 0; i < count; i += stride) rows.push_back(i);
    return PointCloud(detail::rows_of(cloud.points(), rows),
                      detail::rows_of(cloud.normals(), rows));
  }

  // Whether T is apart from `other`: rotation over kApartRadians, or the reference's
  // centroid moved over a voxel.
  bool apart(const Transform& T, const Transform& other) const {
    const Eigen::Matrix3d R = T.topLeftCorner<3, 3>(), S = other.topLeftCorner<3, 3>();
    const Eigen::Vector3d a = R * centroid_ + T.topRightCorner<3, 1>();
    const Eigen::Vector3d b = S * centroid_ + other.topRightCorner<3, 1>();
    return rotation_distance(R, S) > kApartRadians || (a - b).norm() > views_.scale.voxel_size;
  }

  void add_alternatives(ViewAlignResult& result, const std::vector<Hypothesis>& checked) const {
    if (checked.empty()) return;
    const double floor = kAlternativeSupportShare * checked.front().support.score;
    int tried = 0;
    for (const Hypothesis& h : checked) {
      if (tried == kAlternativeCandidates || h.support.score < floor) break;
      const Transform start = views_.model.transform_of(h.pose);
      if (!apart(start, result.T_current_reference)) continue;
      ++tried;
      detail::IcpSettings icp;
      icp.viewpoint = views_.params.sensor_origin;
      const Transform T = detail::refine_in_two_stages(views_.reference, views_.fine_scene, start,
                                                       views_.scale.voxel_size, icp)
                              .T_scene_model;
      if (!apart(T, result.T_current_reference)) continue;
      const double s = score(T, views_.support.of(T, kFineTolerance).fitness);
      if (s < result.score - kViewAlternativeMargin) continue;
      const bool repeated =
          std::any_of(result.alternatives.begin(), result.alternatives.end(),
                      [&](const ViewAlternative& a) { return !apart(T, a.T_current_reference); });
      if (repeated) continue;
      ViewAlternative alternative;
      alternative.T_current_reference = T;
      alternative.score = s;
      alternative.confidence = calibrated_confidence(s, RegistrationKind::view_to_view);
      const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
      const Eigen::Matrix3d S = result.T_current_reference.topLeftCorner<3, 3>();
      alternative.rotation_apart = rotation_distance(R, S);
      alternative.translation_apart = ((R - S) * centroid_ + T.topRightCorner<3, 1>() -
                                       result.T_current_reference.topRightCorner<3, 1>())
                                          .norm();
      result.alternatives.push_back(alternative);
    }
    std::stable_sort(
        result.alternatives.begin(), result.alternatives.end(),
        [](const ViewAlternative& a, const ViewAlternative& b) { return a.score > b.score; });
    if (result.alternatives.size() > kMaxViewAlternatives)
      result.alternatives.resize(kMaxViewAlternatives);
  }

  const Views& views_;
  PointCloud sample_;
  const detail::Verifier& verifier_;
  Eigen::Vector3d centroid_;
};

}  // namespace

void judge(const Views& views, ViewAlignResult& result, const std::vector<Hypothesis>& checked,
           bool timed_out) {
  ViewVerification(views).judge(result, checked, timed_out);
}

}  // namespace spectral_vs::detail::views
