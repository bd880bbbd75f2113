#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "common/checks.hpp"
#include "rotation/correlation_detail.hpp"

#include <fftw3.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <complex>
#include <map>
#include <memory>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

using Complex = std::complex<double>;

// FFTW's planner (double library) is not thread-safe; execution of a plan on new arrays
// is. Plans are made once per grid size and kept for the life of the process.
std::mutex& fftw_double_planner_mutex() {
  static std::mutex mutex;
  return mutex;
}

// Memory of the workers' Wigner matrices together.
constexpr long long kWorkerBytes = 256LL << 20;

struct FftwFree {
  void operator()(void* p) const { fftw_free(p); }
};
template <typename T>
using FftwArray = std::unique_ptr<T[], FftwFree>;

template <typename T>
FftwArray<T> fftw_array(std::size_t count) {
  auto* p = static_cast<T*>(fftw_malloc(sizeof(T) * count));
  if (!p) fail("so3_search: cannot allocate ", sizeof(T) * count, " bytes");
  return FftwArray<T>(p);
}

// n x n complex-to-real 2D transform, half spectrum (n / 2 + 1) along the last axis.
fftw_plan inverse_plan(int n) {
  std::lock_guard<std::mutex> lock(fftw_double_planner_mutex());
  // Never destroyed: a static map would free its nodes at exit and leave the plans
  // unreachable (a leak report under LeakSanitizer), or be gone while a detached thread
  // still searches.
  static auto& plans = *new std::map<int, fftw_plan>;
  auto& plan = plans[n];
  if (!plan) {
    auto in = fftw_array<fftw_complex>(std::size_t(n) * (n / 2 + 1));
    auto out = fftw_array<double>(std::size_t(n) * n);
    plan = fftw_plan_dft_c2r_2d(n, n, in.get(), out.get(), FFTW_ESTIMATE);
    if (!plan) fail("so3_search: FFTW could not plan a ", n, " x ", n, " transform");
  }
  return plan;
}

// Per degree, the complex form of the coefficients in the (cos m phi, sin m phi) pairs:
// c_m = X^l_m + i X^l_{-m} (m > 0), c_0 = X^l_0. A rotation about z by angle a
// multiplies c_m by e^{i m a}, which turns alpha and gamma into Fourier variables.
std::vector<std::vector<Complex>> pair_form(const ShCoefficients& x, int bandwidth) {
  std::vector<std::vector<Complex>> out(bandwidth);
  for (int l = 0; l < bandwidth; ++l) {
    out[l].resize(l + 1);
    out[l][0] = x[sh_index(l, 0)];
    for (int m = 1; m <= l; ++m) out[l][m] = Complex(x[sh_index(l, m)], x[sh_index(l, -m)]);
  }
  return out;
}

// The grid of C: value[(j * n + i) * n + k] = C(alpha_i, beta_j, gamma_k).
struct EulerGrid {
  int bandwidth = 0, n = 0;
  FftwArray<double> value;
  double at(int j, int i, int k) const { return value[(std::size_t(j) * n + i) * n + k]; }
};

// With R = Rz(alpha) Ry(beta) Rz(gamma) and U a representation,
// C = (Z(-alpha) T)^T Y(beta) (Z(gamma) F), Y = U(Ry(beta)). Writing both z-rotated
// vectors in pair form gives C = sum_{mu, nu} K_{mu nu}(beta) e^{i mu alpha} e^{i nu gamma}.
// U(Ry) commutes with the reflection y -> -y, so it never mixes cosine and sine terms
// (Y(a, b) = 0 when a and b have opposite signs), which leaves two terms per (mu, nu):
//   K(+m, n) += conj(t_m) f_n (Y(m, n) + Y(-m, -n)) / 4,
//   K(-m, n) += t_m f_n (Y(m, n) - Y(-m, -n)) / 4          (m, n > 0),
// with the m = 0 or n = 0 rows and columns below. Only nu >= 0 is stored: C is real.
void fill_spectrum(const std::vector<std::vector<Complex>>& t,
                   const std::vector<std::vector<Complex>>& f, const WignerMatrices& Y, int n,
                   Complex* K) {
  const int half = n / 2 + 1;
  std::fill(K, K + std::size_t(n) * half, Complex(0.0, 0.0));
  auto entry = [&](int mu, int nu) -> Complex& { return K[std::size_t((mu + n) % n) * half + nu]; };
  for (int l = 0; l < int(t.size()); ++l) {
    const Eigen::MatrixXd& y = Y[l];
    const auto& tl = t[l];
    const auto& fl = f[l];
    entry(0, 0) += tl[0] * fl[0] * y(l, l);
    for (int q = 1; q <= l; ++q) {
      entry(0, q) += 0.5 * tl[0] * fl[q] * y(l, l + q);
      entry(q, 0) += 0.5 * std::conj(tl[q]) * fl[0] * y(l + q, l);
      entry(-q, 0) += 0.5 * tl[q] * fl[0] * y(l + q, l);
    }
    for (int m = 1; m <= l; ++m) {
      const Complex a = 0.25 * std::conj(tl[m]), b = 0.25 * tl[m];
      for (int q = 1; q <= l; ++q) {
        const double even = y(l + m, l + q), odd = y(l - m, l - q);
        entry(m, q) += a * fl[q] * (even + odd);
        entry(-m, q) += b * fl[q] * (even - odd);
      }
    }
  }
}

