#pragma once
/// @file egi_coefficients.hpp
/// Real SH coefficients F^l_r of an EGI (paper, eq. 5), the input of the rotation
/// estimation, and a heat-kernel smoothing for coarse-to-fine schedules.

#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/rotation/spherical_harmonics.hpp>

namespace spectral_vs {

/// How the coefficients of an EGI are computed.
enum class EgiMethod {
  /// The paper's: the gridded histogram of egi_histogram (counts as function samples,
  /// eq. 4), transformed with the grid quadrature. Snapping normals to grid cells makes
  /// it only approximately rotation-covariant (docs/rotation.md: 35-67 % error).
  histogram,
  /// F^l = sum_i w_i S^l(n_i): the exact coefficients of the EGI as a sum of Dirac
  /// masses, band-limited to l < B. No grid, exactly rotation-covariant. The default.
  projection,
};

/// Coefficients (size B^2) of the EGI of `normals` (rows, normalised here).
/// @param weights one finite weight per normal, or nullptr for 1 each.
/// @throws std::invalid_argument for an invalid bandwidth, no normals, a zero or
///         non-finite normal, or weights of the wrong length.
ShCoefficients egi_coefficients(const Points& normals, int bandwidth,
                                EgiMethod method = EgiMethod::projection,
                                const Eigen::VectorXd* weights = nullptr);

/// egi_coefficients of the cloud's normals. @throws std::invalid_argument without normals.
ShCoefficients egi_coefficients(const PointCloud& cloud, int bandwidth,
                                EgiMethod method = EgiMethod::projection,
                                const Eigen::VectorXd* weights = nullptr);

/// Multiplies degree l by the heat kernel exp(-l (l + 1) sigma^2 / 2): a Gaussian blur
/// of about sigma radians on the sphere. sigma = 0 leaves the coefficients unchanged.
/// @throws std::invalid_argument for sigma < 0 or not finite, or a wrong size.
void smooth_coefficients(ShCoefficients& coefficients, int bandwidth, double sigma);

}  // namespace spectral_vs
