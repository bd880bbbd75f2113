#include <spectral_vs/translation/phase_correlation.hpp>

#include "common/checks.hpp"

#include <fftw3.h>

#include <Eigen/Dense>
#include <algorithm>
#include <climits>
#include <cmath>
#include <complex>
#include <limits>
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
  // Written as arithmetic on 0/1 selects, with no conditional operation, so that a loop
  // over it vectorises (GCC will not speculate a conditional float subtraction).
  const float ax = std::abs(x), ay = std::abs(y);
  const float swap = ay > ax ? 1.0f : 0.0f;
  const float lo = ax < ay ? ax : ay;
  const float hi = ax < ay ? ay : ax;
  const float a = lo / (hi > 1e-30f ? hi : 1e-30f);
  const float s = a * a;
  const float r = ((-0.0464964749f * s + 0.15931422f) * s - 0.327622764f) * s * a + a;
  const float octant = r + swap * (1.57079637f - 2.0f * r);
  const float half = octant + (x < 0.0f ? 1.0f : 0.0f) * (3.14159274f - 2.0f * octant);
  return (y < 0.0f ? -1.0f : 1.0f) * half;
}

constexpr float kTwoPi = 6.28318531f;

// a wrapped to [-pi, pi] by rounding through an integer conversion, which (unlike
// std::nearbyint on baseline x86-64) is a single instruction; |a| is far below 2^31.
float wrap_angle(float a) {
  const float turns = a * (1.0f / kTwoPi);
  return a - kTwoPi * static_cast<float>(static_cast<int>(turns + (turns >= 0.0f ? 0.5f : -0.5f)));
}

}  // namespace

struct PhaseCorrelation::Impl {
  GridSpec spec;
  PhaseCorrelationParams params;
  std::size_t real_count = 0;
  std::size_t complex_count = 0;
  int half_z = 0;            // nz / 2 + 1
  FftwBuffer<float> input;   // forward transform's input; zero outside input_box
  FftwBuffer<float> output;  // inverse transform's output: the correlation
  // The moving grid's spectrum, overwritten in place by the cross-power spectrum (one
  // buffer less to stream through memory on each estimate).
  FftwBuffer<Complex> spectrum;
  FftwBuffer<Complex> target_spectrum;
  // The forward transform in three passes, pruned to the moving grid's occupied box:
  // along z for the x-slabs of the box, along y in those slabs, along x for all. Slabs
  // outside the box are zero in `partial` and skipped by the first two passes.
  FftwBuffer<Complex> partial;
  fftwf_plan z_slab = nullptr, y_slab = nullptr, x_all = nullptr;
  int partial_x0 = 0, partial_x1 = -1;  // slabs of `partial` that may be non-zero
  // The inverse in three passes, pruned to the feasible shifts: along x for all, in
  // place; along y in the x-slabs of feasible shifts; along z (complex to real) in the
  // rows of feasible x and y shifts. The other voxels of `output` are never read.
  fftwf_plan x_inverse = nullptr, y_inverse = nullptr, z_inverse = nullptr;
  bool has_target = false;
  Eigen::Vector3i target_min, target_max;
  // The box of `input` that may hold non-zero voxels: only it is cleared and rewritten,
  // so loading a small moving grid into a large scene grid costs its box, not the grid.
  Eigen::Vector3i input_min = Eigen::Vector3i::Zero(), input_max = Eigen::Vector3i::Constant(-1);
  double phase_bins = 0.0;  // bins of the full spectrum that carry phase in the cross power

  ~Impl() {
    std::lock_guard<std::mutex> lock(planner_mutex());
    for (fftwf_plan plan : {z_slab, y_slab, x_all, x_inverse, y_inverse, z_inverse}) {
      if (plan) fftwf_destroy_plan(plan);
    }
  }

