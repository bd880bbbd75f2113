#include <spectral_vs/translation/phase_correlation.hpp>

#include "common/checks.hpp"

#include <fftw3.h>

#include <Eigen/Dense>
#include <algorithm>
#include <climits>
#include <cmath>
#include <complex>
#include <mutex>

namespace spectral_vs {

using detail::fail;

namespace {

// FFTW's planner is not thread-safe; execution of distinct plans is.
std::mutex& planner_mutex() {
  static std::mutex mutex;
  return mutex;
}

void init_fftw_threads() {
  static std::once_flag once;
  std::call_once(once, [] { fftwf_init_threads(); });
}

template <typename T>
struct FftwDeleter {
  void operator()(T* p) const { fftwf_free(p); }
};
template <typename T>
using FftwBuffer = std::unique_ptr<T[], FftwDeleter<T>>;

template <typename T>
FftwBuffer<T> allocate(std::size_t count) {
  auto* p = static_cast<T*>(fftwf_malloc(sizeof(T) * count));
  if (!p) fail("grid: cannot allocate ", sizeof(T) * count, " bytes for the FFT");
  return FftwBuffer<T>(p);
}

using Complex = std::complex<float>;

// For each circular index along one axis, the signed shift it stands for, or INT_MIN
// when no feasible shift maps there. Feasible shifts are those for which the occupied
// boxes of the two grids overlap: [target_min - moving_max, target_max - moving_min].
std::vector<int> unfolded_shifts(int n, int lo, int hi) {
  std::vector<int> shifts(static_cast<std::size_t>(n), INT_MIN);
  for (int k = 0; k < n; ++k) {
    const int positive = k;
    const int negative = k - n;
    const bool positive_ok = positive >= lo && positive <= hi;
    const bool negative_ok = negative >= lo && negative <= hi;
    if (positive_ok && negative_ok) {
      shifts[k] = (k <= n / 2) ? positive : negative;  // ambiguous: the shorter shift
    } else if (positive_ok) {
      shifts[k] = positive;
    } else if (negative_ok) {
      shifts[k] = negative;
    }
  }
  return shifts;
}

// Signed frequency, cycles per voxel, of index k of an n-point transform.
double frequency(int k, int n) { return (k <= n / 2 ? k : k - n) / static_cast<double>(n); }

// atan2 to within 2e-4 rad (a minimax polynomial on [0, 1] and octant symmetry): the
// phases it reads are far noisier than that, and std::atan2 was a third of the fit.
float fast_atan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float a = std::min(ax, ay) / std::max(std::max(ax, ay), 1e-30f);
  const float s = a * a;
  float r = ((-0.0464964749f * s + 0.15931422f) * s - 0.327622764f) * s * a + a;
  if (ay > ax) r = 1.57079637f - r;
  if (x < 0.0f) r = 3.14159274f - r;
  return y < 0.0f ? -r : r;
}

// a wrapped to [-pi, pi]; std::remainder is exact but several times slower.
double wrap_angle(double a) { return a - 2.0 * M_PI * std::nearbyint(a / (2.0 * M_PI)); }

}  // namespace

struct PhaseCorrelation::Impl {
  GridSpec spec;
  PhaseCorrelationParams params;
  std::size_t real_count = 0;
  std::size_t complex_count = 0;
  int half_z = 0;  // nz / 2 + 1
  FftwBuffer<float> real;
  FftwBuffer<Complex> moving_spectrum;
  FftwBuffer<Complex> cross_power;
  FftwBuffer<Complex> target_spectrum;
  fftwf_plan forward = nullptr;
  fftwf_plan inverse = nullptr;
  bool has_target = false;
  Eigen::Vector3i target_min, target_max;
  double phase_bins = 0.0;  // bins of the full spectrum that carry phase in cross_power

  ~Impl() {
    std::lock_guard<std::mutex> lock(planner_mutex());
    if (forward) fftwf_destroy_plan(forward);
    if (inverse) fftwf_destroy_plan(inverse);
  }