EulerGrid correlation_grid(const ShCoefficients& target, const ShCoefficients& model, int bandwidth,
                           int threads) {
  const int n = 2 * bandwidth;
  EulerGrid grid;
  grid.bandwidth = bandwidth;
  grid.n = n;
  grid.value = fftw_array<double>(std::size_t(n) * n * n);
  const fftw_plan plan = inverse_plan(n);
  const auto t = pair_form(target, bandwidth), f = pair_form(model, bandwidth);
  // Buffers are allocated here, so that nothing in a worker thread can throw.
  std::vector<FftwArray<fftw_complex>> spectra;
  std::vector<WignerMatrices> wigner(threads);
  for (int w = 0; w < threads; ++w)
    spectra.push_back(fftw_array<fftw_complex>(std::size_t(n) * (n / 2 + 1)));
  auto work = [&](int first) {
    for (int j = first; j < n; j += threads) {
      wigner_real_into(euler_zyz(0.0, grid_theta(j, bandwidth), 0.0), bandwidth - 1, wigner[first]);
      fill_spectrum(t, f, wigner[first], n, reinterpret_cast<Complex*>(spectra[first].get()));
      // Each beta plane is n * n doubles, a multiple of 32 bytes: same alignment as the plan's.
      fftw_execute_dft_c2r(plan, spectra[first].get(), grid.value.get() + std::size_t(j) * n * n);
    }
  };
  // A thread the system refuses (a thread or address-space limit) leaves its rows, and
  // those of the workers after it, to this thread: the grid is the same either way.
  std::vector<std::thread> pool;
  int spawned = 1;
  try {
    for (; spawned < threads; ++spawned) pool.emplace_back(work, spawned);
  } catch (const std::system_error&) {
  }
  work(0);
  for (int w = spawned; w < threads; ++w) work(w);
  for (auto& thread : pool) thread.join();
  return grid;
}

struct GridMaximum {
  double value;
  int j, i, k;
};

// True when node (j, i, k) beats its 26 neighbours (alpha and gamma periodic, beta not);
// ties go to the lower linear index, so a plateau yields one maximum.
bool is_local_maximum(const EulerGrid& grid, int j, int i, int k) {
  const int n = grid.n;
  const double v = grid.at(j, i, k);
  const std::size_t self = (std::size_t(j) * n + i) * n + k;
  for (int dj = -1; dj <= 1; ++dj) {
    const int jj = j + dj;
    if (jj < 0 || jj >= n) continue;
    for (int di = -1; di <= 1; ++di) {
      const int ii = (i + di + n) % n;
      for (int dk = -1; dk <= 1; ++dk) {
        const int kk = (k + dk + n) % n;
        const std::size_t other = (std::size_t(jj) * n + ii) * n + kk;
        const double w = grid.at(jj, ii, kk);
        if (other != self && (w > v || (w == v && other < self))) return false;
      }
    }
  }
  return true;
}

std::vector<GridMaximum> local_maxima(const EulerGrid& grid) {
  std::vector<GridMaximum> out;
  for (int j = 0; j < grid.n; ++j)
    for (int i = 0; i < grid.n; ++i)
      for (int k = 0; k < grid.n; ++k)
        if (is_local_maximum(grid, j, i, k)) out.push_back({grid.at(j, i, k), j, i, k});
  return out;
}

void check_params(const So3SearchParams& params) {
  if (params.candidates < 1) fail("params.candidates must be >= 1, got ", params.candidates);
  if (params.threads < 1 || params.threads > 256) {
    fail("params.threads must be in [1, 256], got ", params.threads);
  }
  if (!std::isfinite(params.separation_cells) || params.separation_cells < 0.0) {
    fail("params.separation_cells must be finite and >= 0, got ", params.separation_cells);
  }
}

void check_params(const RotationRefineParams& params) {
  if (!std::isfinite(params.gain) || params.gain <= 0.0)
    fail("params.gain must be finite and > 0, got ", params.gain);
  if (params.max_iterations < 0 || params.max_iterations > 10000)
    fail("params.max_iterations must be in [0, 10000], got ", params.max_iterations);
  if (!std::isfinite(params.gradient_tolerance) || params.gradient_tolerance <= 0.0) {
    fail("params.gradient_tolerance must be finite and > 0, got ", params.gradient_tolerance);
  }
  if (!std::isfinite(params.max_step) || params.max_step <= 0.0) {
    fail("params.max_step must be finite and > 0 (radians), got ", params.max_step);
  }
}

