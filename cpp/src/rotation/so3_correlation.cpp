#include <spectral_vs/rotation/so3_correlation.hpp>

#include "common/checks.hpp"
#include "rotation/correlation_detail.hpp"

namespace spectral_vs {

using detail::fail;

namespace detail {

namespace {

ShCoefficients prepared(const ShCoefficients& c, int bandwidth, bool normalised,
                        const char* argument) {
  require_coefficients(c, bandwidth, argument);
  if (!normalised) {
    // |C| <= |t| |f| (U orthogonal), its derivatives up to l^2 times that: finite below it.
    constexpr double kMaxRawNorm = 1e150;
    if (const double norm = c.stableNorm(); norm > kMaxRawNorm) {
      fail(argument, " has norm ", norm, ", over ", kMaxRawNorm,
           ": the raw correlation (normalised=False) of it would overflow");
    }
    return c;
  }
  ShCoefficients out = c;
  out[0] = 0.0;
  const double norm = out.stableNorm();
  if (!(norm > 0.0)) {
    fail(argument,
         " has no energy at degrees l >= 1 (a uniform EGI): the normalised correlation is "
         "undefined");
  }
  return out / norm;
}

}  // namespace

void prepare_correlation(const ShCoefficients& target, const ShCoefficients& model, int bandwidth,
                         bool normalised, ShCoefficients& target_out, ShCoefficients& model_out) {
  target_out = prepared(target, bandwidth, normalised, "target_coefficients");
  model_out = prepared(model, bandwidth, normalised, "model_coefficients");
}

}  // namespace detail

namespace {

// u_axis applied degree by degree to a flat coefficient vector.
ShCoefficients apply_generator(int axis, const ShCoefficients& c, int bandwidth) {
  ShCoefficients out(c.size());
  for (int l = 0; l < bandwidth; ++l) {
    apply_wigner_generator(axis, c.segment(l * l, 2 * l + 1), out.segment(l * l, 2 * l + 1));
  }
  return out;
}

constexpr int kPairs[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};

}  // namespace

So3Correlation::So3Correlation(const ShCoefficients& target, const ShCoefficients& model,
                               int bandwidth, bool normalised)
    : bandwidth_(bandwidth), normalised_(normalised) {
  detail::prepare_correlation(target, model, bandwidth, normalised, target_, model_);
  if (const double scale = target_.norm() * model_.norm(); !normalised && scale > 0.0) {
    scale_ = scale;
  }
  // The model side of eq. (15) and of the Hessian does not depend on R: apply the
  // generators once here, so an evaluation costs U(R) and one product per degree.
  for (int k = 0; k < 3; ++k) model_first_[k] = apply_generator(k, model_, bandwidth);
  for (int p = 0; p < 6; ++p) {
    const int i = kPairs[p][0], j = kPairs[p][1];
    model_second_[p] = 0.5 * (apply_generator(i, model_first_[j], bandwidth) +
                              apply_generator(j, model_first_[i], bandwidth));
  }
  pulled_target_.resize(target_.size());
  pullback_.emplace(bandwidth - 1);
}

CorrelationValue So3Correlation::evaluate(const Eigen::Matrix3d& R, bool with_hessian) {
  // C = T^T U F = (U^T T)^T F; the same pulled-back target serves every derivative,
  // since d/de U(R exp(hat e)) = U(R) u(e) (eq. 14).
  pullback_->apply(R, target_, pulled_target_);
  CorrelationValue out;
  out.value = pulled_target_.dot(model_);
  for (int k = 0; k < 3; ++k) out.gradient[k] = pulled_target_.dot(model_first_[k]);
  if (with_hessian) {
    for (int p = 0; p < 6; ++p) {
      const int i = kPairs[p][0], j = kPairs[p][1];
      out.hessian(i, j) = out.hessian(j, i) = pulled_target_.dot(model_second_[p]);
    }
  }
  return out;
}

double rotation_cost(const ShCoefficients& target, const ShCoefficients& model,
                     const Eigen::Matrix3d& R, int bandwidth, bool normalised) {
  ShCoefficients g, f;
  detail::prepare_correlation(target, model, bandwidth, normalised, g, f);
  const ShCoefficients rotated = rotate_coefficients(f, wigner_real(R, bandwidth - 1));
  return 0.5 * (g - rotated).squaredNorm();
}

}  // namespace spectral_vs