  void make_plans() {
    half_z = spec.dims.z() / 2 + 1;
    real_count = spec.voxel_count();
    complex_count = static_cast<std::size_t>(spec.dims.x()) * spec.dims.y() * half_z;
    real = allocate<float>(real_count);
    moving_spectrum = allocate<Complex>(complex_count);
    cross_power = allocate<Complex>(complex_count);
    target_spectrum = allocate<Complex>(complex_count);
    init_fftw_threads();
    std::lock_guard<std::mutex> lock(planner_mutex());
    fftwf_plan_with_nthreads(params.threads);
    // FFTW_ESTIMATE: the plan, and so every result bit, is the same on every run.
    forward = fftwf_plan_dft_r2c_3d(spec.dims.x(), spec.dims.y(), spec.dims.z(), real.get(),
                                    reinterpret_cast<fftwf_complex*>(moving_spectrum.get()),
                                    FFTW_ESTIMATE);
    inverse = fftwf_plan_dft_c2r_3d(spec.dims.x(), spec.dims.y(), spec.dims.z(),
                                    reinterpret_cast<fftwf_complex*>(cross_power.get()),
                                    real.get(), FFTW_ESTIMATE);
    if (!forward || !inverse) fail("grid: FFTW could not plan a ", spec.dims.transpose(), " transform");
  }

  void transform(const VoxelGrid& grid, Complex* out) {
    std::copy(grid.values.begin(), grid.values.end(), real.get());
    fftwf_execute_dft_r2c(forward, real.get(), reinterpret_cast<fftwf_complex*>(out));
  }

  // Normalised cross-power spectrum of eq. (7), oriented so that its inverse peaks at
  // the shift of the moving grid onto the target. Voxel values are non-negative, so
  // no bin is larger than the DC bin: it sets the floor below which a bin carries no
  // phase (no energy in either grid) and is left out. Written on plain floats, without
  // branches, so that the compiler vectorises the loop.
  void form_cross_power() {
    const float floor = std::abs(target_spectrum[0] * moving_spectrum[0]) * 1e-6f;
    const float floor_power = floor * floor;
    const float* t = reinterpret_cast<const float*>(target_spectrum.get());
    const float* m = reinterpret_cast<const float*>(moving_spectrum.get());
    float* out = reinterpret_cast<float*>(cross_power.get());
    std::size_t kept = 0;
    for (std::size_t i = 0; i < complex_count; ++i) {
      const float re = t[2 * i] * m[2 * i] + t[2 * i + 1] * m[2 * i + 1];
      const float im = t[2 * i + 1] * m[2 * i] - t[2 * i] * m[2 * i + 1];
      const float power = re * re + im * im;
      const bool keep = power > floor_power;
      const float scale = keep ? 1.0f / std::sqrt(power) : 0.0f;
      out[2 * i] = re * scale;
      out[2 * i + 1] = im * scale;
      kept += keep;
    }
    // An inner bin of the half spectrum also stands for its conjugate twin; the edge
    // bins (k = 0 and, for even nz, k = nz/2) stand for themselves.
    std::size_t kept_edge = 0;
    const int nz = spec.dims.z();
    for (std::size_t row = 0; row < complex_count; row += half_z) {
      kept_edge += cross_power[row] != Complex(0.0f, 0.0f);
      if (nz % 2 == 0) kept_edge += cross_power[row + half_z - 1] != Complex(0.0f, 0.0f);
    }
    phase_bins = static_cast<double>(2 * kept - kept_edge);
  }

  Eigen::Vector3i find_peak(const VoxelGrid& moving, float& height) const {
    std::vector<int> shifts[3];
    for (int axis = 0; axis < 3; ++axis) {
      shifts[axis] = unfolded_shifts(spec.dims[axis], target_min[axis] - moving.occupied_max[axis],
                                     target_max[axis] - moving.occupied_min[axis]);
    }
    const int ny = spec.dims.y(), nz = spec.dims.z();
    height = -INFINITY;
    Eigen::Vector3i best = Eigen::Vector3i::Zero();
    for (int i = 0; i < spec.dims.x(); ++i) {
      if (shifts[0][i] == INT_MIN) continue;
      for (int j = 0; j < ny; ++j) {
        if (shifts[1][j] == INT_MIN) continue;
        const float* row = real.get() + (static_cast<std::size_t>(i) * ny + j) * nz;
        for (int k = 0; k < nz; ++k) {
          if (row[k] > height && shifts[2][k] != INT_MIN) {
            height = row[k];
            best = {shifts[0][i], shifts[1][j], shifts[2][k]};
          }
        }
      }
    }
    return best;
  }