  void make_plans() {
    half_z = spec.dims.z() / 2 + 1;
    real_count = spec.voxel_count();
    complex_count = static_cast<std::size_t>(spec.dims.x()) * spec.dims.y() * half_z;
    input = allocate<float>(real_count);
    output = allocate<float>(real_count);
    std::fill(input.get(), input.get() + real_count, 0.0f);
    spectrum = allocate<Complex>(complex_count);
    target_spectrum = allocate<Complex>(complex_count);
    partial = allocate<Complex>(complex_count);
    std::fill(partial.get(), partial.get() + complex_count, Complex(0.0f, 0.0f));
    init_fftw_threads();
    std::lock_guard<std::mutex> lock(planner_mutex());
    // FFTW_ESTIMATE: the plans, and so every result bit, are the same on every run. The
    // slab plans run at other offsets than planned: FFTW_UNALIGNED allows that.
    const int nx = spec.dims.x(), ny = spec.dims.y(), nz = spec.dims.z();
    auto* part = reinterpret_cast<fftwf_complex*>(partial.get());
    fftwf_plan_with_nthreads(1);
    const fftwf_iodim along_z{nz, 1, 1}, rows{ny, nz, half_z};
    z_slab = fftwf_plan_guru_dft_r2c(1, &along_z, 1, &rows, input.get(), part,
                                     FFTW_ESTIMATE | FFTW_UNALIGNED);
    const fftwf_iodim along_y{ny, half_z, half_z}, columns{half_z, 1, 1};
    y_slab = fftwf_plan_guru_dft(1, &along_y, 1, &columns, part, part, FFTW_FORWARD,
                                 FFTW_ESTIMATE | FFTW_UNALIGNED);
    fftwf_plan_with_nthreads(params.threads);
    const fftwf_iodim along_x{nx, ny * half_z, ny * half_z}, lines{ny * half_z, 1, 1};
    x_all = fftwf_plan_guru_dft(1, &along_x, 1, &lines, part,
                                reinterpret_cast<fftwf_complex*>(spectrum.get()), FFTW_FORWARD,
                                FFTW_ESTIMATE);
    auto* spec_data = reinterpret_cast<fftwf_complex*>(spectrum.get());
    x_inverse = fftwf_plan_guru_dft(1, &along_x, 1, &lines, spec_data, spec_data, FFTW_BACKWARD,
                                    FFTW_ESTIMATE);
    fftwf_plan_with_nthreads(1);
    y_inverse = fftwf_plan_guru_dft(1, &along_y, 1, &columns, spec_data, spec_data, FFTW_BACKWARD,
                                    FFTW_ESTIMATE | FFTW_UNALIGNED);
    z_inverse = fftwf_plan_dft_c2r_1d(nz, spec_data, output.get(), FFTW_ESTIMATE | FFTW_UNALIGNED);
    if (!z_slab || !y_slab || !x_all || !x_inverse || !y_inverse || !z_inverse) {
      fail("grid: FFTW could not plan a ", spec.dims.transpose(), " transform");
    }
  }

  // Calls f(offset, length) for each z-run of the box [lo, hi] in the grid's linear order.
  template <typename F>
  void for_each_row(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi, F f) const {
    if ((lo.array() > hi.array()).any()) return;
    const std::size_t ny = spec.dims.y(), nz = spec.dims.z();
    for (int i = lo.x(); i <= hi.x(); ++i)
      for (int j = lo.y(); j <= hi.y(); ++j)
        f((i * ny + j) * nz + lo.z(), std::size_t(hi.z() - lo.z() + 1));
  }

  // Copies the occupied box of `grid` into `input` after clearing the previous box:
  // a VoxelGrid is zero outside its occupied box.
  void load_input(const VoxelGrid& grid) {
    float* in = input.get();
    for_each_row(input_min, input_max,
                 [&](std::size_t at, std::size_t n) { std::fill_n(in + at, n, 0.0f); });
    const float* values = grid.values.data();
    for_each_row(grid.occupied_min, grid.occupied_max,
                 [&](std::size_t at, std::size_t n) { std::copy_n(values + at, n, in + at); });
    input_min = grid.occupied_min;
    input_max = grid.occupied_max;
  }

