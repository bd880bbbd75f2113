#pragma once
// Unchecked kernels shared by the rotation sources; the public functions check inputs.

#include <spectral_vs/rotation/spherical_harmonics.hpp>

namespace spectral_vs::detail {

/// S^l_m(x, y, z) for l <= lmax into out[0 .. (lmax+1)^2), for a unit vector.
void real_sh_unit(double x, double y, double z, int lmax, double* out);

/// A transform per bandwidth, built once and shared (construction is mutex-guarded).
const SphericalHarmonicTransform& cached_transform(int bandwidth);

/// Largest degree l any rotation function accepts.
inline constexpr int kMaxDegree = kMaxBandwidth - 1;

/// Throws unless 0 <= lmax <= kMaxDegree.
void require_degree(int lmax, const char* argument);

}  // namespace spectral_vs::detail
