#include <spectral_vs/alignment/aligner.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

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
  params.search.global_search = false;
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
  params.search.global_search = false;
  const AlignResult unbounded = align(c.model, c.scene, params);
  params.local.max_translation = 0.15;
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
  params.search.global_search = false;
  params.local.max_iterations = 1;
  params.local.translation_gain = 1.0;
  const Eigen::Vector3d found = align(model, scene, params).T_scene_model.topRightCorner<3, 1>();
  EXPECT_NEAR(found.x(), 0.12, 0.002);
  params.local.max_translation = 0.05;
  const AlignResult result = align(model, scene, params);
  const Eigen::Vector3d bounded = result.T_scene_model.topRightCorner<3, 1>();
  EXPECT_LE(bounded.cwiseAbs().maxCoeff(), 0.05 + result.voxel_size);
}

TEST(Align, RefusesBadInput) {
  const Case c = make_case(10.0, 3);
  EXPECT_THROW(align(PointCloud(), c.scene), std::invalid_argument);
  EXPECT_THROW(align(c.model, PointCloud(c.scene.points())), std::invalid_argument);  // no normals
  AlignParams params;
  params.scene.bandwidth = 1;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.local.tolerance = NAN;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.search.max_parts = 0;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.initial_guess(3, 0) = 1.0;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.local.max_translation = -0.1;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params = AlignParams{};
  params.limits.max_voxels = 1000;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
}

// --- The sensor: one origin, a single view detected from it ------------------------------

// The points of `cloud` whose normals face `origin`: for a convex object this is exactly
// what a sensor there sees (no surface hides another), the independent truth below.
PointCloud facing(const PointCloud& cloud, const Eigen::Vector3d& origin) {
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < cloud.points().rows(); ++i)
    if (cloud.normals().row(i).dot(origin - cloud.points().row(i).transpose()) > 0.0)
      rows.push_back(i);
  Points p(Eigen::Index(rows.size()), 3), n(Eigen::Index(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) {
    p.row(Eigen::Index(k)) = cloud.points().row(rows[k]);
    n.row(Eigen::Index(k)) = cloud.normals().row(rows[k]);
  }
  return PointCloud(p, n);
}

// A 0.24 x 0.12 x 0.08 m box (convex) 0.6 m in front of the origin, in the camera's frame.
PointCloud box_in_front(std::mt19937& rng, int samples = 8000) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const Eigen::Vector3d half(0.12, 0.06, 0.04);
  Points p(samples, 3), n(samples, 3);
  for (int i = 0; i < samples; ++i) {
    const int axis = i % 3;
    Eigen::Vector3d u(uniform(rng), uniform(rng), uniform(rng));
    u[axis] = u[axis] < 0 ? -1.0 : 1.0;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    normal[axis] = u[axis];
    p.row(i) = (half.cwiseProduct(u) + Eigen::Vector3d(0.05, -0.03, 0.6)).transpose();
    n.row(i) = normal.transpose();
  }
  return PointCloud(p, n);
}

TEST(SingleView, AViewFromTheOriginIsDetected) {
  std::mt19937 rng(21);
  const PointCloud box = box_in_front(rng);
  const PointCloud view = facing(box, Eigen::Vector3d::Zero());
  const SingleViewEvidence evidence = detect_single_view(view, Eigen::Vector3d::Zero(), 0.008);
  EXPECT_GT(evidence.visible, 0.97);
  EXPECT_TRUE(evidence.single_view);
}

TEST(SingleView, ScenesSeenFromAllSidesAreNot) {
  std::mt19937 rng(22);
  const PointCloud box = box_in_front(rng);
  const Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  // The full box from outside: its back is hidden by its front. The truth: the share of
  // its points facing the origin (no convex surface hides another part of its own side).
  const double truth = double(facing(box, origin).size()) / double(box.size());
  const SingleViewEvidence full = detect_single_view(box, origin, 0.008);
  EXPECT_NEAR(full.visible, truth, 0.05);
  EXPECT_FALSE(full.single_view);
  // A fused map: the views from two sensors on opposite sides, seen from either.
  const Eigen::Vector3d other(0.1, -0.06, 1.2);
  const PointCloud front = facing(box, origin), back = facing(box, other);
  Points p(front.size() + back.size(), 3), n(front.size() + back.size(), 3);
  p << front.points(), back.points();
  n << front.normals(), back.normals();
  const PointCloud fused(p, n);
  EXPECT_FALSE(detect_single_view(fused, origin, 0.008).single_view);
  EXPECT_FALSE(detect_single_view(fused, other, 0.008).single_view);
  // The box centred on the origin (a model in its own frame): nothing faces the origin.
  const PointCloud centred = box.transformed(test::translation(Eigen::Vector3d(-0.05, 0.03, -0.6)));
  EXPECT_LT(detect_single_view(centred, origin, 0.008).visible, 0.05);
  // The view in a world frame: its sensor is not at the origin.
  Transform T_world_camera = Transform::Identity();
  T_world_camera.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T_world_camera.topRightCorner<3, 1>() << 0.3, 0.0, 1.0;
  EXPECT_FALSE(detect_single_view(front.transformed(T_world_camera), origin, 0.008).single_view);
}

