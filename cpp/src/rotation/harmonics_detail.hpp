#pragma once
// Unchecked kernels shared by the rotation sources; the public functions check inputs.

#include <spectral_vs/rotation/spherical_harmonics.hpp>

#include <memory>

namespace spectral_vs::detail {

/// S^l_m(x, y, z) for l <= lmax into out[0 .. (lmax+1)^2), for a unit vector.
void real_sh_unit(double x, double y, double z, int lmax, double* out);

/// Adds sum_j w[j] S^l_m(x[j], y[j], z[j]) for l <= lmax to out[0 .. (lmax+1)^2), for
/// count <= kHarmonicsBlock unit vectors: real_sh_unit for a block of vectors at once,
/// whose inner loops run across the vectors (vectorised), with no per-vector output.
void accumulate_real_sh(const double* x, const double* y, const double* z, const double* w,
                        int count, int lmax, double* out);

/// Vectors per call of accumulate_real_sh.
inline constexpr int kHarmonicsBlock = 32;

/// Bytes of transforms the cache keeps: the largest (B = 128, 17 MB) and the recently used
/// ones beside it. Every bandwidth cached at once took 549 MB and stayed resident.
inline constexpr long long kCachedTransformBytes = 64LL << 20;

/// The transform of a bandwidth, built once and kept while it is among the recently used
/// within kCachedTransformBytes (least recently used dropped first; mutex-guarded).
std::shared_ptr<const SphericalHarmonicTransform> cached_transform(int bandwidth);

/// Largest degree l any rotation function accepts.
inline constexpr int kMaxDegree = kMaxBandwidth - 1;

/// Throws unless 0 <= lmax <= kMaxDegree.
void require_degree(int lmax, const char* argument);

}  // namespace spectral_vs::detail
