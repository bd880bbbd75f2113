// Times the translation step of the paper (voxelize the moving cloud, forward FFT,
// normalised cross-power spectrum, inverse FFT, peak search, sub-voxel fit) against
// the bare forward + inverse real FFT of the same grid with the same FFTW planning,
// single-threaded. Prints one JSON object per voxel size.
#include <spectral_vs/translation/phase_correlation.hpp>

#include <fftw3.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

using spectral_vs::PointCloud;
using spectral_vs::Points;
using Clock = std::chrono::steady_clock;

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

double bare_fft_ms(const Eigen::Vector3i& d, int runs) {
  const std::size_t n = std::size_t(d.x()) * d.y() * d.z();
  const std::size_t nc = std::size_t(d.x()) * d.y() * (d.z() / 2 + 1);
  float* real = fftwf_alloc_real(n);
  fftwf_complex* spectrum = fftwf_alloc_complex(nc);
  fftwf_plan forward = fftwf_plan_dft_r2c_3d(d.x(), d.y(), d.z(), real, spectrum, FFTW_ESTIMATE);
  fftwf_plan inverse = fftwf_plan_dft_c2r_3d(d.x(), d.y(), d.z(), spectrum, real, FFTW_ESTIMATE);
  std::fill(real, real + n, 0.0f);
  std::vector<double> times;
  for (int r = 0; r < runs; ++r) {
    const auto start = Clock::now();
    fftwf_execute(forward);
    fftwf_execute(inverse);
    times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
    std::fill(real, real + n, 0.0f);
  }
  fftwf_destroy_plan(forward);
  fftwf_destroy_plan(inverse);
  fftwf_free(real);
  fftwf_free(spectrum);
  return median(times);
}

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
    std::vector<double> step_binary, step_trilinear;
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();
    for (int k = 0; k < 2 * runs; ++k) {
      const bool trilinear = k % 2;
      const auto start = Clock::now();
      spectral_vs::voxelize_into(object.points(), spec,
                                 trilinear ? spectral_vs::Occupancy::trilinear : spectral_vs::Occupancy::binary,
                                 moving);
      shift = correlation.estimate(moving).shift;
      (trilinear ? step_trilinear : step_binary)
          .push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
    }
    const double fft = bare_fft_ms(spec.dims, runs);
    std::printf("  {\"voxel_size_m\": %.4f, \"dims\": [%d, %d, %d], \"points\": %zu, \"runs\": %d,\n"
                "   \"bare_fft_ms\": %.4f, \"step_binary_ms\": %.4f, \"step_trilinear_ms\": %.4f,\n"
                "   \"ratio_binary\": %.3f, \"ratio_trilinear\": %.3f,\n"
                "   \"shift_mm\": [%.2f, %.2f, %.2f]}%s\n",
                r, spec.dims.x(), spec.dims.y(), spec.dims.z(), object.size(), runs, fft,
                median(step_binary), median(step_trilinear), median(step_binary) / fft,
                median(step_trilinear) / fft, 1000 * shift.x(), 1000 * shift.y(), 1000 * shift.z(),
                s == 0 ? "," : "");
  }
  std::printf("]\n");
  return 0;
}
