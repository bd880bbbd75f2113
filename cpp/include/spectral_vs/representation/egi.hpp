#pragma once
/// @file egi.hpp
/// The Extended Gaussian Image f_r of eq. (3)-(4): the representation used for rotation.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>

namespace spectral_vs {

/// Largest bandwidth any spherical function of the library accepts (a 256 x 256 grid).
inline constexpr int kMaxBandwidth = 128;

/// (2B) x (2B) grid, row j = colatitude theta_j = pi (2j+1) / (4B),
/// column k = longitude phi_k = pi k / B.
using SphereGrid = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// Colatitude theta_j of row j of a bandwidth-B grid, radians.
double grid_theta(int j, int bandwidth);
/// Longitude phi_k of column k of a bandwidth-B grid, radians.
double grid_phi(int k, int bandwidth);

/// Cell of the grid node nearest to unit vector n: j = floor(theta * 2B / pi)
/// (clamped to 2B-1), k = round(phi * B / pi) mod 2B, with theta in [0, pi] and
/// phi = atan2(n_y, n_x) in [0, 2 pi).
/// @throws std::invalid_argument for an invalid bandwidth or a zero or non-finite normal.
Eigen::Vector2i egi_cell(const Eigen::Vector3d& normal, int bandwidth);

/// Histogram of unit normals on the bandwidth-B grid: entry [j, k] counts the
/// normals whose nearest node is (theta_j, phi_k) (eq. 4). With `weights`
/// (one per normal, finite) each normal adds its weight instead of 1.
/// @throws std::invalid_argument for a bandwidth outside [1, kMaxBandwidth], an
///         empty normal set, or weights of the wrong length.
SphereGrid egi_histogram(const Points& normals, int bandwidth,
                         const Eigen::VectorXd* weights = nullptr);

/// Throws std::invalid_argument unless 1 <= bandwidth <= kMaxBandwidth.
void require_bandwidth(int bandwidth, const char* argument = "bandwidth");

}  // namespace spectral_vs
