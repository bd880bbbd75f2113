#pragma once
/// @file spherical_harmonics.hpp
/// Real spherical harmonics and the spherical harmonic transform on the EGI grid
/// (paper, eq. 5-6: f = sum_l (F^l)^T S^l).
///
/// Convention. S^l_m are the orthonormal real harmonics (integral of S^l_m S^l'_m' over
/// the sphere = delta), WITHOUT the Condon-Shortley phase, with N^l_m the usual
/// normalisation sqrt((2l+1)/(4 pi) (l-|m|)!/(l+|m|)!) and P^l_m the associated Legendre
/// function without the (-1)^m factor:
///   S^l_m = sqrt(2) N^l_|m| P^l_|m|(cos theta) cos(m phi)     for m > 0,
///   S^l_0 = N^l_0 P^l_0(cos theta),
///   S^l_m = sqrt(2) N^l_|m| P^l_|m|(cos theta) sin(|m| phi)   for m < 0.
/// So S^1_{-1}, S^1_0, S^1_1 = sqrt(3 / (4 pi)) (y, z, x): the ordering of Ivanic and
/// Ruedenberg, whose recursion builds the rotation matrices of wigner.hpp.
/// Coefficients are flat vectors of size B^2, entry l*l + l + m for l = 0..B-1, m = -l..l.

#include <spectral_vs/representation/egi.hpp>

#include <Eigen/Core>
#include <vector>

namespace spectral_vs {

/// Flat real SH coefficients, entry sh_index(l, m), l = 0..B-1, m = -l..l (size B^2).
using ShCoefficients = Eigen::VectorXd;

/// Position of (l, m) in a flat coefficient vector.
inline int sh_index(int l, int m) { return l * l + l + m; }

/// Number of coefficients of degrees l < bandwidth: bandwidth^2.
inline int sh_count(int bandwidth) { return bandwidth * bandwidth; }

/// Throws std::invalid_argument naming `argument` unless the bandwidth is valid and
/// `coefficients` has bandwidth^2 finite entries.
void require_coefficients(const ShCoefficients& coefficients, int bandwidth, const char* argument);

/// Values S^l_m(direction) for all l <= lmax in the flat layout; `out` must have size
/// (lmax + 1)^2. The direction is normalised first; exact at the poles (no atan2).
/// @throws std::invalid_argument for a zero or non-finite direction, lmax outside
///         [0, kMaxBandwidth - 1], or `out` of the wrong size.
void real_spherical_harmonics(const Eigen::Vector3d& unit_direction, int lmax,
                              Eigen::Ref<Eigen::VectorXd> out);

/// Forward and inverse SH transform on the (2B) x (2B) grid of egi.hpp.
///
/// The forward transform integrates with the Driscoll-Healy quadrature, exact for any
/// function of degree <= B-1 (so the round trip inverse(forward(f)) = f holds for such
/// f). Cost O(B^3): a product with a cached cos/sin table over phi, then one cached
/// Legendre table per order m over theta. Construction O(B^3) time and B^3 doubles of
/// memory (16 MB at B = 128). forward/inverse are const and safe to call concurrently.
class SphericalHarmonicTransform {
 public:
  /// @throws std::invalid_argument unless 1 <= bandwidth <= kMaxBandwidth.
  explicit SphericalHarmonicTransform(int bandwidth);

  int bandwidth() const { return bandwidth_; }

  /// Coefficients of degrees l < B of the function sampled on the grid.
  /// @throws std::invalid_argument if `samples` is not (2B) x (2B) or not finite.
  ShCoefficients forward(const SphereGrid& samples) const;

  /// The band-limited function with these coefficients, sampled on the grid.
  /// @throws std::invalid_argument if `coefficients` does not have B^2 finite entries.
  SphereGrid inverse(const ShCoefficients& coefficients) const;

  /// Quadrature weight of row j (theta_j): the integral over the sphere is
  /// sum_j weight(j) sum_k f(theta_j, phi_k).
  double weight(int j) const { return weights_[static_cast<std::size_t>(j)]; }

 private:
  int bandwidth_;
  std::vector<double> weights_;            // per row j, including the phi step pi / B
  Eigen::MatrixXd cos_table_, sin_table_;  // (2B) x B: cos(m phi_k), sin(m phi_k)
  std::vector<Eigen::MatrixXd> legendre_;  // per m: (B - m) x (2B), N^l_m P^l_m(cos theta_j)
};

/// Coefficients of a function sampled on the bandwidth-B grid (a cached transform).
ShCoefficients sh_coefficients(const SphereGrid& samples, int bandwidth);

/// The function with these coefficients sampled on the bandwidth-B grid.
SphereGrid sh_synthesis(const ShCoefficients& coefficients, int bandwidth);

}  // namespace spectral_vs
