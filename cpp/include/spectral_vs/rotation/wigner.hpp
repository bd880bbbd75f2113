#pragma once
/// @file wigner.hpp
/// Real Wigner matrices U^l(R) (paper, eq. 9-10) and their generators u^l(e_k) (eq. 13).
///
/// Convention: if g(x) = f(R^T x), the real SH coefficients (spherical_harmonics.hpp)
/// satisfy G^l = U^l(R) F^l. U^l is orthogonal and a representation:
/// U^l(R1 R2) = U^l(R1) U^l(R2). U^1(R) is R with rows and columns reordered (y, z, x).

#include <spectral_vs/rotation/spherical_harmonics.hpp>

#include <Eigen/Core>
#include <vector>

namespace spectral_vs {

/// U^l for l = 0..lmax, each (2l+1) x (2l+1), indexed [m + l, m' + l].
using WignerMatrices = std::vector<Eigen::MatrixXd>;

/// U^l(R) for l = 0..lmax, built from R itself by the Ivanic-Ruedenberg recursion
/// (J. Phys. Chem. 100, 6342 (1996), with the erratum of 102, 9099 (1998)): no Euler
/// angles, so no singular rotation. O(lmax^3).
/// @throws std::invalid_argument if R is not a rotation (require_rotation) or lmax is
///         outside [0, kMaxBandwidth - 1].
WignerMatrices wigner_real(const Eigen::Matrix3d& R, int lmax);

/// wigner_real into `out`, re-using its storage when the sizes already match (no
/// allocation in a loop at fixed lmax).
void wigner_real_into(const Eigen::Matrix3d& R, int lmax, WignerMatrices& out);

/// The generators u^l(e_k) = d/de U^l(exp(e hat(e_k))) at e = 0 for k = x, y, z, dense,
/// l = 0..lmax. They are constant, antisymmetric and sparse (at most two non-zeros per
/// row and column), entries of the form sqrt((l-m)(l+m+1))/2, sqrt(l(l+1)/2) or m.
struct WignerGenerators {
  std::vector<Eigen::MatrixXd> x, y, z;
};

/// Generators for degrees 0..lmax: 3 sum_l (2l+1)^2 doubles (67 MB at lmax = 127), built
/// at each call (about the cost of zeroing them; a cache per lmax held 2.1 GB once every
/// lmax had been asked for).
/// @throws std::invalid_argument if lmax is outside [0, kMaxBandwidth - 1].
WignerGenerators wigner_generators(int lmax);

/// y = u^l(e_axis) x for one degree l = (x.size() - 1) / 2, axis 0, 1, 2 = x, y, z,
/// without forming the matrix (O(l)).
void apply_wigner_generator(int axis, const Eigen::Ref<const Eigen::VectorXd>& x,
                            Eigen::Ref<Eigen::VectorXd> y);

/// U(R)^T x for SH coefficient vectors of degrees 0..lmax, without forming U(R): by the
/// zyz factorisation R = Rz(alpha) Ry(beta) Rz(gamma), U(R) = Z(alpha) K^T Z(beta) K Z(gamma)
/// with Z(theta) = U(Rz(theta)) a rotation of each (m, -m) pair by m theta and
/// K = U(Rx(90 degrees)) fixed. Two dense products per degree, against the five
/// multiply-adds per entry of the recursion and one product: what an SO(3) correlation
/// evaluates at each rotation. A rotation within 45 degrees of a pole (|R(2, 2)| > cos 45)
/// is first turned by Rx(-90) so that beta stays well conditioned. Agrees with
/// wigner_real to rounding (tests/cpp/rotation_test.cpp).
class WignerPullback {
 public:
  /// @throws std::invalid_argument if lmax is outside [0, kMaxBandwidth - 1].
  explicit WignerPullback(int lmax);

  /// out = U(R)^T x; x holds (lmax + 1)^2 coefficients. `out` must not be `x`.
  /// @throws std::invalid_argument if R is not a rotation or x has another size.
  void apply(const Eigen::Matrix3d& R, const ShCoefficients& x, ShCoefficients& out);

  int lmax() const { return lmax_; }

 private:
  // y = Z(theta)^T y, degree by degree.
  void turn_about_z(double theta, ShCoefficients& y);
  // out = K x (transposed: K^T x), degree by degree.
  void quarter_turn(const ShCoefficients& x, ShCoefficients& out, bool transposed) const;

  int lmax_;
  WignerMatrices quarter_;  // K = U(Rx(90 degrees)), per degree
  ShCoefficients work_;
  std::vector<double> cos_, sin_;  // cos(m theta), sin(m theta), m = 0..lmax
};

/// G^l = U^l F^l for every degree of F; U must hold at least the degrees of F.
/// @throws std::invalid_argument if F is not a full B^2 vector or U has too few degrees.
ShCoefficients rotate_coefficients(const ShCoefficients& F, const WignerMatrices& U);

}  // namespace spectral_vs
