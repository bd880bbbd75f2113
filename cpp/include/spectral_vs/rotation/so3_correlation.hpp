#pragma once
/// @file so3_correlation.hpp
/// The correlation of two EGIs over SO(3), its gradient and Hessian (paper, eq. 12-15)
/// and the rotation cost J_r (eq. 16).
///
/// C(R) = sum_l (F_target^l)^T U^l(R) F_model^l. If target normals = R* model normals,
/// then F_target = U(R*) F_model and C is largest at R = R*. The paper's factor 1/(4 pi)
/// is left out: it only rescales the gain.

#include <spectral_vs/rotation/spherical_harmonics.hpp>
#include <spectral_vs/rotation/wigner.hpp>

#include <Eigen/Core>
#include <array>
#include <optional>

namespace spectral_vs {

/// C(R) with its derivatives for the right perturbation R exp(hat(e)), e in radians.
struct CorrelationValue {
  /// C(R).
  double value = 0.0;
  /// dC/de at e = 0, per radian (eq. 15).
  Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
  /// d2C/de2 at e = 0, per radian^2, symmetric; filled only when asked.
  Eigen::Matrix3d hessian = Eigen::Matrix3d::Zero();
};

/// Evaluates C at many rotations for fixed target and model coefficients.
///
/// The gradient pairs with the update R <- R exp(lambda hat(gradient)) of eq. (17).
/// normalised = true: the cosine similarity of the coefficient vectors with l = 0 left
/// out (both divided by their norm over l >= 1), so C is in [-1, 1], equals 1 exactly
/// when the target is a rotated copy of the model, and a gain means the same for any
/// point count and bandwidth. normalised = false: the paper's sum over l = 0..B-1.
/// Holds re-used buffers: one object per thread.
class So3Correlation {
 public:
  /// @throws std::invalid_argument for wrong sizes or non-finite coefficients, or,
  ///         normalised, for coefficients with no energy at l >= 1 (a uniform EGI).
  So3Correlation(const ShCoefficients& target, const ShCoefficients& model, int bandwidth,
                 bool normalised = true);

  /// C(R), its gradient, and its Hessian when with_hessian. O(B^3).
  /// @throws std::invalid_argument if R is not a rotation.
  CorrelationValue evaluate(const Eigen::Matrix3d& R, bool with_hessian = false);

  int bandwidth() const { return bandwidth_; }
  bool normalised() const { return normalised_; }
  /// |target| |model| as correlated, the bound of |C| (1 when normalised; 1 for zero input).
  double scale() const { return scale_; }

 private:
  int bandwidth_;
  bool normalised_;
  double scale_ = 1.0;
  ShCoefficients target_, model_;               // as correlated (normalised when asked)
  std::array<ShCoefficients, 3> model_first_;   // u_k F, k = x, y, z
  std::array<ShCoefficients, 6> model_second_;  // (u_i u_j + u_j u_i) F / 2: xx yy zz xy xz yz
  std::optional<WignerPullback> pullback_;      // of degrees 0..B-1, made once B is checked
  ShCoefficients pulled_target_;                // U(R)^T target, per degree
};

/// J_r of eq. (16): 0.5 ||g - f(R^T .)||^2 = 0.5 sum_l |G^l - U^l(R) F^l|^2 (Parseval),
/// g the target and f the model, in the same normalisation as So3Correlation
/// (normalised: 1 - C(R), in [0, 2]).
double rotation_cost(const ShCoefficients& target, const ShCoefficients& model,
                     const Eigen::Matrix3d& R, int bandwidth, bool normalised = true);

}  // namespace spectral_vs
