// The pose verification (verify_pose, AlignResult::confidence / inliers / inlier_rmse)
// on hand-computed cases, and the alternatives of align() for a symmetric box.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verdict.hpp>
#include <spectral_vs/alignment/verification.hpp>
#include <spectral_vs/rotation/so3.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "test_support.hpp"

namespace spectral_vs {
namespace {

constexpr double kMm = 1e-3;

PointCloud cloud_of(const std::vector<Eigen::Vector3d>& points,
                    const std::vector<Eigen::Vector3d>& normals) {
  Points p(Eigen::Index(points.size()), 3), n(Eigen::Index(points.size()), 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    p.row(Eigen::Index(i)) = points[i].transpose();
    n.row(Eigen::Index(i)) = normals[i].transpose();
  }
  return PointCloud(p, n);
}

const Eigen::Vector3d kUp(0.0, 0.0, 1.0);

// Three scene points on the plane z = 0 (normals +z) and five model points: by hand,
// distances 3, 6, 5 and 1 mm to their nearest scene points (inliers at d = 8 mm) and one
// 300 mm off; point-to-plane within 4 mm and turned the same way: the first and third.
TEST(VerifyPose, InliersRmseAndTightCountsMatchHandComputation) {
  const PointCloud scene =
      cloud_of({{0.0, 0.0, 0.0}, {0.1, 0.0, 0.0}, {0.2, 0.0, 0.0}}, {kUp, kUp, kUp});
  const PointCloud model = cloud_of(
      {{0.0, 0.0, 0.003}, {0.1, 0.0, 0.006}, {0.2, 0.005, 0.0}, {0.5, 0.0, 0.0}, {0.0, 0.0, 0.001}},
      {kUp, kUp, kUp, kUp, -kUp});
  VerifyParams params;
  params.voxel_size = 0.008;
  const PoseVerification v = verify_pose(model, scene, Transform::Identity(), params);
  EXPECT_DOUBLE_EQ(v.inlier_distance, 0.008);
  EXPECT_EQ(v.inliers, 4);
  EXPECT_NEAR(v.inlier_rmse, std::sqrt((9.0 + 36.0 + 25.0 + 1.0) / 4.0) * kMm, 1e-9);
  EXPECT_NEAR(v.inlier_fraction, 0.8, 1e-12);
  EXPECT_EQ(v.visible, 5);  // no viewpoint: every model point
  EXPECT_EQ(v.tight, 2);    // the 6 mm one is too far, the last is turned away
  EXPECT_EQ(v.seen_through, 0);
  EXPECT_EQ(v.hidden, 0);
  EXPECT_NEAR(v.confidence, 2.0 / 5.0, 1e-12);
  EXPECT_NEAR(confidence_of(v), v.confidence, 1e-15);
}

TEST(VerifyPose, CountsFollowThePoseNotTheModelFrame) {
  std::mt19937 rng(7);
  const PointCloud model = test::box_and_sphere(2000, rng);
  const PointCloud scene = model.transformed(test::translation({0.001, -0.002, 0.0015}));
  Transform A = Transform::Identity();
  A.topLeftCorner<3, 3>() = exp_so3(Eigen::Vector3d(0.3, -1.1, 0.7));
  A.topRightCorner<3, 1>() = Eigen::Vector3d(0.5, 0.2, -0.3);
  const Transform T = test::translation({0.001, -0.002, 0.0015});
  const PoseVerification direct = verify_pose(model, scene, T);
  const PoseVerification moved = verify_pose(model.transformed(A), scene, T * A.inverse());
  EXPECT_EQ(direct.inliers, moved.inliers);
  EXPECT_EQ(direct.tight, moved.tight);
  EXPECT_NEAR(direct.inlier_rmse, moved.inlier_rmse, 1e-9);
  // The exact copy, moved by T: every point is its own scene point.
  EXPECT_EQ(direct.inliers, int(model.size()));
  EXPECT_LT(direct.inlier_rmse, 1e-9);
  EXPECT_DOUBLE_EQ(direct.confidence, 1.0);
}

// A scanned wall at z = 1 m (2 mm grid, normals toward the sensor at the origin) and
// four model points: on it, 50 mm in front of it (the sensor saw through it), 50 mm
// behind it (hidden), and one turned away from the sensor.
TEST(VerifyPose, ViewpointSortsPointsIntoVisibleSeenThroughAndHidden) {
  std::vector<Eigen::Vector3d> points, normals;
  for (int i = -50; i <= 50; ++i)
    for (int j = -50; j <= 50; ++j) {
      points.emplace_back(0.002 * i, 0.002 * j, 1.0);
      normals.emplace_back(-kUp);
    }
  const PointCloud scene = cloud_of(points, normals);
  const PointCloud model = cloud_of(
      {{0.011, 0.011, 1.001}, {0.021, 0.001, 0.95}, {-0.021, 0.011, 1.05}, {0.0, -0.02, 1.0}},
      {-kUp, -kUp, -kUp, kUp});
  VerifyParams params;
  params.voxel_size = 0.008;
  params.viewpoint = Eigen::Vector3d::Zero();
  const PoseVerification v = verify_pose(model, scene, Transform::Identity(), params);
  EXPECT_EQ(v.visible, 2);
  EXPECT_EQ(v.tight, 1);
  EXPECT_EQ(v.seen_through, 1);
  EXPECT_EQ(v.hidden, 1);
  EXPECT_EQ(v.inliers, 2);  // the one on the wall and the turned one (normals ignored)
  EXPECT_NEAR(v.confidence, 0.5 * (1.0 - 0.5), 1e-12);
}

TEST(VerifyPose, BadInputNamesTheArgument) {
  std::mt19937 rng(1);
  const PointCloud cloud = test::box_and_sphere(200, rng);
  VerifyParams params;
  params.voxel_size = 0.0;
  EXPECT_THROW(verify_pose(cloud, cloud, Transform::Identity(), params), std::invalid_argument);
  Transform skewed = Transform::Identity();
  skewed(0, 1) = 0.5;
  EXPECT_THROW(verify_pose(cloud, cloud, skewed), std::invalid_argument);
  params = {};
  params.viewpoint = Eigen::Vector3d(NAN, 0.0, 0.0);
  EXPECT_THROW(verify_pose(cloud, cloud, Transform::Identity(), params), std::invalid_argument);
  EXPECT_THROW(verify_pose(PointCloud(), cloud, Transform::Identity()), std::invalid_argument);
}

double degrees_apart(const Transform& a, const Transform& b) {
  return rotation_distance(a.topLeftCorner<3, 3>(), b.topLeftCorner<3, 3>()) * 180.0 / M_PI;
}

Transform true_pose() {
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() = exp_so3(Eigen::Vector3d(0.4, 1.2, -0.5));
  T.topRightCorner<3, 1>() = Eigen::Vector3d(0.03, -0.02, 0.01);
  return T;
}

// --- The servo's step score ------------------------------------------------------------

// A current view whose returns span x/z and y/z in [-0.5, 0.5] (a 2 x 2 grid at 1 m), and
// a reference of four points: two inside that field at 1 m, one outside it, one behind.
struct Field {
  Points current = Points(4, 3), reference = Points(4, 3);
  Field() {
    current << -0.5, -0.5, 1.0, 0.5, -0.5, 1.0, -0.5, 0.5, 1.0, 0.5, 0.5, 1.0;
    reference << 0.0, 0.0, 1.0, 0.2, 0.1, 2.0, 3.0, 0.0, 1.0, 0.0, 0.0, -1.0;
  }
};

TEST(StepScore, IsTheVisibleFitnessFromTheThresholdUpAndReadsNoField) {
  StepScoreParams params;
  params.relocalize_fitness = 0.8;
  const Points none(0, 3);
  for (const double fitness : {0.8, 0.93, 1.0}) {
    EXPECT_FALSE(step_score_needs_field(fitness, params));
    // Empty clouds: a read of the field would give a share of 0, and a score under 1.
    const StepScore s = step_score(fitness, false, none, Transform::Identity(), none, params);
    EXPECT_EQ(s.score, fitness);
    EXPECT_EQ(s.confidence, calibrated_confidence(fitness, RegistrationKind::servo_step));
    EXPECT_EQ(step_score(fitness, true, none, Transform::Identity(), none, params).confidence,
              calibrated_confidence(fitness, RegistrationKind::servo_carried));
  }
}

TEST(StepScore, UnderTheThresholdDividesByTheShareInTheFieldAtLeastTheFloor) {
  const Field field;
  StepScoreParams params;
  params.relocalize_fitness = 0.8;
  params.min_field_share = 0.3;
  EXPECT_TRUE(step_score_needs_field(0.6, params));
  // Two of the four reference points are in the field: 0.6 / 0.5.
  EXPECT_NEAR(
      step_score(0.6, false, field.reference, Transform::Identity(), field.current, params).score,
      1.0, 1e-12);
  EXPECT_NEAR(
      step_score(0.3, false, field.reference, Transform::Identity(), field.current, params).score,
      0.6, 1e-12);
  // Nearer than max_depth only: one in the field, a share of 0.25 counts as 0.3.
  params.max_depth = 1.5;
  EXPECT_NEAR(
      step_score(0.15, false, field.reference, Transform::Identity(), field.current, params).score,
      0.5, 1e-12);
  // Moved 10 m aside, none is in the field: the floor.
  Transform aside = Transform::Identity();
  aside(0, 3) = 10.0;
  const StepScore far = step_score(0.15, true, field.reference, aside, field.current, params);
  EXPECT_NEAR(far.score, 0.5, 1e-12);
  EXPECT_EQ(far.confidence, calibrated_confidence(far.score, RegistrationKind::servo_carried));
}

TEST(StepScore, ReadingTheFieldRefusesWhatFieldShareRefuses) {
  const Field field;
  const Points none(0, 3);
  StepScoreParams floor_zero;
  floor_zero.min_field_share = 0.0;
  for (const double fitness : {std::nan(""), -0.1, 1.5}) {
    EXPECT_THROW(step_score(fitness, false, none, Transform::Identity(), none, {}),
                 std::invalid_argument);
  }
  EXPECT_THROW(step_score(0.5, false, none, Transform::Identity(), none, floor_zero),
               std::invalid_argument);
  Points bad = field.current;
  bad(0, 0) = std::nan("");
  EXPECT_THROW(step_score(0.5, false, field.reference, Transform::Identity(), bad, {}),
               std::invalid_argument);
}

TEST(AlignAlternatives, ABoxReportsItsFourHalfTurnPoses) {
  std::mt19937 rng(3);
  const PointCloud model = test::box(4000, rng);
  const PointCloud scene = test::box(4000, rng).transformed(true_pose());
  const AlignResult result = align(model, scene);
  // The half turns map the box onto itself: the same answer, listed but not ambiguous.
  EXPECT_FALSE(result.ambiguous);
  EXPECT_TRUE(result.reliable) << verdict_name(result.status);
  EXPECT_GT(result.score, kConfidenceThreshold);
  std::vector<Transform> reported{result.T_scene_model};
  for (const AlignAlternative& a : result.alternatives) reported.push_back(a.T_scene_model);
  // Each of the box's four equal poses is among the reported ones, within 5 degrees and
  // 10 mm (its centroid is the model origin).
  const std::vector<Eigen::Vector3d> half_turns{
      Eigen::Vector3d::Zero(), {M_PI, 0.0, 0.0}, {0.0, M_PI, 0.0}, {0.0, 0.0, M_PI}};
  for (const Eigen::Vector3d& axis : half_turns) {
    Transform S = Transform::Identity();
    S.topLeftCorner<3, 3>() = exp_so3(axis);
    const Transform T = true_pose() * S;
    bool found = false;
    for (const Transform& R : reported) {
      found |= degrees_apart(R, T) < 5.0 &&
               (R.topRightCorner<3, 1>() - T.topRightCorner<3, 1>()).norm() < 0.010;
    }
    EXPECT_TRUE(found) << "half turn " << axis.transpose();
  }
  for (const AlignAlternative& a : result.alternatives) {
    EXPECT_TRUE(a.symmetric);
    EXPECT_GE(a.score, result.score - 0.05);
    EXPECT_GT(a.rotation_apart * 180.0 / M_PI, 5.0);
    EXPECT_NEAR(a.rotation_apart * 180.0 / M_PI,
                degrees_apart(a.T_scene_model, result.T_scene_model), 1e-6);
  }
}

TEST(AlignAlternatives, AnAsymmetricObjectIsNotAmbiguousAndAWrongPoseScoresLow) {
  std::mt19937 rng(5);
  const PointCloud model = test::box_and_sphere(4000, rng);
  const PointCloud scene = test::box_and_sphere(4000, rng).transformed(true_pose());
  const AlignResult result = align(model, scene);
  ASSERT_LT(degrees_apart(result.T_scene_model, true_pose()), 5.0);
  EXPECT_FALSE(result.ambiguous);
  EXPECT_TRUE(result.alternatives.empty());
  EXPECT_GT(result.confidence, kConfidenceThreshold);
  // Two independent samplings, no noise: for a Poisson sampling of density rho per m^2 the
  // mean squared distance to the nearest sample is 1 / (pi rho): 4.3 mm RMS on the box
  // (2000 points on 0.115 m^2), 2.7 mm on the sphere; the pose adds little to it.
  EXPECT_LT(result.inlier_rmse, 4.3 * kMm);
  EXPECT_GT(result.inlier_rmse, 2.0 * kMm);
  EXPECT_GT(result.inliers, 3000);
  Transform wrong = true_pose();
  wrong.topLeftCorner<3, 3>() = wrong.topLeftCorner<3, 3>() * exp_so3({0.0, 0.0, M_PI / 2});
  EXPECT_LT(verify_pose(model, scene, wrong).confidence, kConfidenceThreshold);
}

TEST(AlignAlternatives, NoneAskedNoneSought) {
  std::mt19937 rng(3);
  const PointCloud model = test::box(2000, rng);
  AlignParams params;
  params.verification.max_alternatives = 0;
  const AlignResult result = align(model, test::box(2000, rng).transformed(true_pose()), params);
  EXPECT_TRUE(result.alternatives.empty());
  EXPECT_FALSE(result.ambiguous);
  params.verification.max_alternatives = 65;
  EXPECT_THROW(align(model, model, params), std::invalid_argument);
  params.verification.max_alternatives = 8;
  params.verification.reselect_margin = 1.5;
  EXPECT_THROW(align(model, model, params), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