  // The bins of the half spectrum with |f| < band on every axis, found once per grid.
  struct LowBin {
    std::size_t index;
    Eigen::Vector3d f;  // cycles per voxel
    double weight;      // 2 for an inner bin, which also stands for its conjugate twin
  };
  std::vector<LowBin> low_bins;
  mutable std::vector<double> low_angles;  // per-call scratch of fit_phase_plane
  mutable std::vector<char> low_valid;

  void find_low_bins() {
    const double band = params.subvoxel_band;
    const int nx = spec.dims.x(), ny = spec.dims.y(), nz = spec.dims.z();
    for (int i = 0; i < nx; ++i) {
      const double fx = frequency(i, nx);
      if (std::abs(fx) >= band) continue;
      for (int j = 0; j < ny; ++j) {
        const double fy = frequency(j, ny);
        if (std::abs(fy) >= band) continue;
        for (int k = 0; k < half_z && k < band * nz; ++k) {
          if (i == 0 && j == 0 && k == 0) continue;  // DC carries no phase
          const std::size_t index = (static_cast<std::size_t>(i) * ny + j) * half_z + k;
          low_bins.push_back({index, Eigen::Vector3d(fx, fy, k / double(nz)),
                              (k == 0 || 2 * k == nz) ? 1.0 : 2.0});
        }
      }
    }
  }

  // Least-squares fit of the phase plane angle(X(f)) = -2 pi f . d over the low bins,
  // after removing the integer peak: the sub-voxel residual d, in voxels. Two passes,
  // the second on the phases left by the first, so that a residual near half a voxel
  // does not wrap.
  Eigen::Vector3d fit_phase_plane(const Eigen::Vector3i& peak) const {
    std::vector<double>& angles = low_angles;
    std::vector<char>& valid = low_valid;
    angles.resize(low_bins.size());
    valid.resize(low_bins.size());
    const Eigen::Vector3d p = peak.cast<double>();
    for (std::size_t b = 0; b < low_bins.size(); ++b) {
      const std::size_t index = low_bins[b].index;
      const Complex product = target_spectrum[index] * std::conj(moving_spectrum[index]);
      valid[b] = std::norm(product) > 0.0f;
      angles[b] = wrap_angle(fast_atan2(product.imag(), product.real()) + 2.0 * M_PI * low_bins[b].f.dot(p));
    }
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    for (int pass = 0; pass < 2; ++pass) {
      Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
      Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
      for (std::size_t b = 0; b < low_bins.size(); ++b) {
        if (!valid[b]) continue;
        const LowBin& bin = low_bins[b];
        const double residual = wrap_angle(angles[b] + 2.0 * M_PI * bin.f.dot(d));
        normal.noalias() += bin.weight * bin.f * bin.f.transpose();
        rhs.noalias() += bin.weight * residual * bin.f;
      }
      const Eigen::Vector3d step = normal.ldlt().solve(rhs) / (-2.0 * M_PI);
      if (!step.allFinite()) return Eigen::Vector3d::Zero();
      d += step;
    }
    // A fit that leaves the peak's voxel disagrees with the peak: trust the peak.
    for (int axis = 0; axis < 3; ++axis) {
      if (!(std::abs(d[axis]) <= 1.0)) d[axis] = 0.0;
    }
    return d;
  }
};

PhaseCorrelation::PhaseCorrelation(const GridSpec& spec, const PhaseCorrelationParams& params)
    : impl_(std::make_unique<Impl>()) {
  detail::require_positive_finite(spec.resolution, "spec.resolution");
  if ((spec.dims.array() < 1).any()) fail("spec.dims must be >= 1, got ", spec.dims.transpose());
  if (!(params.subvoxel_band > 0.0 && params.subvoxel_band <= 0.5)) {
    fail("subvoxel_band must be in (0, 0.5] cycles per voxel, got ", params.subvoxel_band);
  }
  if (params.threads < 1) fail("threads must be >= 1, got ", params.threads);
  impl_->spec = spec;
  impl_->params = params;
  impl_->make_plans();
  if (params.subvoxel) impl_->find_low_bins();
}

