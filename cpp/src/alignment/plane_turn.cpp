// PlaneTurn (plane_turn.hpp): the turn about a reference's dominant normal, on the EGIs of
// the normals off its plane, by the registration's rotation law along that one axis.

#include <spectral_vs/alignment/plane_turn.hpp>

#include <spectral_vs/representation/dominant_plane.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/point_sets.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

void check_params(const PlaneTurnParams& p) {
  if (!(p.plane_cone > 0.0 && p.plane_cone < M_PI / 2))
    fail("plane_cone must be in (0, pi/2) rad, got ", p.plane_cone);
  if (!(p.min_plane_share >= 0.0 && p.min_plane_share <= 1.0))
    fail("min_plane_share must be in [0, 1], got ", p.min_plane_share);
  if (p.stride < 1) fail("stride must be >= 1, got ", p.stride);
  if (p.bandwidth < 2 || p.bandwidth > kMaxAlignBandwidth)
    fail("bandwidth must be in [2, ", kMaxAlignBandwidth, "], got ", p.bandwidth);
  if (p.fine_bandwidth < 2 || p.fine_bandwidth > kMaxAlignBandwidth)
    fail("fine_bandwidth must be in [2, ", kMaxAlignBandwidth, "], got ", p.fine_bandwidth);
  if (!(p.max_tilt >= 0.0 && std::isfinite(p.max_tilt)))
    fail("max_tilt must be finite and >= 0 rad, got ", p.max_tilt);
}

// Every stride-th normal split by a plane's normal: the rows off the plane (farther from
// `normal` than the cone) and the sum of the others (on the plane).
struct PlaneSplit {
  std::vector<Eigen::Index> off;
  Eigen::Vector3d on_sum = Eigen::Vector3d::Zero();
  Eigen::Index sampled = 0;
};

PlaneSplit split_by_plane(const Points& normals, int stride, const Eigen::Vector3d& normal,
                          double cos_cone) {
  PlaneSplit split;
  for (Eigen::Index row = 0; row < normals.rows(); row += stride, ++split.sampled) {
    if (normals.row(row).dot(normal) <= cos_cone) {
      split.off.push_back(row);
    } else {
      split.on_sum += normals.row(row).transpose();
    }
  }
  return split;
}

// The step of the law along `axis` on the correlation of the first `bandwidth` degrees.
AxisRotationStep step_at(const ShCoefficients& current, const ShCoefficients& reference,
                         int bandwidth, const Eigen::Matrix3d& R, const Eigen::Vector3d& axis,
                         const AlignParams& law) {
  const Eigen::Index count = Eigen::Index(bandwidth) * bandwidth;  // degrees < B come first
  So3Correlation correlation(current.head(count), reference.head(count), bandwidth, true);
  return rotation_step_about(correlation, R, axis, law);
}

}  // namespace

PlaneTurn::PlaneTurn(const Eigen::Vector3d& axis, ShCoefficients coefficients,
                     PlaneTurnParams params)
    : axis_(axis),
      coefficients_(std::move(coefficients)),
      params_(std::move(params)),
      cos_cone_(std::cos(params_.plane_cone)) {}

std::optional<PlaneTurn> PlaneTurn::of(const PointCloud& reference, const PlaneTurnParams& params) {
  check_params(params);
  require_normals(reference, "reference");
  PlaneDetectionParams detection;
  detection.member_cone = params.plane_cone;
  const DominantDirection dominant = dominant_direction(reference.normals(), detection);
  const Points& normals = reference.normals();
  const PlaneSplit split =
      split_by_plane(normals, params.stride, dominant.axis, std::cos(params.plane_cone));
  if (dominant.share < params.min_plane_share || Eigen::Index(split.off.size()) < kMinOffPlane)
    return std::nullopt;
  PlaneTurnParams kept = params;
  kept.fine_bandwidth = std::max(params.fine_bandwidth, params.bandwidth);
  kept.law.local.rotation_gain = 1.0;
  ShCoefficients coefficients =
      egi_coefficients(detail::rows_of(normals, split.off), kept.fine_bandwidth);
  return PlaneTurn(dominant.axis, std::move(coefficients), std::move(kept));
}

double PlaneTurn::turn(const PointCloud& current, const Eigen::Matrix3d& R) const {
  require_normals(current, "current");
  const Eigen::Vector3d expected = R * axis_;  // where the estimate puts the plane's normal
  const Points& normals = current.normals();
  const PlaneSplit split = split_by_plane(normals, params_.stride, expected, cos_cone_);
  const auto off = Eigen::Index(split.off.size());
  if (off < kMinOffPlane || off == split.sampled) return 0.0;
  // The tilt still off: the turn would be measured about a wrong axis.
  const Eigen::Vector3d& plane = split.on_sum;
  if (plane.dot(expected) < std::cos(params_.max_tilt) * plane.norm()) return 0.0;
  const ShCoefficients fine =
      egi_coefficients(detail::rows_of(normals, split.off), params_.fine_bandwidth);
  const AxisRotationStep coarse =
      step_at(fine, coefficients_, params_.bandwidth, R, axis_, params_.law);
  if (!coarse.newton || coarse.capped) return coarse.turn;
  if (params_.fine_bandwidth > params_.bandwidth) {
    const AxisRotationStep sharp =
        step_at(fine, coefficients_, params_.fine_bandwidth, R, axis_, params_.law);
    if (sharp.newton && !sharp.capped) return sharp.turn;
  }
  return coarse.turn;
}

}  // namespace spectral_vs
