#include <spectral_vs/rotation/spherical_harmonics.hpp>

#include "common/checks.hpp"
#include "rotation/harmonics_detail.hpp"

#include <algorithm>
#include <cmath>
#include <list>
#include <memory>
#include <mutex>

namespace spectral_vs {

using detail::fail;

namespace {

// Recurrence factors of the normalised associated Legendre functions (no sin^m):
//   Q^l_m = a(l, m) (z Q^{l-1}_m - b(l, m) Q^{l-2}_m),
// tabulated once for every degree the library accepts (2 x 128 x 128 doubles), because
// computing the square roots per call would cost more than the recurrence itself.
struct LegendreFactors {
  static constexpr int kSize = detail::kMaxDegree + 1;
  std::vector<double> a, b;      // [l * kSize + m]
  std::vector<double> diagonal;  // Q^m_m, m = 0..kMaxDegree
  LegendreFactors() : a(kSize * kSize, 0.0), b(kSize * kSize, 0.0), diagonal(kSize) {
    diagonal[0] = 1.0 / std::sqrt(4.0 * M_PI);
    for (int m = 1; m < kSize; ++m) {
      diagonal[m] = diagonal[m - 1] * std::sqrt((2.0 * m + 1.0) / (2.0 * m));
    }
    for (int l = 1; l < kSize; ++l) {
      for (int m = 0; m < l; ++m) {
        const double l2 = double(l) * l, m2 = double(m) * m;
        a[l * kSize + m] = std::sqrt((4.0 * l2 - 1.0) / (l2 - m2));
        b[l * kSize + m] =
            std::sqrt(((l - 1.0) * (l - 1.0) - m2) / (4.0 * (l - 1.0) * (l - 1.0) - 1.0));
      }
    }
  }
};

const LegendreFactors& legendre_factors() {
  static const LegendreFactors factors;
  return factors;
}

// Q^l_m(z) for l = m..lmax into q[0 .. lmax - m]: P^l_m = sin^m(theta) Q^l_m(cos theta).
void legendre_column(double z, int m, int lmax, double* q) {
  const LegendreFactors& f = legendre_factors();
  constexpr int n = LegendreFactors::kSize;
  q[0] = f.diagonal[m];
  if (lmax == m) return;
  q[1] = std::sqrt(2.0 * m + 3.0) * z * q[0];
  for (int l = m + 2; l <= lmax; ++l) {
    q[l - m] = f.a[l * n + m] * (z * q[l - m - 1] - f.b[l * n + m] * q[l - m - 2]);
  }
}

}  // namespace

namespace detail {

void require_degree(int lmax, const char* argument) {
  if (lmax < 0 || lmax > kMaxDegree)
    fail(argument, " must be in [0, ", kMaxDegree, "], got ", lmax);
}

void real_sh_unit(double x, double y, double z, int lmax, double* out) {
  double q[kMaxDegree + 1];
  // (x + i y)^m = sin^m(theta) e^{i m phi}: the azimuthal factor without atan2.
  double re = 1.0, im = 0.0;
  for (int m = 0; m <= lmax; ++m) {
    legendre_column(z, m, lmax, q);
    if (m == 0) {
      for (int l = 0; l <= lmax; ++l) out[sh_index(l, 0)] = q[l];
    } else {
      const double c = M_SQRT2 * re, s = M_SQRT2 * im;
      for (int l = m; l <= lmax; ++l) {
        out[sh_index(l, m)] = c * q[l - m];
        out[sh_index(l, -m)] = s * q[l - m];
      }
    }
    const double next_re = re * x - im * y;
    im = re * y + im * x;
    re = next_re;
  }
}

void accumulate_real_sh(const double* x, const double* y, const double* z, const double* w,
                        int count, int lmax, double* out) {
  constexpr int K = kHarmonicsBlock;
  const LegendreFactors& f = legendre_factors();
  constexpr int n = LegendreFactors::kSize;
  // Padded to a whole block with zero weights, so every loop below has K iterations.
  double zz[K], re[K], im[K], xs[K], ys[K], c[K], s[K], q_prev[K], q[K], q_next[K];
  for (int j = 0; j < K; ++j) {
    const bool used = j < count;
    xs[j] = used ? x[j] : 0.0;
    ys[j] = used ? y[j] : 0.0;
    zz[j] = used ? z[j] : 0.0;
    re[j] = used ? w[j] : 0.0;  // the weight rides on the azimuthal factor
    im[j] = 0.0;
  }
  for (int m = 0; m <= lmax; ++m) {
    const double scale = m == 0 ? 1.0 : M_SQRT2;
    double sum_c = 0.0, sum_s = 0.0;
    for (int j = 0; j < K; ++j) {
      c[j] = scale * re[j];
      s[j] = scale * im[j];
      sum_c += c[j];
      sum_s += s[j];
    }
    // Q^m_m is a constant; Q^{m+1}_m = sqrt(2m + 3) z Q^m_m.
    out[sh_index(m, m)] += f.diagonal[m] * sum_c;
    if (m > 0) out[sh_index(m, -m)] += f.diagonal[m] * sum_s;
    if (m < lmax) {
      const double first = std::sqrt(2.0 * m + 3.0) * f.diagonal[m];
      for (int j = 0; j < K; ++j) {
        q_prev[j] = f.diagonal[m];
        q[j] = first * zz[j];
      }
      for (int l = m + 1; l <= lmax; ++l) {
        if (l > m + 1) {
          const double a = f.a[l * n + m], b = f.b[l * n + m];
          for (int j = 0; j < K; ++j) {
            q_next[j] = a * (zz[j] * q[j] - b * q_prev[j]);
            q_prev[j] = q[j];
            q[j] = q_next[j];
          }
        }
        double dot_c = 0.0, dot_s = 0.0;
        for (int j = 0; j < K; ++j) {
          dot_c += c[j] * q[j];
          dot_s += s[j] * q[j];
        }
        out[sh_index(l, m)] += dot_c;
        if (m > 0) out[sh_index(l, -m)] += dot_s;
      }
    }
    for (int j = 0; j < K; ++j) {  // (x + i y)^(m + 1) = sin^(m+1)(theta) e^{i (m+1) phi}
      const double next_re = re[j] * xs[j] - im[j] * ys[j];
      im[j] = re[j] * ys[j] + im[j] * xs[j];
      re[j] = next_re;
    }
  }
}

std::shared_ptr<const SphericalHarmonicTransform> cached_transform(int bandwidth) {
  require_bandwidth(bandwidth);
  // Bytes of a transform's tables: Legendre B^2 (B + 1), cos and sin 4 B^2, weights 2 B.
  const auto bytes_of = [](long long B) { return 8 * (B * B * (B + 1) + 4 * B * B + 2 * B); };
  struct Entry {
    int bandwidth;
    std::shared_ptr<const SphericalHarmonicTransform> transform;
  };
  static std::mutex mutex;
  static std::list<Entry> cache;  // most recently used last
  std::lock_guard<std::mutex> lock(mutex);
  const auto hit = std::find_if(cache.begin(), cache.end(),
                                [bandwidth](const Entry& e) { return e.bandwidth == bandwidth; });
  if (hit != cache.end()) {
    cache.splice(cache.end(), cache, hit);
    return cache.back().transform;
  }
  cache.push_back({bandwidth, std::make_shared<const SphericalHarmonicTransform>(bandwidth)});
  const auto cached_bytes = [&] {
    long long total = 0;
    for (const Entry& entry : cache) total += bytes_of(entry.bandwidth);
    return total;
  };
  // Least recently used first; a caller still holding one keeps it alive until done.
  while (cache.size() > 1 && cached_bytes() > kCachedTransformBytes) cache.pop_front();
  return cache.back().transform;
}

}  // namespace detail

void require_coefficients(const ShCoefficients& coefficients, int bandwidth, const char* argument) {
  require_bandwidth(bandwidth);
  if (coefficients.size() != sh_count(bandwidth)) {
    fail(argument, ": expected bandwidth^2 = ", sh_count(bandwidth), " coefficients (bandwidth ",
         bandwidth, "), got ", coefficients.size());
  }
  if (!coefficients.allFinite()) fail(argument, " has non-finite entries");
}

void real_spherical_harmonics(const Eigen::Vector3d& unit_direction, int lmax,
                              Eigen::Ref<Eigen::VectorXd> out) {
  detail::require_degree(lmax, "lmax");
  const double norm = unit_direction.norm();
  if (!std::isfinite(norm) || norm == 0.0) fail("unit_direction must be finite and non-zero");
  if (out.size() != (lmax + 1) * (lmax + 1)) {
    fail("out: expected (lmax + 1)^2 = ", (lmax + 1) * (lmax + 1), " entries, got ", out.size());
  }
  const Eigen::Vector3d n = unit_direction / norm;
  detail::real_sh_unit(n.x(), n.y(), n.z(), lmax, out.data());
}

SphericalHarmonicTransform::SphericalHarmonicTransform(int bandwidth) : bandwidth_(bandwidth) {
  require_bandwidth(bandwidth);
  const int B = bandwidth, n = 2 * bandwidth;
  // Driscoll-Healy weights: exact for polynomials of degree < 2B in cos(theta).
  weights_.resize(n);
  for (int j = 0; j < n; ++j) {
    const double theta = grid_theta(j, B);
    double sum = 0.0;
    for (int k = 0; k < B; ++k) sum += std::sin((2 * k + 1) * theta) / (2 * k + 1);
    weights_[j] = (2.0 / B) * std::sin(theta) * sum * (M_PI / B);
  }
  cos_table_.resize(n, B);
  sin_table_.resize(n, B);
  for (int k = 0; k < n; ++k) {
    for (int m = 0; m < B; ++m) {
      const double phi = grid_phi((m * k) % n, B);  // reduced argument: exact tables
      cos_table_(k, m) = std::cos(phi);
      sin_table_(k, m) = std::sin(phi);
    }
  }
  legendre_.resize(B);
  std::vector<double> q(B);
  for (int m = 0; m < B; ++m) legendre_[m].resize(B - m, n);
  for (int j = 0; j < n; ++j) {
    const double theta = grid_theta(j, B);
    const double s = std::sin(theta);
    double sin_m = 1.0;
    for (int m = 0; m < B; ++m) {
      legendre_column(std::cos(theta), m, B - 1, q.data());
      const double scale = (m == 0 ? 1.0 : M_SQRT2) * sin_m;
      for (int l = m; l < B; ++l) legendre_[m](l - m, j) = scale * q[l - m];
      sin_m *= s;
    }
  }
}

ShCoefficients SphericalHarmonicTransform::forward(const SphereGrid& samples) const {
  const int B = bandwidth_, n = 2 * B;
  if (samples.rows() != n || samples.cols() != n) {
    fail("samples: expected a ", n, " x ", n, " grid for bandwidth ", B, ", got ", samples.rows(),
         " x ", samples.cols());
  }
  if (!samples.allFinite()) fail("samples has non-finite entries");
  const Eigen::Map<const Eigen::VectorXd> w(weights_.data(), n);
  const Eigen::MatrixXd cosines = w.asDiagonal() * (samples * cos_table_);
  const Eigen::MatrixXd sines = w.asDiagonal() * (samples * sin_table_);
  ShCoefficients out(sh_count(B));
  for (int m = 0; m < B; ++m) {
    const Eigen::VectorXd c = legendre_[m] * cosines.col(m);
    for (int l = m; l < B; ++l) out[sh_index(l, m)] = c[l - m];
    if (m == 0) continue;
    const Eigen::VectorXd s = legendre_[m] * sines.col(m);
    for (int l = m; l < B; ++l) out[sh_index(l, -m)] = s[l - m];
  }
  return out;
}

SphereGrid SphericalHarmonicTransform::inverse(const ShCoefficients& coefficients) const {
  const int B = bandwidth_, n = 2 * B;
  require_coefficients(coefficients, B, "coefficients");
  Eigen::MatrixXd cosines = Eigen::MatrixXd::Zero(n, B), sines = Eigen::MatrixXd::Zero(n, B);
  Eigen::VectorXd c(B), s(B);
  for (int m = 0; m < B; ++m) {
    for (int l = m; l < B; ++l) {
      c[l - m] = coefficients[sh_index(l, m)];
      s[l - m] = m == 0 ? 0.0 : coefficients[sh_index(l, -m)];
    }
    cosines.col(m).noalias() = legendre_[m].transpose() * c.head(B - m);
    if (m > 0) sines.col(m).noalias() = legendre_[m].transpose() * s.head(B - m);
  }
  SphereGrid out = cosines * cos_table_.transpose();
  out.noalias() += sines * sin_table_.transpose();
  return out;
}

ShCoefficients sh_coefficients(const SphereGrid& samples, int bandwidth) {
  return detail::cached_transform(bandwidth)->forward(samples);
}

SphereGrid sh_synthesis(const ShCoefficients& coefficients, int bandwidth) {
  return detail::cached_transform(bandwidth)->inverse(coefficients);
}

}  // namespace spectral_vs
