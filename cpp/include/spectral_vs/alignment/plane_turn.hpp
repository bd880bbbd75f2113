#pragma once
/// @file plane_turn.hpp
/// The turn about a reference view's dominant plane (a table top), beyond the paper: the
/// step of the registration's rotation law about the plane's normal, on the EGIs of the
/// normals off that plane. The plane fills most of a tabletop view's EGI and leaves the
/// rotation about its normal almost unseen by Algorithm 1; without it the objects' sides
/// give that rotation a clear peak (docs/servoing.md). The servo turns each tracked
/// estimate by it (ServoParams.plane in Python).

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <optional>

namespace spectral_vs {

/// Settings of PlaneTurn.
struct PlaneTurnParams {
  double plane_cone = 0.3490658503988659;  ///< Half-angle about the dominant normal whose
                                           ///< normals are the plane's, rad (20 degrees), in
                                           ///< (0, pi / 2).
  double min_plane_share = 0.3;            ///< The turn exists when at least this share of the
                                           ///< reference's normals lies in the cone, in [0, 1].
  int stride = 4;           ///< Every stride-th normal is read, >= 1 (the clouds as captured).
  int bandwidth = 16;       ///< B of the coarse step: the registration's, in [2, 64].
  int fine_bandwidth = 16;  ///< B of the fine step near the goal, in [bandwidth, 64].
  double max_tilt = 0.08726646259971647;  ///< No turn while the current view's plane normal
                                          ///< is farther than this from where the estimate
                                          ///< puts the reference's, rad (5 degrees).
  /// The rotation law (rotation_step, max_rotation_step; its rotation_gain is taken as 1:
  /// the turn is one whole step).
  AlignParams law;
};

/// The reference's side of the turn, made once; `turn` per estimate.
class PlaneTurn {
 public:
  /// Fewest normals off the plane (reference or current view) for a turn.
  static constexpr Eigen::Index kMinOffPlane = 50;

  /// The turn of a reference view (its normals, as captured), or none when it has no
  /// dominant plane (under min_plane_share) or too few normals off it.
  /// @throws std::invalid_argument for a reference without normals or settings out of range.
  static std::optional<PlaneTurn> of(const PointCloud& reference, const PlaneTurnParams& params);

  /// The turn about axis() (rad, right-multiplied: R exp(turn hat(axis))) that ascends the
  /// correlation of the off-plane EGIs from the estimate's rotation `R_current_reference`,
  /// given the current view's normals (as captured); 0 when that view shows too few
  /// normals off its plane, or none on it, or its plane's normal is more than max_tilt
  /// from where R puts the reference's. Coarse to fine: the step at `bandwidth`; where
  /// that is an uncapped Newton step and the step at `fine_bandwidth` is one too, that
  /// one. @throws std::invalid_argument for a current view without normals.
  double turn(const PointCloud& current, const Eigen::Matrix3d& R_current_reference) const;

  /// The reference's dominant normal, reference frame (unit).
  const Eigen::Vector3d& axis() const { return axis_; }

 private:
  PlaneTurn(const Eigen::Vector3d& axis, ShCoefficients coefficients, PlaneTurnParams params);

  Eigen::Vector3d axis_;
  ShCoefficients coefficients_;  // the reference's off-plane EGI at the fine bandwidth
  PlaneTurnParams params_;
  double cos_cone_;
};

}  // namespace spectral_vs