TEST(SingleView, AlignChecksADetectedViewAndOnlyThen) {
  std::mt19937 rng(23);
  const PointCloud box = box_in_front(rng);
  const PointCloud view = facing(box, Eigen::Vector3d::Zero());
  std::mt19937 model_rng(24);
  const PointCloud model = box_with_ball(4000, model_rng);
  AlignParams params;
  params.local.max_iterations = 5;
  params.search.hypotheses = 4;
  params.search.refinements = 1;
  EXPECT_TRUE(align(model, view, params).single_view);
  EXPECT_FALSE(align(model, box, params).single_view);
  params.scene.scene_view = SceneView::all_sides;
  EXPECT_FALSE(align(model, view, params).single_view);
  params.scene.scene_view = SceneView::single_view;
  params.scene.sensor_origin = Eigen::Vector3d(0.0, 0.0, 2.0);
  EXPECT_TRUE(align(model, box, params).single_view);  // declared: not detected
}

// --- Scale from the data ---------------------------------------------------------------

// Points on a sphere of radius r about c: their median is about c, every distance from it
// about r, so the typical size is 2 r and the rule gives max(2 r / 12, 2 r / sqrt(N)).
PointCloud sphere(double r, const Eigen::Vector3d& c, int samples, std::mt19937& rng) {
  std::normal_distribution<double> gaussian;
  Points p(samples, 3), n(samples, 3);
  for (int i = 0; i < samples; ++i) {
    const Eigen::Vector3d d =
        Eigen::Vector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized();
    p.row(i) = (c + r * d).transpose();
    n.row(i) = d.transpose();
  }
  return PointCloud(p, n);
}

TEST(AlignmentVoxel, FollowsTheRuleFromObjectsToRooms) {
  std::mt19937 rng(31);
  for (const double r : {0.025, 0.06, 1.0, 5.0}) {  // 5 cm objects to 10 m rooms
    const PointCloud dense = sphere(r, Eigen::Vector3d(0.3, -1.0, 2.0), 20000, rng);
    EXPECT_NEAR(alignment_voxel_size(dense, dense), 2.0 * r / 12.0, 0.02 * r / 12.0) << r;
    // 100 points: the spacing term binds; the typical size by brute force (sorting).
    const PointCloud sparse = sphere(r, Eigen::Vector3d::Zero(), 100, rng);
    const auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    Eigen::Vector3d centre;
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::VectorXd column = sparse.points().col(axis);
      centre[axis] = median(std::vector<double>(column.data(), column.data() + column.size()));
    }
    std::vector<double> distances;
    for (Eigen::Index i = 0; i < sparse.points().rows(); ++i)
      distances.push_back((sparse.points().row(i).transpose() - centre).norm());
    const double extent = 2.0 * median(distances);
    EXPECT_NEAR(alignment_voxel_size(sparse, sparse), extent / 10.0, 1e-12) << r;
    EXPECT_NEAR(extent, 2.0 * r, 0.2 * r) << r;
  }
  // A model of one point takes the scene's size; align() reports the voxel it used.
  const PointCloud room = sphere(2.0, Eigen::Vector3d::Zero(), 20000, rng);
  const PointCloud point(Points(Eigen::RowVector3d(0.1, 0.2, 0.3)),
                         Points(Eigen::RowVector3d(0.0, 0.0, 1.0)));
  EXPECT_NEAR(alignment_voxel_size(point, room), 4.0 / 12.0, 0.01);
  const PointCloud ball = sphere(0.06, Eigen::Vector3d::Zero(), 3000, rng);
  AlignParams params;
  params.search.global_search = false;
  params.local.max_iterations = 1;
  EXPECT_DOUBLE_EQ(align(ball, ball, params).voxel_size, alignment_voxel_size(ball, ball));
  params.scene.voxel_size = 0.004;
  EXPECT_DOUBLE_EQ(align(ball, ball, params).voxel_size, 0.004);
}