// The step of one iteration: Newton where the Hessian is negative definite (quadratic
// convergence near a maximum), else the paper's gradient step with the current gain.
Eigen::Vector3d ascent_step(const CorrelationValue& v, const RotationRefineParams& params,
                            double gain, bool& is_newton) {
  Eigen::Vector3d step = gain * v.gradient;
  is_newton = false;
  if (params.newton) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(v.hessian);
    const Eigen::Vector3d lambda = eigen.eigenvalues();
    if (lambda.maxCoeff() < 0.0) {
      const Eigen::Matrix3d V = eigen.eigenvectors();
      step = -V * (V.transpose() * v.gradient).cwiseQuotient(lambda);
      is_newton = true;
    }
  }
  const double norm = step.norm();
  if (norm > params.max_step) step *= params.max_step / norm;
  return step;
}

Eigen::Matrix3d orthonormalised(const Eigen::Matrix3d& R) {
  return Eigen::Quaterniond(R).normalized().toRotationMatrix();
}

}  // namespace

std::vector<RotationCandidate> so3_search(const ShCoefficients& target, const ShCoefficients& model,
                                          int bandwidth, const So3SearchParams& params) {
  check_params(params);
  ShCoefficients t, f;
  detail::prepare_correlation(target, model, bandwidth, params.normalised, t, f);
  // Each worker holds the Wigner matrices of every degree: 22 MB at B = 128, where 256
  // workers took 5.6 GB. They share kWorkerBytes; the grid does not depend on their number.
  const long long wigner_bytes = 8LL * bandwidth * (4LL * bandwidth * bandwidth - 1) / 3;
  const int by_memory = int(std::max(1LL, kWorkerBytes / wigner_bytes));
  const int threads = std::min({params.threads, 2 * bandwidth, by_memory});
  const EulerGrid grid = correlation_grid(t, f, bandwidth, threads);
  std::vector<GridMaximum> maxima = local_maxima(grid);
  std::sort(maxima.begin(), maxima.end(),
            [](const GridMaximum& a, const GridMaximum& b) { return a.value > b.value; });
  const double separation = params.separation_cells * M_PI / bandwidth;
  std::vector<RotationCandidate> out;
  for (const GridMaximum& m : maxima) {
    const Eigen::Matrix3d R =
        euler_zyz(grid_phi(m.i, bandwidth), grid_theta(m.j, bandwidth), grid_phi(m.k, bandwidth));
    const bool distinct = std::all_of(out.begin(), out.end(), [&](const RotationCandidate& c) {
      return rotation_distance(c.R, R) >= separation;
    });
    if (!distinct) continue;
    out.push_back({R, m.value});
    if (int(out.size()) == params.candidates) break;
  }
  return out;
}

RotationRefineResult refine_rotation(So3Correlation& correlation, const Eigen::Matrix3d& R0,
                                     const RotationRefineParams& params) {
  require_rotation(R0, "R0");
  check_params(params);
  RotationRefineResult result;
  result.R = orthonormalised(R0);
  CorrelationValue current = correlation.evaluate(result.R, params.newton);
  // A gain near 2 / (largest eigenvalue of -H) still raises C at every step while the
  // stiffest component flips sign and decays ever more slowly: halve the gain when the
  // gradient reverses (or a step lowers C), which the paper's fixed gain cannot do.
  double gain = params.gain;
  // Relative to |C|'s bound: raw sums (normalised = false) of 1e3-point EGIs never reached
  // an absolute 1e-6 and ran every iteration (24 s at B = 128).
  const double tolerance = params.gradient_tolerance * correlation.scale();
  while (result.iterations < params.max_iterations && current.gradient.norm() >= tolerance) {
    bool is_newton = false;
    Eigen::Vector3d step = ascent_step(current, params, gain, is_newton);
    bool improved = false;
    // Halving 40 times reaches 1e-13 rad: below that no step changes C in double precision.
    for (int halving = 0; halving < 40 && !improved; ++halving) {
      const Eigen::Matrix3d R = orthonormalised(result.R * exp_so3(step));
      const CorrelationValue next = correlation.evaluate(R, params.newton);
      if (next.value >= current.value) {
        if (!is_newton && next.gradient.dot(current.gradient) < 0.0) gain *= 0.5;
        result.R = R;
        current = next;
        improved = true;
      } else {
        step *= 0.5;
        if (!is_newton) gain *= 0.5;
      }
    }
    ++result.iterations;
    if (!improved) break;
  }
  result.correlation = current.value;
  result.converged = current.gradient.norm() < tolerance;
  return result;
}

}  // namespace spectral_vs
