// Times the translation step of the paper (voxelize the moving cloud, forward FFT,
// normalised cross-power spectrum, inverse FFT, peak search, sub-voxel fit) against
// the bare forward + inverse real FFT of the same grid with the same FFTW planning,
// single-threaded. Prints one JSON object per voxel size.
//
// Times are the CPU time of the calling thread, and the three measurements are
// interleaved run by run, so that other jobs on the machine neither inflate one of them
// (a descheduled thread's clock stops) nor skew the ratio between them.
#include <spectral_vs/translation/phase_correlation.hpp>

#include <fftw3.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

using spectral_vs::PointCloud;
using spectral_vs::Points;

double thread_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * double(t.tv_sec) + 1e-6 * double(t.tv_nsec);
}

// A 0.25 m object (box with a sphere) on a 0.6 m x 0.6 m table with two other boxes.
PointCloud scene_cloud(std::mt19937& rng, PointCloud& object) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> g;
  std::vector<Eigen::RowVector3d> obj, scene;
  for (int i = 0; i < 6000; ++i) {
    if (i % 2) {
      Eigen::RowVector3d n(g(rng), g(rng), g(rng));
      obj.push_back(Eigen::RowVector3d(0.07, 0.05, 0.06) + 0.06 * n.normalized());
    } else {
      Eigen::RowVector3d p(u(rng), u(rng), u(rng));
      const int axis = i % 3;
      p[axis] = p[axis] < 0 ? -1 : 1;
      obj.push_back(p.cwiseProduct(Eigen::RowVector3d(0.09, 0.06, 0.04)) + Eigen::RowVector3d(0, 0, 0.04));
    }
  }
  Points op(obj.size(), 3);
  for (std::size_t i = 0; i < obj.size(); ++i) op.row(i) = obj[i];
  object = PointCloud(op);
  for (int i = 0; i < 20000; ++i) scene.push_back(Eigen::RowVector3d(0.3 * u(rng), 0.3 * u(rng), 0.0));
  for (int i = 0; i < 4000; ++i) {
    Eigen::RowVector3d p(u(rng), u(rng), u(rng));
    p[i % 3] = p[i % 3] < 0 ? -1 : 1;
    const Eigen::RowVector3d centre = i % 2 ? Eigen::RowVector3d(-0.2, 0.2, 0.05) : Eigen::RowVector3d(0.2, -0.2, 0.05);
    scene.push_back(centre + p * 0.05);
  }
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topRightCorner<3, 1>() << 0.031, -0.047, 0.0;
  const PointCloud moved = object.transformed(T);
  for (Eigen::Index i = 0; i < moved.points().rows(); ++i) scene.push_back(moved.points().row(i));
  Points sp(scene.size(), 3);
  for (std::size_t i = 0; i < scene.size(); ++i) sp.row(i) = scene[i];
  return PointCloud(sp);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The bare forward + inverse real FFT of a grid, with the library's planning flags.
class BareFft {
public:
  explicit BareFft(const Eigen::Vector3i& d)
      : n_(std::size_t(d.x()) * d.y() * d.z()),
        real_(fftwf_alloc_real(n_)),
        spectrum_(fftwf_alloc_complex(std::size_t(d.x()) * d.y() * (d.z() / 2 + 1))) {
    forward_ = fftwf_plan_dft_r2c_3d(d.x(), d.y(), d.z(), real_, spectrum_, FFTW_ESTIMATE);
    inverse_ = fftwf_plan_dft_c2r_3d(d.x(), d.y(), d.z(), spectrum_, real_, FFTW_ESTIMATE);
    std::fill(real_, real_ + n_, 0.0f);
  }
  ~BareFft() {
    fftwf_destroy_plan(forward_);
    fftwf_destroy_plan(inverse_);
    fftwf_free(real_);
    fftwf_free(spectrum_);
  }
  double time_ms() {
    const double start = thread_ms();
    fftwf_execute(forward_);
    fftwf_execute(inverse_);
    const double elapsed = thread_ms() - start;
    std::fill(real_, real_ + n_, 0.0f);  // the inverse is unnormalised: keep values bounded
    return elapsed;
  }

private:
  std::size_t n_;
  float* real_;
  fftwf_complex* spectrum_;
  fftwf_plan forward_, inverse_;
};

}  // namespace

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::atoi(argv[1]) : 100;
  std::mt19937 rng(42);
  PointCloud object;
  const PointCloud scene = scene_cloud(rng, object);
  std::printf("[\n");
  const double sizes[] = {0.008, 0.004};
  for (int s = 0; s < 2; ++s) {
    const double r = sizes[s];
    const auto spec = spectral_vs::make_grid_spec(spectral_vs::bounding_box(object),
                                                  spectral_vs::bounding_box(scene), r);
    spectral_vs::PhaseCorrelation correlation(spec);
    correlation.set_target(spectral_vs::voxelize(scene, spec, spectral_vs::Occupancy::binary));
    spectral_vs::VoxelGrid moving;
    BareFft bare(spec.dims);
    std::vector<double> step_binary, step_trilinear, fft;
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();
    for (int k = 0; k < runs; ++k) {
      for (const bool trilinear : {false, true}) {
        const double start = thread_ms();
        spectral_vs::voxelize_into(object.points(), spec,
                                   trilinear ? spectral_vs::Occupancy::trilinear : spectral_vs::Occupancy::binary,
                                   moving);
        shift = correlation.estimate(moving).shift;
        (trilinear ? step_trilinear : step_binary).push_back(thread_ms() - start);
      }
      fft.push_back(bare.time_ms());
    }
    std::printf("  {\"voxel_size_m\": %.4f, \"dims\": [%d, %d, %d], \"points\": %zu, \"runs\": %d,\n"
                "   \"bare_fft_ms\": %.4f, \"step_binary_ms\": %.4f, \"step_trilinear_ms\": %.4f,\n"
                "   \"ratio_binary\": %.3f, \"ratio_trilinear\": %.3f,\n"
                "   \"shift_mm\": [%.2f, %.2f, %.2f]}%s\n",
                r, spec.dims.x(), spec.dims.y(), spec.dims.z(), object.size(), runs, median(fft),
                median(step_binary), median(step_trilinear), median(step_binary) / median(fft),
                median(step_trilinear) / median(fft), 1000 * shift.x(), 1000 * shift.y(), 1000 * shift.z(),
                s == 0 ? "," : "");
  }
  std::printf("]\n");
  return 0;
}
