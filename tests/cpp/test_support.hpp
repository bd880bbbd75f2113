#pragma once
// Seeded synthetic data and the path of the shared real scans, for the C++ tests.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Geometry>
#include <cstdlib>
#include <random>
#include <string>
#include <utility>

namespace spectral_vs::test {

inline std::string data_path(const std::string& file) {
  const char* folder = std::getenv("SPECTRAL_VS_DATA");
  return std::string(folder ? folder : SPECTRAL_VS_TEST_DATA) + "/" + file;
}

/// Row i of `points` and `normals`: a uniform sample of one of the two faces of a box of
/// half sides `half` across `axis` (the side drawn at random), its outward normal.
inline void sample_box_face(const Eigen::Vector3d& half, int axis, std::mt19937& rng,
                            Points& points, Points& normals, Eigen::Index i) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::Vector3d u(uniform(rng), uniform(rng), uniform(rng));
  u[axis] = u[axis] < 0 ? -1.0 : 1.0;
  points.row(i) = half.cwiseProduct(u).transpose();
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  n[axis] = u[axis];
  normals.row(i) = n.transpose();
}

/// Surface samples of a box (0.24 x 0.12 x 0.08 m) with a sphere (r = 0.06 m) beside
/// it: an asymmetric 0.25 m object with outward unit normals.
inline PointCloud box_and_sphere(int samples, std::mt19937& rng) {
  std::normal_distribution<double> gaussian(0.0, 1.0);
  Points points(samples, 3), normals(samples, 3);
  const Eigen::Vector3d half(0.12, 0.06, 0.04);
  for (int i = 0; i < samples; ++i) {
    if (i % 2 == 0) {
      Eigen::Vector3d n(gaussian(rng), gaussian(rng), gaussian(rng));
      n.normalize();
      points.row(i) = (Eigen::Vector3d(0.10, 0.10, 0.0) + 0.06 * n).transpose();
      normals.row(i) = n.transpose();
    } else {
      const int axis = std::uniform_int_distribution<int>(0, 2)(rng);
      sample_box_face(half, axis, rng, points, normals, i);
    }
  }
  return PointCloud(points, normals);
}

/// Surface samples of a box (0.20 x 0.12 x 0.06 m) with distinct sides, area-weighted,
/// with outward unit normals: its symmetries are the half turns about its axes.
inline PointCloud box(int samples, std::mt19937& rng) {
  const Eigen::Vector3d half(0.10, 0.06, 0.03);
  const Eigen::Vector3d area(half.y() * half.z(), half.x() * half.z(), half.x() * half.y());
  std::discrete_distribution<int> face{area.x(), area.y(), area.z()};
  Points points(samples, 3), normals(samples, 3);
  for (int i = 0; i < samples; ++i) sample_box_face(half, face(rng), rng, points, normals, i);
  return PointCloud(points, normals);
}

/// `cloud` with each point kept with probability `keep` and moved by Gaussian noise.
inline PointCloud thin_and_jitter(const PointCloud& cloud, double keep, double sigma,
                                  std::mt19937& rng) {
  std::bernoulli_distribution kept(keep);
  std::normal_distribution<double> noise(0.0, sigma);
  Points points(cloud.size(), 3);
  Eigen::Index n = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!kept(rng)) continue;
    points.row(n++) = cloud.points().row(Eigen::Index(i)) +
                      Eigen::RowVector3d(noise(rng), noise(rng), noise(rng));
  }
  points.conservativeResize(n, Eigen::NoChange);
  return PointCloud(points);
}

/// How far `T` is from `T_true`: the rotation between them (degrees) and the distance
/// between where they put `centre` (metres).
inline std::pair<double, double> pose_error(const Transform& T, const Transform& T_true,
                                            const Eigen::Vector3d& centre) {
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>(), R_true = T_true.topLeftCorner<3, 3>();
  const Eigen::Vector3d moved = R * centre + T.topRightCorner<3, 1>();
  const Eigen::Vector3d truth = R_true * centre + T_true.topRightCorner<3, 1>();
  return {Eigen::AngleAxisd(R.transpose() * R_true).angle() * 180.0 / M_PI, (moved - truth).norm()};
}

inline Transform translation(const Eigen::Vector3d& t) {
  Transform T = Transform::Identity();
  T.topRightCorner<3, 1>() = t;
  return T;
}

}  // namespace spectral_vs::test
