#include <spectral_vs/alignment/aligner.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace spectral_vs {
namespace {

// A box sampled in proportion to its face areas, with a ball on its top face: an
// object whose EGI and shape single out one pose.
PointCloud box_with_ball(int samples, std::mt19937& rng) {
  const Eigen::Vector3d half(0.12, 0.06, 0.04);
  const Eigen::Vector3d areas(half.y() * half.z(), half.x() * half.z(), half.x() * half.y());
  std::discrete_distribution<int> face_axis({areas.x(), areas.y(), areas.z()});
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> gaussian;
  Points p(2 * samples, 3), n(2 * samples, 3);
  Eigen::Index count = 0;
  for (int i = 0; i < samples; ++i) {
    const int axis = face_axis(rng);
    Eigen::Vector3d u(uniform(rng), uniform(rng), uniform(rng));
    u[axis] = u[axis] < 0 ? -1.0 : 1.0;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    normal[axis] = u[axis];
    p.row(count) = half.cwiseProduct(u).transpose();
    n.row(count++) = normal.transpose();
  }
  for (int i = 0; i < samples / 2; ++i) {
    const Eigen::Vector3d d =
        Eigen::Vector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized();
    const Eigen::Vector3d q = Eigen::Vector3d(0.07, 0.0, 0.07) + 0.03 * d;
    if (q.z() <= 0.04) continue;
    p.row(count) = q.transpose();
    n.row(count++) = d.transpose();
  }
  p.conservativeResize(count, Eigen::NoChange);
  n.conservativeResize(count, Eigen::NoChange);
  return PointCloud(p, n);
}

struct Case {
  PointCloud model, scene;
  Transform T_scene_model;
};

Case make_case(double angle_degrees, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gaussian;
  std::uniform_real_distribution<double> offset(-0.1, 0.1);
  Case c;
  c.model = box_with_ball(6000, rng);
  const Eigen::Vector3d axis =
      Eigen::Vector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized();
  c.T_scene_model = Transform::Identity();
  c.T_scene_model.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(angle_degrees * M_PI / 180.0, axis).toRotationMatrix();
  c.T_scene_model.topRightCorner<3, 1>() << offset(rng), offset(rng), offset(rng);
  const PointCloud resampled = box_with_ball(6000, rng);
  c.scene = resampled.transformed(c.T_scene_model);
  return c;
}

double rotation_error_degrees(const Transform& a, const Transform& b) {
  const Eigen::Matrix3d d = a.topLeftCorner<3, 3>().transpose() * b.topLeftCorner<3, 3>();
  return std::acos(std::clamp((d.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
}

double translation_error_mm(const Transform& a, const Transform& b) {
  return 1000.0 * (a.topRightCorner<3, 1>() - b.topRightCorner<3, 1>()).norm();
}

TEST(Align, PaperModeConvergesFromASmallRotation) {
  const Case c = make_case(12.0, 1);
  AlignParams params;
  params.global_search = false;
  const AlignResult result = align(c.model, c.scene, params);
  EXPECT_TRUE(result.converged);
  EXPECT_LT(rotation_error_degrees(result.T_scene_model, c.T_scene_model), 1.0);
  EXPECT_LT(translation_error_mm(result.T_scene_model, c.T_scene_model), 2.0);
  EXPECT_GT(result.fitness, 0.9);
}

TEST(Align, GlobalSearchRecoversAHalfTurn) {
  const Case c = make_case(170.0, 2);
  const AlignResult result = align(c.model, c.scene);
  EXPECT_LT(rotation_error_degrees(result.T_scene_model, c.T_scene_model), 1.0);
  EXPECT_LT(translation_error_mm(result.T_scene_model, c.T_scene_model), 2.0);
}

TEST(Align, BoundedTranslationAgreesWithinItsBound) {
  // Offsets of up to 0.1 m per axis: a bound of 0.15 m changes the grid, not the answer.
  const Case c = make_case(8.0, 4);
  AlignParams params;
  params.global_search = false;
  const AlignResult unbounded = align(c.model, c.scene, params);
  params.max_translation = 0.15;
  const AlignResult bounded = align(c.model, c.scene, params);
  EXPECT_LT(rotation_error_degrees(bounded.T_scene_model, c.T_scene_model), 1.0);
  EXPECT_LT(translation_error_mm(bounded.T_scene_model, c.T_scene_model), 2.0);
  EXPECT_LT(rotation_error_degrees(bounded.T_scene_model, unbounded.T_scene_model), 0.2);
  EXPECT_LT(translation_error_mm(bounded.T_scene_model, unbounded.T_scene_model), 0.5);
}

TEST(Align, BoundedTranslationSeeksNoFartherThanItsBound) {
  // The scene is the model moved 0.12 m along x: one full translation step finds it
  // unbounded; bounded to 0.05 m, the step stays within the bound (per axis).
  std::mt19937 rng(5);
  const PointCloud model = box_with_ball(6000, rng);
  const PointCloud scene = model.transformed(test::translation(Eigen::Vector3d(0.12, 0.0, 0.0)));
  AlignParams params;
  params.global_search = false;
  params.max_iterations = 1;
  params.translation_gain = 1.0;
  const Eigen::Vector3d found = align(model, scene, params).T_scene_model.topRightCorner<3, 1>();
  EXPECT_NEAR(found.x(), 0.12, 0.002);
  params.max_translation = 0.05;
  const Eigen::Vector3d bounded = align(model, scene, params).T_scene_model.topRightCorner<3, 1>();
  EXPECT_LE(bounded.cwiseAbs().maxCoeff(), 0.05 + params.voxel_size);
}

TEST(Align, RefusesBadInput) {
  const Case c = make_case(10.0, 3);
  EXPECT_THROW(align(PointCloud(), c.scene), std::invalid_argument);
  EXPECT_THROW(align(c.model, PointCloud(c.scene.points())), std::invalid_argument);  // no normals
  AlignParams params;
  params.bandwidth = 1;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.tolerance = NAN;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.initial_guess(3, 0) = 1.0;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.max_translation = -0.1;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.limits.max_voxels = 1000;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
