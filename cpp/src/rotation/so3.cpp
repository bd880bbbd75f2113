#include <spectral_vs/rotation/so3.hpp>

#include "common/checks.hpp"

#include <Eigen/Geometry>
#include <cmath>

namespace spectral_vs {

using detail::fail;

Eigen::Matrix3d hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& given) {
  // A turn of 2 pi more is the same rotation: beyond it the angle is reduced, so that
  // K K of a huge vector cannot overflow (1e200 rad gave NaN).
  Eigen::Vector3d omega = given;
  const double full = omega.stableNorm();      // no overflow of the squares of 1e200
  constexpr double kTurn = 6.283185307179586;  // 2 pi
  if (omega.allFinite() && !std::isfinite(full)) {
    fail("omega: its norm exceeds the largest double (", omega.cwiseAbs().maxCoeff(),
         " rad on an axis): no angle to reduce");
  }
  if (std::isfinite(full) && full > kTurn) omega *= std::fmod(full, kTurn) / full;
  const double angle = omega.norm();
  const Eigen::Matrix3d K = hat(omega);
  // Taylor terms below 1e-4 rad keep sin(t)/t and (1 - cos t)/t^2 exact to rounding.
  const double a = angle < 1e-4 ? 1.0 - angle * angle / 6.0 : std::sin(angle) / angle;
  const double b =
      angle < 1e-4 ? 0.5 - angle * angle / 24.0 : (1.0 - std::cos(angle)) / (angle * angle);
  return Eigen::Matrix3d::Identity() + a * K + b * K * K;
}

Eigen::Vector3d log_so3(const Eigen::Matrix3d& R) {
  // Through the quaternion: well conditioned at every angle, including pi.
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() *= -1.0;
  const double s = q.vec().norm();
  if (s < 1e-300) return Eigen::Vector3d::Zero();
  const double angle = 2.0 * std::atan2(s, q.w());
  return q.vec() * (angle / s);
}

double rotation_distance(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  // angle * (|v| / |v|) may round one ulp past pi.
  return std::min(log_so3(a.transpose() * b).norm(), 3.141592653589793);
}

Eigen::Matrix3d euler_zyz(double alpha, double beta, double gamma) {
  return (Eigen::AngleAxisd(alpha, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(beta, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(gamma, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

void require_rotation(const Eigen::Matrix3d& R, const std::string& argument, double tolerance) {
  if (!R.allFinite()) fail(argument, " is not finite");
  const double orthogonality =
      (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = R.determinant();
  if (orthogonality > tolerance || std::abs(det - 1.0) > tolerance) {
    fail(argument, " is not a rotation matrix: max |R^T R - I| = ", orthogonality,
         " and det = ", det, " (tolerance ", tolerance, ")");
  }
}

}  // namespace spectral_vs