  void transform(const VoxelGrid& grid, Complex* out) {
    load_input(grid);
    const std::size_t slab_in = std::size_t(spec.dims.y()) * spec.dims.z();
    const std::size_t slab_out = std::size_t(spec.dims.y()) * half_z;
    const int x0 = grid.occupied_min.x(), x1 = grid.occupied_max.x();
    for (int x = partial_x0; x <= partial_x1; ++x) {
      if (x < x0 || x > x1)
        std::fill_n(partial.get() + x * slab_out, slab_out, Complex(0.0f, 0.0f));
    }
    for (int x = x0; x <= x1; ++x) {
      auto* slab = reinterpret_cast<fftwf_complex*>(partial.get() + x * slab_out);
      fftwf_execute_dft_r2c(z_slab, input.get() + x * slab_in, slab);
      fftwf_execute_dft(y_slab, slab, slab);
    }
    partial_x0 = x0;
    partial_x1 = x1;
    fftwf_execute_dft(x_all, reinterpret_cast<fftwf_complex*>(partial.get()),
                      reinterpret_cast<fftwf_complex*>(out));
  }

  // Normalised cross-power spectrum of eq. (7), oriented so that its inverse peaks at
  // the shift of the moving grid onto the target. Voxel values are non-negative, so
  // no bin is larger than the DC bin: it sets the floor below which a bin carries no
  // phase (no energy in either grid) and is left out. Written on plain floats, without
  // branches, so that the compiler vectorises the loop.
  void form_cross_power() {
    const float floor = std::abs(target_spectrum[0] * spectrum[0]) * 1e-6f;
    const float floor_power = floor * floor;
    const float* t = reinterpret_cast<const float*>(target_spectrum.get());
    float* m = reinterpret_cast<float*>(spectrum.get());
    float* out = m;
    // The scale is computed for every bin (clamped away from 0) and then masked: a
    // division under a condition would stop the vectoriser.
    const float smallest = std::max(floor_power, std::numeric_limits<float>::min());
    int kept = 0;
    for (std::size_t i = 0; i < complex_count; ++i) {
      const float re = t[2 * i] * m[2 * i] + t[2 * i + 1] * m[2 * i + 1];
      const float im = t[2 * i + 1] * m[2 * i] - t[2 * i] * m[2 * i + 1];
      const float power = re * re + im * im;
      const int keep = power > floor_power;
      const float scale = (1.0f / std::sqrt(std::max(power, smallest))) * static_cast<float>(keep);
      out[2 * i] = re * scale;
      out[2 * i + 1] = im * scale;
      kept += keep;
    }
    // An inner bin of the half spectrum also stands for its conjugate twin; the edge
    // bins (k = 0 and, for even nz, k = nz/2) stand for themselves.
    std::size_t kept_edge = 0;
    const int nz = spec.dims.z();
    for (std::size_t row = 0; row < complex_count; row += half_z) {
      kept_edge += spectrum[row] != Complex(0.0f, 0.0f);
      if (nz % 2 == 0) kept_edge += spectrum[row + half_z - 1] != Complex(0.0f, 0.0f);
    }
    phase_bins = 2.0 * double(kept) - double(kept_edge);
  }

  // Per axis, the shift each circular index stands for (INT_MIN where infeasible).
  struct FeasibleShifts {
    std::vector<int> along[3];
  };

  FeasibleShifts feasible_shifts(const VoxelGrid& moving, const Eigen::Vector3i& max_shift) const {
    FeasibleShifts feasible;
    for (int axis = 0; axis < 3; ++axis) {
      feasible.along[axis] = unfolded_shifts(
          spec.dims[axis], std::max(target_min[axis] - moving.occupied_max[axis], -max_shift[axis]),
          std::min(target_max[axis] - moving.occupied_min[axis], max_shift[axis]));
    }
    return feasible;
  }