// --- initial_guess under global search --------------------------------------------------

TEST(InitialGuess, ANeighbourhoodPicksTheGuessedOfTwoCopies) {
  // Two copies of the model, 0.5 m apart: the global search alone has no way to prefer
  // either. A guess near each, with a neighbourhood, finds that one.
  std::mt19937 rng(41);
  const PointCloud model = box_with_ball(5000, rng);
  Transform A = Transform::Identity(), B = Transform::Identity();
  A.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  B.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(2.0, Eigen::Vector3d(-1, 0, 2).normalized()).toRotationMatrix();
  B.topRightCorner<3, 1>() << 0.5, 0.1, 0.0;
  const PointCloud a = box_with_ball(5000, rng).transformed(A);
  const PointCloud b = box_with_ball(5000, rng).transformed(B);
  Points p(a.size() + b.size(), 3), n(a.size() + b.size(), 3);
  p << a.points(), b.points();
  n << a.normals(), b.normals();
  const PointCloud scene(p, n);
  for (const Transform& truth : {A, B}) {
    Transform guess = truth;
    guess.topLeftCorner<3, 3>() =
        Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
        truth.topLeftCorner<3, 3>();
    guess.topRightCorner<3, 1>() += Eigen::Vector3d(0.02, -0.01, 0.01);
    AlignParams params;
    params.initial_guess = guess;
    params.search.guess_angle_deg = 30.0;
    params.search.guess_distance = 0.05;
    const AlignResult result = align(model, scene, params);
    EXPECT_LT(rotation_error_degrees(result.T_scene_model, truth), 1.0);
    EXPECT_LT(translation_error_mm(result.T_scene_model, truth), 2.0);
  }
}

TEST(InitialGuess, RefusesANeighbourhoodOutOfRange) {
  const Case c = make_case(10.0, 3);
  AlignParams params;
  params.search.guess_angle_deg = 181.0;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
  params.search.guess_angle_deg = 0.0;
  params.search.guess_distance = -0.1;
  EXPECT_THROW(align(c.model, c.scene, params), std::invalid_argument);
}

// --- What converged, iterations and history describe ------------------------------------

TEST(AlignResult, HistoryDescribesTheReturnedPose) {
  for (unsigned seed = 0; seed < 6; ++seed) {
    const Case c = make_case(60.0 + 20.0 * seed, 50 + seed);
    AlignParams params;
    params.refinement.polish = false;
    params.refinement.icp_refinement = false;
    const AlignResult result = align(c.model, c.scene, params);
    EXPECT_EQ(result.iterations, int(result.history.size()));
    if (result.stop_reason == AlignStopReason::kept_start ||
        result.stop_reason == AlignStopReason::reselected) {
      EXPECT_FALSE(result.converged);
      EXPECT_TRUE(result.history.empty());
    } else {
      ASSERT_FALSE(result.history.empty());
      // Without the polish and the ICP the returned pose is where the run ended, to the
      // bit (an angle from the trace of R1^T R2 has a floor of about 1e-6 degree).
      EXPECT_EQ(result.history.back().T_scene_model, result.T_scene_model) << "seed " << seed;
      const AlignIteration& last = result.history.back();
      EXPECT_EQ(result.converged,
                last.translation_step + last.rotation_gradient < params.local.tolerance);
    }
  }
}

TEST(AlignResult, RefinementsRunCountsTheRefinedHypotheses) {
  const Case c = make_case(120.0, 7);
  AlignParams params;
  const int runs = align(c.model, c.scene, params).refinements_run;
  EXPECT_GE(runs, 1);
  EXPECT_LE(runs, params.search.refinements);
  params.search.refinements = 1;
  EXPECT_EQ(align(c.model, c.scene, params).refinements_run, 1);
  params.search.global_search = false;
  EXPECT_EQ(align(c.model, c.scene, params).refinements_run, 0);
}

}  // namespace
}  // namespace spectral_vs