PhaseCorrelation::~PhaseCorrelation() = default;
PhaseCorrelation::PhaseCorrelation(PhaseCorrelation&&) noexcept = default;
PhaseCorrelation& PhaseCorrelation::operator=(PhaseCorrelation&&) noexcept = default;

const GridSpec& PhaseCorrelation::spec() const { return impl_->spec; }

bool PhaseCorrelation::has_target() const { return impl_->has_target; }

namespace {

void require_same_spec(const GridSpec& expected, const VoxelGrid& grid, const char* argument) {
  if (grid.spec.dims != expected.dims || grid.values.size() != expected.voxel_count()) {
    fail(argument, ": grid of ", grid.spec.dims.transpose(), " voxels, expected ",
         expected.dims.transpose());
  }
  if (grid.empty()) fail(argument, " is empty: no occupied voxel");
}

}  // namespace

void PhaseCorrelation::set_target(const VoxelGrid& target) {
  require_same_spec(impl_->spec, target, "target");
  impl_->transform(target, impl_->target_spectrum.get());
  impl_->target_min = target.occupied_min;
  impl_->target_max = target.occupied_max;
  impl_->has_target = true;
}

TranslationEstimate PhaseCorrelation::estimate(const VoxelGrid& moving) {
  if (!impl_->has_target) fail("PhaseCorrelation: set_target() must be called before estimate()");
  require_same_spec(impl_->spec, moving, "moving");
  Impl& im = *impl_;
  im.transform(moving, im.moving_spectrum.get());
  im.form_cross_power();
  fftwf_execute_dft_c2r(im.inverse, reinterpret_cast<fftwf_complex*>(im.cross_power.get()),
                        im.real.get());

  TranslationEstimate result;
  float height = 0.0f;
  result.peak_voxels = im.find_peak(moving, height);
  result.peak = im.phase_bins > 0.0 ? std::clamp(double(height) / im.phase_bins, 0.0, 1.0) : 0.0;
  result.shift_voxels = result.peak_voxels.cast<double>();
  if (im.params.subvoxel) result.shift_voxels += im.fit_phase_plane(result.peak_voxels);
  result.shift = result.shift_voxels * im.spec.resolution;
  return result;
}

TranslationEstimate phase_correlation(const VoxelGrid& moving, const VoxelGrid& target,
                                      const PhaseCorrelationParams& params) {
  if (moving.spec.dims != target.spec.dims) {
    fail("target: grid of ", target.spec.dims.transpose(), " voxels, expected the moving grid's ",
         moving.spec.dims.transpose());
  }
  PhaseCorrelation correlation(moving.spec, params);
  correlation.set_target(target);
  return correlation.estimate(moving);
}

double grid_energy(const VoxelGrid& grid) {
  double energy = 0.0;
  for (const float v : grid.values) energy += double(v) * v;
  return energy;
}

// 0.5 * sum (t - m)^2 = 0.5 * (sum t^2 + sum m^2 - 2 sum t m), where only voxels of the
// moving grid that land inside the grid contribute the last two terms.
double translation_cost(const VoxelGrid& moving, const VoxelGrid& target,
                        const Eigen::Vector3i& shift, double target_energy) {
  if (moving.spec.dims != target.spec.dims) fail("target: grid dims differ from moving's");
  double energy = 0.0, cross = 0.0;
  if (!moving.empty()) {
    for (int i = moving.occupied_min.x(); i <= moving.occupied_max.x(); ++i)
      for (int j = moving.occupied_min.y(); j <= moving.occupied_max.y(); ++j)
        for (int k = moving.occupied_min.z(); k <= moving.occupied_max.z(); ++k) {
          const Eigen::Vector3i destination = Eigen::Vector3i(i, j, k) + shift;
          if (!target.spec.contains(destination)) continue;
          const double m = moving.at(i, j, k);
          energy += m * m;
          cross += m * target.at(destination.x(), destination.y(), destination.z());
        }
  }
  return 0.5 * (target_energy + energy - 2.0 * cross);
}

double translation_cost(const VoxelGrid& moving, const VoxelGrid& target,
                        const Eigen::Vector3i& shift) {
  return translation_cost(moving, target, shift, grid_energy(target));
}

}  // namespace spectral_vs