  // The correlation (the inverse transform of the cross power in `spectrum`, which it
  // overwrites) at the feasible shifts only: a small search range costs its share of the
  // y and z passes.
  void inverse_transform(const FeasibleShifts& feasible) {
    const int ny = spec.dims.y(), nz = spec.dims.z();
    auto* data = reinterpret_cast<fftwf_complex*>(spectrum.get());
    fftwf_execute_dft(x_inverse, data, data);
    const std::size_t slab = std::size_t(ny) * half_z;
    for (int i = 0; i < spec.dims.x(); ++i) {
      if (feasible.along[0][i] == INT_MIN) continue;
      fftwf_execute_dft(y_inverse, data + i * slab, data + i * slab);
      for (int j = 0; j < ny; ++j) {
        if (feasible.along[1][j] == INT_MIN) continue;
        const std::size_t row = std::size_t(i) * ny + j;
        fftwf_execute_dft_c2r(z_inverse, data + row * half_z, output.get() + row * nz);
      }
    }
  }

  // The largest correlation over feasible shifts. Along z the feasible indices form at
  // most two runs; each run's maximum is a vectorised reduction, and the index is
  // searched only in a run that beats the best so far.
  Eigen::Vector3i find_peak(const FeasibleShifts& feasible, float& height) const {
    const std::vector<int>* shifts = feasible.along;
    const std::vector<std::pair<int, int>> runs = feasible_runs(shifts[2]);
    const int ny = spec.dims.y(), nz = spec.dims.z();
    height = -INFINITY;
    Eigen::Vector3i best = Eigen::Vector3i::Zero();
    for (int i = 0; i < spec.dims.x(); ++i) {
      if (shifts[0][i] == INT_MIN) continue;
      for (int j = 0; j < ny; ++j) {
        if (shifts[1][j] == INT_MIN) continue;
        const float* row = output.get() + (static_cast<std::size_t>(i) * ny + j) * nz;
        for (const auto& [begin, end] : runs) {
          const float run_max =
              Eigen::Map<const Eigen::ArrayXf>(row + begin, end - begin).maxCoeff();
          if (!(run_max > height)) continue;
          const int k = static_cast<int>(std::find(row + begin, row + end, run_max) - row);
          height = run_max;
          best = {shifts[0][i], shifts[1][j], shifts[2][k]};
        }
      }
    }
    return best;
  }

  // The maximal runs [begin, end) of feasible indices.
  static std::vector<std::pair<int, int>> feasible_runs(const std::vector<int>& shifts) {
    std::vector<std::pair<int, int>> runs;
    const int n = static_cast<int>(shifts.size());
    for (int k = 0; k < n;) {
      if (shifts[k] == INT_MIN) {
        ++k;
        continue;
      }
      const int begin = k;
      while (k < n && shifts[k] != INT_MIN) ++k;
      runs.emplace_back(begin, k);
    }
    return runs;
  }

