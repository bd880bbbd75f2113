#pragma once
/// @file so3.hpp
/// The few operations on the rotation group SO(3) that the rotation estimation needs:
/// the hat map, the exponential and logarithm (eq. 8 and the update rule of eq. 17), ZYZ
/// Euler angles (eq. 8, used only by the grid of the global search) and input checks.

#include <Eigen/Core>
#include <string>

namespace spectral_vs {

/// The skew-symmetric matrix with hat(v) x = v.cross(x).
Eigen::Matrix3d hat(const Eigen::Vector3d& v);

/// exp(hat(omega)): the rotation by |omega| radians about omega / |omega| (Rodrigues).
Eigen::Matrix3d exp_so3(const Eigen::Vector3d& omega);

/// The rotation vector omega, |omega| in [0, pi] radians, with exp_so3(omega) = R.
/// At exactly pi the sign of the axis is arbitrary.
Eigen::Vector3d log_so3(const Eigen::Matrix3d& R);

/// Angle of the rotation a^T b, radians in [0, pi]: the geodesic distance on SO(3).
double rotation_distance(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b);

/// R = Rz(alpha) Ry(beta) Rz(gamma), angles in radians (the paper's eq. 8).
Eigen::Matrix3d euler_zyz(double alpha, double beta, double gamma);

/// Throws std::invalid_argument naming `argument` unless R is finite, orthonormal
/// (max |R^T R - I| <= tolerance) and has determinant +1 (within tolerance).
void require_rotation(const Eigen::Matrix3d& R, const std::string& argument,
                      double tolerance = 1e-6);

}  // namespace spectral_vs
