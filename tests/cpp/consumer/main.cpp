// Recovers a known shift through the installed library; exits non-zero on failure.
#include <spectral_vs/translation/phase_correlation.hpp>

#include <cstdio>
#include <random>

int main() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-0.05, 0.05);
  spectral_vs::Points points(500, 3);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    points.row(i) << uniform(rng), uniform(rng), 0.5 * uniform(rng);
  }
  const spectral_vs::PointCloud model(points);
  spectral_vs::Transform T = spectral_vs::Transform::Identity();
  T.topRightCorner<3, 1>() << 0.03, -0.02, 0.01;
  const spectral_vs::PointCloud scene = model.transformed(T);

  const auto spec = spectral_vs::make_grid_spec(spectral_vs::bounding_box(model),
                                                spectral_vs::bounding_box(scene), 0.005);
  const auto estimate = spectral_vs::phase_correlation(spectral_vs::voxelize(model, spec),
                                                       spectral_vs::voxelize(scene, spec));
  const double error = (estimate.shift - T.topRightCorner<3, 1>()).norm();
  std::printf("shift %.4f %.4f %.4f m, error %.2f mm\n", estimate.shift.x(), estimate.shift.y(),
              estimate.shift.z(), 1000.0 * error);
  return error < 0.001 ? 0 : 1;
}
