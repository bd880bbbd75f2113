#include <spectral_vs/alignment/model_aligner.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace spectral_vs {
namespace {

// A table top (0.6 x 0.4 m, normals up) with a box and a sphere on it, the objects
// jittered by 0.5 mm: a small version of the servo's view of a cluttered table.
PointCloud table_scene(std::mt19937& rng) {
  const PointCloud objects = test::box_and_sphere(6000, rng);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, 0.0005);
  const int table = 8000;
  Points points(Eigen::Index(objects.size()) + table, 3), normals(points.rows(), 3);
  for (Eigen::Index i = 0; i < Eigen::Index(objects.size()); ++i) {
    points.row(i) =
        objects.points().row(i) + Eigen::RowVector3d(noise(rng), noise(rng), noise(rng) + 0.1);
    normals.row(i) = objects.normals().row(i);
  }
  for (int i = 0; i < table; ++i) {
    const Eigen::Index row = Eigen::Index(objects.size()) + i;
    points.row(row) << 0.3 * uniform(rng), 0.2 * uniform(rng), 0.06 + noise(rng);
    normals.row(row) << 0.0, 0.0, 1.0;
  }
  return PointCloud(points, normals);
}

Transform motion(double degrees, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  Transform T = test::translation(t);
  T.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(degrees * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  return T;
}

// The servo's settings: one iteration of Algorithm 1 from the identity, bounded search.
AlignParams servo_params() {
  AlignParams params;
  params.scene.voxel_size = 0.015;
  params.scene.bandwidth = 8;
  params.search.global_search = false;
  params.local.max_iterations = 1;
  params.local.translation_gain = 1.0;
  params.local.rotation_gain = 1.0;
  params.local.max_rotation_step = 0.05;
  params.local.max_translation = 0.3;
  return params;
}

void expect_same(const AlignResult& a, const AlignResult& b) {
  EXPECT_LT((a.T_scene_model - b.T_scene_model).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(a.converged, b.converged);
  EXPECT_EQ(a.stop_reason, b.stop_reason);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_NEAR(a.fitness, b.fitness, 1e-12);
  EXPECT_NEAR(a.correlation, b.correlation, 1e-12);
  EXPECT_NEAR(a.translation_peak, b.translation_peak, 1e-12);
  ASSERT_EQ(a.history.size(), b.history.size());
  for (std::size_t i = 0; i < a.history.size(); ++i) {
    EXPECT_NEAR(a.history[i].translation_cost, b.history[i].translation_cost, 1e-9);
    EXPECT_NEAR(a.history[i].rotation_cost, b.history[i].rotation_cost, 1e-12);
    EXPECT_NEAR(a.history[i].translation_step, b.history[i].translation_step, 1e-9);
    EXPECT_NEAR(a.history[i].rotation_gradient, b.history[i].rotation_gradient, 1e-12);
  }
}

double rotation_error_degrees(const Transform& a, const Transform& b) {
  const Eigen::Matrix3d d = a.topLeftCorner<3, 3>().transpose() * b.topLeftCorner<3, 3>();
  return std::acos(std::clamp((d.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
}

double translation_error_mm(const Transform& a, const Transform& b) {
  return 1000.0 * (a.topRightCorner<3, 1>() - b.topRightCorner<3, 1>()).norm();
}

TEST(ModelAligner, OneIterationStepsMatchAlignOnASequenceOfViews) {
  // One aligner, many scenes: the servo's use. Views that move by a few centimetres
  // keep the grid's size (its FFT plans are re-used) or change it; every result must be
  // align()'s.
  std::mt19937 rng(11);
  const PointCloud model = table_scene(rng);
  const AlignParams params = servo_params();
  ModelAligner aligner(model, params);
  const Eigen::Vector3d moves[] = {{0.0, 0.0, 0.0},
                                   {0.02, -0.01, 0.0},
                                   {0.021, -0.011, 0.001},
                                   {-0.08, 0.05, 0.03},
                                   {0.0, 0.0, 0.0}};
  for (const Eigen::Vector3d& t : moves) {
    const PointCloud scene = table_scene(rng).transformed(motion(3.0, Eigen::Vector3d(1, 2, 3), t));
    expect_same(aligner.align(scene), align(model, scene, params));
    EXPECT_GT(aligner.last_timings().total, 0.0);
  }
}

// The servo's bounded search run to convergence (40 iterations at half gains).
AlignParams converging_params() {
  AlignParams params = servo_params();
  params.local.max_iterations = 40;
  params.local.translation_gain = 0.5;
  params.local.rotation_gain = 0.5;
  return params;
}

TEST(ModelAligner, RunToConvergenceMatchesAlignAndFindsTheMotion) {
  std::mt19937 rng(12);
  const PointCloud model = table_scene(rng);
  const AlignParams params = converging_params();
  const Transform truth =
      motion(6.0, Eigen::Vector3d(-1, 0.5, 2), Eigen::Vector3d(0.04, -0.03, 0.02));
  const PointCloud scene = table_scene(rng).transformed(truth);
  ModelAligner aligner(model, params);
  const AlignResult result = aligner.align(scene);
  expect_same(result, align(model, scene, params));
  EXPECT_LT(rotation_error_degrees(result.T_scene_model, truth), 1.0);
  EXPECT_LT(translation_error_mm(result.T_scene_model, truth), 3.0);
}

// The bounded search's grid reads only the scene within max_translation of the model's
// box: with far clutter (a floor seen by a tilted camera, 1 m off; its normals still
// enter the scene's EGI) ModelAligner and align() agree and find the motion.
TEST(ModelAligner, FarClutterLeavesTheBoundedSearchAlone) {
  std::mt19937 rng(31);
  const PointCloud model = table_scene(rng);
  const AlignParams params = converging_params();
  const Transform truth =
      motion(4.0, Eigen::Vector3d(0.5, -1, 2), Eigen::Vector3d(-0.05, 0.02, 0.01));
  const PointCloud scene = table_scene(rng).transformed(truth);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Points points(Eigen::Index(scene.size()) + 4000, 3), normals(points.rows(), 3);
  points.topRows(Eigen::Index(scene.size())) = scene.points();
  normals.topRows(Eigen::Index(scene.size())) = scene.normals();
  for (Eigen::Index i = Eigen::Index(scene.size()); i < points.rows(); ++i) {
    points.row(i) << 0.8 * uniform(rng), 0.8 * uniform(rng), 1.2 + 0.3 * uniform(rng);
    normals.row(i) << 0.0, 0.0, -1.0;
  }
  const PointCloud cluttered(points, normals);
  ModelAligner aligner(model, params);
  const AlignResult result = aligner.align(cluttered);
  expect_same(result, align(model, cluttered, params));
  EXPECT_LT(rotation_error_degrees(result.T_scene_model, truth), 1.0);
  EXPECT_LT(translation_error_mm(result.T_scene_model, truth), 3.0);
}

// A tool left on the table: a 10 cm cube's top and sides, which the model does not have.
PointCloud with_a_tool(const PointCloud& scene, std::mt19937& rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const int tool = 6000;
  Points points(Eigen::Index(scene.size()) + tool, 3), normals(points.rows(), 3);
  points.topRows(Eigen::Index(scene.size())) = scene.points();
  normals.topRows(Eigen::Index(scene.size())) = scene.normals();
  const Eigen::Vector3d centre(-0.18, -0.1, 0.11);
  for (int i = 0; i < tool; ++i) {
    const int face = i % 5;  // top, then four sides; the table hides the bottom
    const int axis = face == 0 ? 2 : (face - 1) / 2;
    const double sign = face == 0 ? 1.0 : (face % 2 ? 1.0 : -1.0);
    Eigen::Vector3d u(uniform(rng), uniform(rng), uniform(rng));
    u[axis] = sign;
    const Eigen::Index row = Eigen::Index(scene.size()) + i;
    points.row(row) = (centre + 0.05 * u).transpose();
    normals.row(row).setZero();
    normals(row, axis) = sign;
  }
  return PointCloud(points, normals);
}

// LocalParams::icp: Algorithm 1's one step toward a view with a tool the model lacks ends
// where the ICP (pairs within a voxel, the tool left out) takes it to the motion, in
// ModelAligner as in align(); off, the pose is Algorithm 1's alone.
TEST(ModelAligner, LocalIcpTakesAStepPulledByNewGeometryToTheMotion) {
  std::mt19937 rng(41);
  const PointCloud model = table_scene(rng);
  const Transform truth =
      motion(2.0, Eigen::Vector3d(0.3, -1, 2), Eigen::Vector3d(0.012, -0.008, 0.004));
  const PointCloud scene = with_a_tool(table_scene(rng), rng).transformed(truth);
  AlignParams params = servo_params();
  params.scene.scene_view = SceneView::all_sides;
  const AlignResult paper = ModelAligner(model, params).align(scene);
  EXPECT_EQ(paper.icp_iterations, 0);
  params.local.icp = true;
  ModelAligner aligner(model, params);
  const AlignResult refined = aligner.align(scene);
  expect_same(refined, align(model, scene, params));
  EXPECT_GT(refined.icp_iterations, 0);
  EXPECT_GT(aligner.last_timings().icp, 0.0);
  EXPECT_LT(rotation_error_degrees(refined.T_scene_model, truth), 0.1);
  EXPECT_LT(translation_error_mm(refined.T_scene_model, truth), 0.5);
  const auto off = [&](const AlignResult& r) {  // degrees plus mm
    return rotation_error_degrees(r.T_scene_model, truth) +
           translation_error_mm(r.T_scene_model, truth);
  };
  EXPECT_LT(off(refined), 0.5 * off(paper));  // what the ICP mends
}

TEST(ModelAligner, FitnessIsAlignsWhereTheModelOnlyPartlyMeetsTheScene) {
  // The fitness map is built only around the model: a scene that holds part of the
  // model (a window of it), a model that sticks out of the scene's box (its voxels
  // outside count, unsupported), a turned model (few normals agree) and the visible
  // points only (a declared single view) all score as align() scores them.
  std::mt19937 rng(16);
  const PointCloud model = table_scene(rng);
  const PointCloud full =
      table_scene(rng).transformed(motion(2.0, Eigen::Vector3d(0, 1, 1), {0.01, 0.0, 0.0}));
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < Eigen::Index(full.size()); ++i) {
    if (full.points()(i, 0) < 0.1) rows.push_back(i);
  }
  Points p(Eigen::Index(rows.size()), 3), n(Eigen::Index(rows.size()), 3);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    p.row(Eigen::Index(i)) = full.points().row(rows[i]);
    n.row(Eigen::Index(i)) = full.normals().row(rows[i]);
  }
  const PointCloud part(p, n);
  AlignParams params = servo_params();
  for (const bool visible : {false, true}) {
    if (visible) {
      params.scene.scene_view = SceneView::single_view;
      params.scene.sensor_origin = Eigen::Vector3d(0.1, 0.0, 1.0);
    }
    ModelAligner aligner(model, params);
    for (const PointCloud* scene : {&full, &part}) {
      for (const Transform& guess :
           {Transform(Transform::Identity()), motion(50.0, {1, 0, 0}, {0.0, 0.0, 0.05})}) {
        const AlignResult prepared = aligner.align(*scene, guess);
        AlignParams plain = params;
        plain.initial_guess = guess;
        expect_same(prepared, align(model, *scene, plain));
        EXPECT_GT(prepared.fitness, 0.0);
        EXPECT_LE(prepared.fitness, 1.0);
        if (scene == &part) {
          EXPECT_LT(prepared.fitness, 0.9);  // much of the model is unsupported
        }
      }
    }
  }
}

TEST(ModelAligner, InitialGuessArgumentActsAsTheParameter) {
  std::mt19937 rng(13);
  const PointCloud model = table_scene(rng);
  const PointCloud scene =
      table_scene(rng).transformed(motion(4.0, Eigen::Vector3d(0, 0, 1), {0.03, 0.0, 0.0}));
  AlignParams params = servo_params();
  const Transform guess = motion(2.0, Eigen::Vector3d(0, 0, 1), {0.02, 0.0, 0.0});
  ModelAligner aligner(model, params);
  const AlignResult from_argument = aligner.align(scene, guess);
  params.initial_guess = guess;
  expect_same(from_argument, align(model, scene, params));
  expect_same(ModelAligner(model, params).align(scene), from_argument);
}

// The servo reads only the fitness: without the verification (AlignParams::verify) the
// pose, fitness and history are the verified call's bit for bit, and the verification's
// figures stay 0; align() skips it alike in its local mode.
TEST(ModelAligner, WithoutVerificationThePoseAndFitnessAreTheSame) {
  std::mt19937 rng(16);
  const PointCloud model = table_scene(rng);
  const AlignParams verified = servo_params();
  AlignParams unverified = verified;
  unverified.verification.verify = false;
  ModelAligner with(model, verified), without(model, unverified);
  for (const Eigen::Vector3d& t : {Eigen::Vector3d(0.02, -0.01, 0.0), Eigen::Vector3d(0, 0, 0)}) {
    const Transform truth = motion(3.0, Eigen::Vector3d(1, 2, 3), t);
    const PointCloud scene = table_scene(rng).transformed(truth);
    const AlignResult a = with.align(scene);
    const AlignResult b = without.align(scene);
    EXPECT_TRUE(a.T_scene_model.matrix() == b.T_scene_model.matrix());
    EXPECT_EQ(a.fitness, b.fitness);
    EXPECT_EQ(a.correlation, b.correlation);
    ASSERT_EQ(a.history.size(), b.history.size());
    EXPECT_TRUE(a.history.back().T_scene_model.matrix() == b.history.back().T_scene_model.matrix());
    // One step of the servo from the identity lands within a few mm of the truth: the
    // verified call confirms most of the model, the unverified one reports nothing.
    EXPECT_LT(translation_error_mm(a.T_scene_model, truth), 10.0);
    EXPECT_GT(a.confidence, 0.5);
    EXPECT_GT(a.inliers, 1000);
    EXPECT_EQ(b.confidence, 0.0);
    EXPECT_EQ(b.inliers, 0);
    EXPECT_EQ(b.inlier_rmse, 0.0);
    EXPECT_EQ(b.inlier_distance, 0.0);
    const AlignResult plain = align(model, scene, unverified);
    expect_same(plain, b);
    EXPECT_EQ(plain.confidence, 0.0);
    EXPECT_EQ(plain.inliers, 0);
  }
}

TEST(ModelAligner, OtherModesRunAlign) {
  // The global search and the paper's unbounded translation are not prepared: they give
  // align()'s result as it is.
  std::mt19937 rng(14);
  const PointCloud model = test::box_and_sphere(3000, rng);
  const PointCloud scene =
      test::box_and_sphere(3000, rng).transformed(motion(40.0, {1, 1, 0}, {0.05, 0, 0}));
  AlignParams params;
  params.scene.voxel_size = 0.01;
  params.search.hypotheses = 4;
  params.search.refinements = 1;
  expect_same(ModelAligner(model, params).align(scene), align(model, scene, params));
  params.search.global_search = false;
  params.local.max_translation = 0.0;
  expect_same(ModelAligner(model, params).align(scene), align(model, scene, params));
  EXPECT_EQ(ModelAligner(model, params).model_coefficients().size(),
            params.scene.bandwidth * params.scene.bandwidth);
}

TEST(ModelAligner, RefusesBadInput) {
  std::mt19937 rng(15);
  const PointCloud model = test::box_and_sphere(2000, rng);
  EXPECT_THROW(ModelAligner(PointCloud(), servo_params()), std::invalid_argument);
  EXPECT_THROW(ModelAligner(PointCloud(model.points()), servo_params()),
               std::invalid_argument);  // no normals
  AlignParams params = servo_params();
  params.scene.bandwidth = 1;
  EXPECT_THROW(ModelAligner(model, params), std::invalid_argument);
  ModelAligner aligner(model, servo_params());
  EXPECT_THROW(aligner.align(PointCloud()), std::invalid_argument);
  EXPECT_THROW(aligner.align(PointCloud(model.points())), std::invalid_argument);
  Transform bad = Transform::Identity();
  bad(3, 0) = 1.0;
  EXPECT_THROW(aligner.align(model, bad), std::invalid_argument);
  params = servo_params();
  params.limits.max_voxels = 1000;
  ModelAligner small(model, params);
  EXPECT_THROW(small.align(model), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
