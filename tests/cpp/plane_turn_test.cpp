#include <spectral_vs/alignment/plane_turn.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace spectral_vs {
namespace {

constexpr double kDeg = M_PI / 180.0;

// A table top's normals (up, 60% of the view) under a box and a sphere: the servo's view
// of a cluttered table, whose plane leaves the rotation about its normal to the objects.
PointCloud table_view() {
  std::mt19937 rng(7);
  const PointCloud objects = test::box_and_sphere(4000, rng);
  const Eigen::Index table = 6000;
  Points points(Eigen::Index(objects.size()) + table, 3), normals(points.rows(), 3);
  points.topRows(objects.size()) = objects.points();
  normals.topRows(objects.size()) = objects.normals();
  std::uniform_real_distribution<double> uniform(-0.3, 0.3);
  for (Eigen::Index i = objects.size(); i < points.rows(); ++i) {
    points.row(i) << uniform(rng), uniform(rng), -0.1;
    normals.row(i) << 0.0, 0.0, 1.0;
  }
  return PointCloud(points, normals);
}

PointCloud turned(const PointCloud& cloud, const Eigen::Matrix3d& R) {
  return PointCloud(cloud.points() * R.transpose(), cloud.normals() * R.transpose());
}

Eigen::Matrix3d about(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * kDeg, axis.normalized()).toRotationMatrix();
}

TEST(PlaneTurn, FindsTheTablesNormal) {
  const auto turn = PlaneTurn::of(table_view(), PlaneTurnParams{});
  ASSERT_TRUE(turn.has_value());
  EXPECT_LT(std::acos(std::min(1.0, turn->axis().z())), 0.1 * kDeg);
}

// The current view is the reference turned about the table's normal by `degrees`. Near
// the goal, where the off-plane EGIs' correlation is concave along the normal (within
// about a third of its peak's width, pi / B = 11 degrees at B = 16), the turn from R = I
// is a Newton step that takes most of the way, and a second from where it ended the rest.
TEST(PlaneTurn, TakesTheTurnAboutTheTableNormal) {
  const PointCloud reference = table_view();
  const auto turn = PlaneTurn::of(reference, PlaneTurnParams{});
  ASSERT_TRUE(turn.has_value());
  for (const double degrees : {-4.0, -2.0, 1.0, 3.0, 4.0}) {
    const PointCloud current = turned(reference, about(Eigen::Vector3d::UnitZ(), degrees));
    const double first = turn->turn(current, Eigen::Matrix3d::Identity()) / kDeg;
    EXPECT_NEAR(first, degrees, 0.25 * std::abs(degrees)) << degrees << " degrees";
    const double second = turn->turn(current, about(turn->axis(), first)) / kDeg;
    EXPECT_NEAR(first + second, degrees, 0.2) << degrees << " degrees";
  }
}

// Farther off the step is the gradient law's, capped at max_rotation_step: toward the
// goal, never more than the cap.
TEST(PlaneTurn, FarOffItStepsTowardTheGoalWithinTheCap) {
  const PointCloud reference = table_view();
  const auto turn = PlaneTurn::of(reference, PlaneTurnParams{});
  ASSERT_TRUE(turn.has_value());
  const double cap = PlaneTurnParams{}.law.local.max_rotation_step;
  for (const double degrees : {-8.0, -6.0, 6.0, 8.0}) {
    const PointCloud current = turned(reference, about(Eigen::Vector3d::UnitZ(), degrees));
    const double step = turn->turn(current, Eigen::Matrix3d::Identity());
    EXPECT_GT(step * degrees, 0.0) << degrees << " degrees";
    EXPECT_LE(std::abs(step), cap + 1e-12) << degrees << " degrees";
  }
}

TEST(PlaneTurn, NoTurnWhileTheViewIsTiltedPastMaxTilt) {
  const PointCloud reference = table_view();
  const auto turn = PlaneTurn::of(reference, PlaneTurnParams{});
  ASSERT_TRUE(turn.has_value());
  const Eigen::Matrix3d tilt =
      about(Eigen::Vector3d::UnitX(), 10.0) * about(Eigen::Vector3d::UnitZ(), 4.0);
  EXPECT_EQ(turn->turn(turned(reference, tilt), Eigen::Matrix3d::Identity()), 0.0);
  // Within max_tilt of where the estimate puts the plane it turns again.
  EXPECT_NE(turn->turn(turned(reference, tilt), about(Eigen::Vector3d::UnitX(), 10.0)), 0.0);
}

TEST(PlaneTurn, NoneWithoutADominantPlaneOrWithoutNormalsOffIt) {
  std::mt19937 rng(3);
  EXPECT_FALSE(PlaneTurn::of(test::box_and_sphere(4000, rng), PlaneTurnParams{}).has_value());
  // Only the table: no normal off it.
  const PointCloud reference = table_view();
  Points up = Points::Zero(500, 3);
  up.col(2).setOnes();
  EXPECT_FALSE(PlaneTurn::of(PointCloud(up, up), PlaneTurnParams{}).has_value());
  // A current view of the table alone gives no turn.
  const auto turn = PlaneTurn::of(reference, PlaneTurnParams{});
  ASSERT_TRUE(turn.has_value());
  EXPECT_EQ(turn->turn(PointCloud(up, up), Eigen::Matrix3d::Identity()), 0.0);
}

TEST(PlaneTurn, RefusesSettingsOutOfRangeNamingThem) {
  const PointCloud reference = table_view();
  const auto message = [&](PlaneTurnParams params) {
    try {
      PlaneTurn::of(reference, params);
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  PlaneTurnParams p;
  p.plane_cone = 0.0;
  EXPECT_NE(message(p).find("plane_cone"), std::string::npos);
  p = PlaneTurnParams{};
  p.stride = 0;
  EXPECT_NE(message(p).find("stride"), std::string::npos);
  p = PlaneTurnParams{};
  p.fine_bandwidth = 65;
  EXPECT_NE(message(p).find("fine_bandwidth"), std::string::npos);
  EXPECT_THROW(PlaneTurn::of(PointCloud(reference.points()), PlaneTurnParams{}),
               std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
