// align_views()'s stages on their own (view_stages.hpp), each against a known motion
// rather than through align_views(): the hypotheses of the SO(3) search placed by phase
// correlation, and the refinement (Algorithm 1, then the ICP) from one hypothesis.

#include <spectral_vs/alignment/view_aligner.hpp>

#include "alignment/view_stages.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <random>
#include <vector>

namespace spectral_vs::detail::views {
namespace {

constexpr double kDeg = M_PI / 180.0;

Eigen::Matrix3d about(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * kDeg, axis.normalized()).toRotationMatrix();
}

// A camera 0.7 m above a table (along +z) with a box, a sphere and a second box on it:
// the surfaces that face the camera, which sits at the origin.
PointCloud table_view(std::mt19937& rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<Eigen::RowVector3d> points, normals;
  for (int i = 0; i < 20000; ++i) {
    points.emplace_back(0.4 * uniform(rng), 0.3 * uniform(rng), 0.7);
    normals.emplace_back(0.0, 0.0, -1.0);
  }
  const PointCloud object = test::box_and_sphere(12000, rng);
  for (const auto& [R, t] : {std::pair{about({0, 0, 1}, 30.0), Eigen::Vector3d(-0.1, 0.0, 0.6)},
                             std::pair{about({1, 1, 0}, 90.0), Eigen::Vector3d(0.2, 0.1, 0.62)}}) {
    for (std::size_t i = 0; i < object.size(); ++i) {
      const Eigen::Vector3d p = R * object.points().row(Eigen::Index(i)).transpose() + t;
      const Eigen::Vector3d n = R * object.normals().row(Eigen::Index(i)).transpose();
      if (n.dot(-p) <= 0.0 || p.z() >= 0.7) continue;  // facing away, or under the table
      points.push_back(p.transpose());
      normals.push_back(n.transpose());
    }
  }
  Points p(Eigen::Index(points.size()), 3), n(p.rows(), 3);
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    p.row(i) = points[std::size_t(i)];
    n.row(i) = normals[std::size_t(i)];
  }
  return PointCloud(p, n);
}

// The reference view, and the current: the same scene sampled again, seen from a camera
// moved by T_current_reference (its sensor at that motion's translation, as the scan
// pairs of spectral_vs.data have it).
struct MovedView {
  PointCloud reference, current;
  Transform T_current_reference = Transform::Identity();
  ViewAlignParams params;

  MovedView() {
    std::mt19937 rng(11);
    reference = table_view(rng);
    T_current_reference.topLeftCorner<3, 3>() = about({0.3, -0.2, 1.0}, 25.0);
    T_current_reference.topRightCorner<3, 1>() << 0.05, -0.03, 0.02;
    current = table_view(rng).transformed(T_current_reference);
    params.sensor_origin = T_current_reference.topRightCorner<3, 1>();
  }

  std::pair<double, double> error(const Transform& T) const {
    return test::pose_error(T, T_current_reference, reference.centroid());
  }
};

TEST(ViewHypotheses, TheBestSupportedIsTheTrueMotionWithinTheSearchGrid) {
  const MovedView pair;
  const ViewScale scale = view_scale(pair.reference, pair.current, pair.params.voxels_across);
  PreparedViews prepared(pair.reference, pair.current, pair.params, scale, Clock::now());
  const Views views = prepared.views();
  const std::vector<Hypothesis> ranked = hypotheses(views);
  ASSERT_FALSE(ranked.empty());
  for (std::size_t i = 0; i < ranked.size(); ++i) {
    if (i > 0) {
      EXPECT_GE(ranked[i - 1].support.score, ranked[i].support.score) << "best first";
    }
    EXPECT_EQ(ranked[i].fitness, ranked[i].support.score) << "ranked by its support";
  }
  const auto [degrees, metres] = pair.error(views.model.transform_of(ranked.front().pose));
  EXPECT_LT(degrees, 5.0);
  EXPECT_LT(metres, 2.0 * scale.search_voxel_size);
}

TEST(ViewRefinement, FromAHypothesisOffTheTruthReachesIt) {
  const MovedView pair;
  const ViewScale scale = view_scale(pair.reference, pair.current, pair.params.voxels_across);
  PreparedViews prepared(pair.reference, pair.current, pair.params, scale, Clock::now());
  const Views views = prepared.views();
  Transform start = pair.T_current_reference;
  start.topLeftCorner<3, 3>() = about({1.0, 0.5, 0.2}, 4.0) * start.topLeftCorner<3, 3>();
  start.topRightCorner<3, 1>() += Eigen::Vector3d(0.006, 0.004, -0.005);
  Hypothesis hypothesis;
  hypothesis.pose = views.model.pose_of(start);
  hypothesis.support = views.support.of(start, kCoarseTolerance);
  const ViewAlignResult result = refine(views, hypothesis);
  const auto [degrees, metres] = pair.error(result.T_current_reference);
  EXPECT_LT(degrees, 0.5);
  EXPECT_LT(metres, 0.002);
  EXPECT_GT(result.support.score, views.support.of(start, kFineTolerance).score);
}

}  // namespace
}  // namespace spectral_vs::detail::views