  // The bins of the half spectrum with |f| < band on every axis, found once per grid,
  // as separate arrays so that the fit's passes are plain loops over floats.
  struct LowBins {
    std::vector<std::size_t> index;
    std::vector<float> fx, fy, fz;  // frequency, cycles per voxel
    std::vector<float> weight;      // 2 for an inner bin, which also stands for its twin
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();  // sum of weight f f^T over all bins
    std::size_t size() const { return index.size(); }
  };
  LowBins low;
  // Per-call scratch of the fit: the products' phases, real parts and weights, and the
  // normal matrix over the bins that carry phase.
  std::vector<float> low_angles, low_reals, low_weights;
  Eigen::Matrix3d low_normal;

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
          const Eigen::Vector3d f(fx, fy, k / double(nz));
          const double weight = (k == 0 || 2 * k == nz) ? 1.0 : 2.0;
          low.index.push_back((static_cast<std::size_t>(i) * ny + j) * half_z + k);
          low.fx.push_back(float(f.x()));
          low.fy.push_back(float(f.y()));
          low.fz.push_back(float(f.z()));
          low.weight.push_back(float(weight));
          low.normal += weight * f * f.transpose();
        }
      }
    }
  }

  // Reads the cross products target * conj(moving) at the low bins, before the
  // spectrum is overwritten by the cross power: the fit's input.
  void gather_low_bins() {
    const std::size_t n = low.size();
    low_angles.resize(n);
    low_weights.resize(n);
    low_reals.resize(n);
    low_normal = low.normal;
    for (std::size_t b = 0; b < n; ++b) {
      const Complex product = target_spectrum[low.index[b]] * std::conj(spectrum[low.index[b]]);
      low_angles[b] = product.imag();
      low_reals[b] = product.real();
      low_weights[b] = low.weight[b];
      if (std::norm(product) > 0.0f) continue;
      low_weights[b] = 0.0f;  // no energy, no phase
      const Eigen::Vector3d f(low.fx[b], low.fy[b], low.fz[b]);
      low_normal -= double(low.weight[b]) * f * f.transpose();
    }
  }

  // Least-squares fit of the phase plane angle(X(f)) = -2 pi f . d over the low bins,
  // after removing the integer peak: the sub-voxel residual d, in voxels. Two passes,
  // the second on the phases left by the first, so that a residual near half a voxel
  // does not wrap.
  Eigen::Vector3d fit_phase_plane(const Eigen::Vector3i& peak) {
    const std::size_t n = low.size();
    float* angles = low_angles.data();
    const float* reals = low_reals.data();
    const float* weights = low_weights.data();
    const float px = float(peak.x()), py = float(peak.y()), pz = float(peak.z());
    const float *fx = low.fx.data(), *fy = low.fy.data(), *fz = low.fz.data();
#pragma omp simd
    for (std::size_t b = 0; b < n; ++b) {
      const float shift_phase = kTwoPi * (fx[b] * px + fy[b] * py + fz[b] * pz);
      angles[b] = wrap_angle(fast_atan2(angles[b], reals[b]) + shift_phase);
    }
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    for (int pass = 0; pass < 2; ++pass) {
      const float dx = float(d.x()), dy = float(d.y()), dz = float(d.z());
      // Float sums in any order (omp simd): a few ulp over some 10^4 bins, far below the
      // phase noise, for a vectorised pass.
      float rx = 0.0f, ry = 0.0f, rz = 0.0f;
#pragma omp simd reduction(+ : rx, ry, rz)
      for (std::size_t b = 0; b < n; ++b) {
        const float residual =
            weights[b] * wrap_angle(angles[b] + kTwoPi * (fx[b] * dx + fy[b] * dy + fz[b] * dz));
        rx += residual * fx[b];
        ry += residual * fy[b];
        rz += residual * fz[b];
      }
      const Eigen::Vector3d step =
          low_normal.ldlt().solve(Eigen::Vector3d(rx, ry, rz)) / (-2.0 * M_PI);
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
  if (params.threads < 1 || params.threads > 256)
    fail("threads must be in [1, 256], got ", params.threads);
  check_grid_limits(params.limits);
  const double voxels = double(spec.dims.x()) * double(spec.dims.y()) * double(spec.dims.z());
  if (voxels > double(params.limits.max_voxels)) {
    fail("spec: a phase correlation grid of ", spec.dims.x(), " x ", spec.dims.y(), " x ",
         spec.dims.z(), " voxels (about ", voxels * kPhaseCorrelationBytesPerVoxel / 1e9,
         " GB) exceeds the limit of ", params.limits.max_voxels,
         " voxels (GridLimits::max_voxels)");
  }
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
  return estimate(moving, Eigen::Vector3i::Constant(INT_MAX / 2));
}

TranslationEstimate PhaseCorrelation::estimate(const VoxelGrid& moving,
                                               const Eigen::Vector3i& max_shift_voxels) {
  if (!impl_->has_target) fail("PhaseCorrelation: set_target() must be called before estimate()");
  if ((max_shift_voxels.array() < 0).any())
    fail("max_shift_voxels must be >= 0 voxels, got ", max_shift_voxels.transpose());
  require_same_spec(impl_->spec, moving, "moving");
  Impl& im = *impl_;
  im.transform(moving, im.spectrum.get());
  if (im.params.subvoxel) im.gather_low_bins();
  im.form_cross_power();
  const Impl::FeasibleShifts feasible = im.feasible_shifts(moving, max_shift_voxels);
  im.inverse_transform(feasible);

  TranslationEstimate result;
  float height = 0.0f;
  result.peak_voxels = im.find_peak(feasible, height);
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
