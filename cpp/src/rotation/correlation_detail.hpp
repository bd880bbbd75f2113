#pragma once
// The coefficient vectors as the correlation uses them, shared by So3Correlation,
// rotation_cost and so3_search so that all three define C identically.

#include <spectral_vs/rotation/spherical_harmonics.hpp>

namespace spectral_vs::detail {

/// Checks both vectors; normalised: l = 0 zeroed and each scaled to unit norm over l >= 1.
/// @throws std::invalid_argument naming target_coefficients / model_coefficients.
void prepare_correlation(const ShCoefficients& target, const ShCoefficients& model, int bandwidth,
                         bool normalised, ShCoefficients& target_out, ShCoefficients& model_out);

}  // namespace spectral_vs::detail
