// Recovers a known shift, and reads a sensor's depth frame, through the installed library;
// exits non-zero on failure.
#include <spectral_vs/representation/depth_image.hpp>
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
  if (error >= 0.001) return 1;

  // A wall 0.8 m in front of a Kinect-class camera, in millimetres.
  Eigen::Matrix3d K;
  K << 525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0;
  const spectral_vs::RawDepthImage depth = spectral_vs::RawDepthImage::Constant(480, 640, 800);
  const spectral_vs::PointCloud wall = spectral_vs::cloud_from_depth(depth, K);
  std::printf("depth frame: %zu points at z = %.3f m, normal z %.3f\n", wall.size(),
              wall.points()(0, 2), wall.normals()(0, 2));
  return wall.size() == 476u * 636u && wall.points()(0, 2) == 0.8 && wall.normals()(0, 2) == -1.0
             ? 0
             : 1;
}
