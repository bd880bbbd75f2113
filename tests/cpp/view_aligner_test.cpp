// align_views on two views cut from one real Kinect scan (disjoint pixels, the current
// moved by a known transform), its scale rule against closed forms, and its errors.
#include <spectral_vs/alignment/view_aligner.hpp>
#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/rotation/so3.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "test_support.hpp"

namespace spectral_vs {
namespace {

constexpr int kWidth = 640, kHeight = 480;

// The finite points of the scan's pixels in [u0, u0 + w) x [v0, v0 + h) whose u + v has
// the given parity, every second row and column (a 320 x 240 camera), with normals from
// 20 neighbours toward the sensor at the origin, moved by T.
PointCloud view_of(const Points& scan, int u0, int v0, int w, int h, int parity,
                   const Transform& T) {
  Points points(Eigen::Index(w) * h, 3);
  Eigen::Index n = 0;
  for (int v = v0; v < v0 + h; v += 2) {
    for (int u = u0; u < u0 + w; u += 2) {
      if (((u / 2 + v / 2) & 1) != parity) continue;
      const Eigen::RowVector3d p = scan.row(Eigen::Index(v) * kWidth + u);
      if (p.allFinite()) points.row(n++) = p;
    }
  }
  points.conservativeResize(n, Eigen::NoChange);
  NormalEstimationParams normals;
  normals.k_neighbors = 20;
  return estimate_normals(PointCloud(points), normals).transformed(T);
}

double angle_deg(const Eigen::Matrix3d& R) {
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
}

struct TablePair : ::testing::Test {
  void SetUp() override {
    CloudFileInfo info;
    scan = load_points(test::data_path("milk_cartoon_all_small_clorox.pcd"), &info);
    ASSERT_EQ(info.width, std::size_t(kWidth));
    // The current camera turned by 35 degrees about a tilted axis and moved 0.1 m.
    T_current_scan.topLeftCorner<3, 3>() =
        exp_so3(35.0 * M_PI / 180.0 * Eigen::Vector3d(0.3, 1.0, 0.2).normalized());
    T_current_scan.topRightCorner<3, 1>() = Eigen::Vector3d(0.06, -0.05, 0.06);
    reference = view_of(scan, 0, 0, 480, 360, 0, Transform::Identity());
    current = view_of(scan, 160, 120, 480, 360, 1, T_current_scan);
    params.sensor_origin = T_current_scan.topRightCorner<3, 1>();
  }
  Points scan;
  Transform T_current_scan = Transform::Identity();
  PointCloud reference, current;
  ViewAlignParams params;
};

TEST_F(TablePair, RegistersTwoViewsOfOneScanWithinAMillimetre) {
  const ViewAlignResult result = align_views(reference, current, params);
  const Transform error = T_current_scan.inverse() * result.T_current_reference;
  EXPECT_LT(angle_deg(error.topLeftCorner<3, 3>()), 0.3);  // degrees
  const Eigen::Vector3d offset =
      (result.T_current_reference - T_current_scan).topRightCorner<3, 1>();
  EXPECT_LT(offset.norm(), 0.003);  // metres
  EXPECT_TRUE(result.converged);
  EXPECT_EQ(result.hypotheses.size(), std::size_t(params.hypotheses));
  // The returned pose is the best supported of those refined, and it beats a pose 5
  // degrees off.
  Transform off = T_current_scan;
  off.topLeftCorner<3, 3>() = off.topLeftCorner<3, 3>() * exp_so3(Eigen::Vector3d(0, 0.087, 0));
  EXPECT_GT(result.support.score, view_support(reference, current, off, params).score + 0.05);
  EXPECT_GT(result.support.fitness, 0.5);
}

TEST_F(TablePair, IsDeterministic) {
  const ViewAlignResult a = align_views(reference, current, params);
  const ViewAlignResult b = align_views(reference, current, params);
  EXPECT_EQ(a.T_current_reference, b.T_current_reference);
  EXPECT_EQ(a.support.score, b.support.score);
}

// The window search forced to run (its threshold over any score) on a pair the search
// registers: its hypotheses are checked and added, and the right pose is kept, to the bit,
// since a window's pose replaces it only when better supported.
TEST_F(TablePair, TheWindowSearchKeepsARightPose) {
  params.window_search_below = 0.0;
  const ViewAlignResult searched = align_views(reference, current, params);
  params.window_search_below = 1.0;
  const ViewAlignResult windowed = align_views(reference, current, params);
  EXPECT_EQ(searched.windows, 0);
  EXPECT_GT(windowed.windows, 4);
  EXPECT_GT(windowed.hypotheses.size(), searched.hypotheses.size());
  EXPECT_EQ(windowed.T_current_reference, searched.T_current_reference);
  EXPECT_EQ(windowed.support.score, searched.support.score);
  EXPECT_LT(windowed.hypothesis, params.hypotheses);  // one of the search's
  for (std::size_t i = 1; i < windowed.hypotheses.size(); ++i) {
    EXPECT_GE(windowed.hypotheses[i - 1].second.score, windowed.hypotheses[i].second.score);
  }
  // Deterministic: the same windows, hypotheses and scores on a second call.
  const ViewAlignResult again = align_views(reference, current, params);
  EXPECT_EQ(again.windows, windowed.windows);
  ASSERT_EQ(again.hypotheses.size(), windowed.hypotheses.size());
  for (std::size_t i = 0; i < again.hypotheses.size(); ++i) {
    EXPECT_EQ(again.hypotheses[i].first, windowed.hypotheses[i].first);
    EXPECT_EQ(again.hypotheses[i].second.score, windowed.hypotheses[i].second.score);
  }
}

TEST_F(TablePair, SupportOfTheTruthIsHighAndOfAWrongPoseLow) {
  const ViewSupport truth = view_support(reference, current, T_current_scan, params);
  const ViewSupport wrong = view_support(reference, current, Transform::Identity(), params);
  EXPECT_GT(truth.overlap, 0.3);  // the windows share 44% of their pixels
  EXPECT_LT(wrong.score, 0.2 * truth.score);
  EXPECT_NEAR(truth.score, truth.fitness * truth.overlap, 1e-12);
  EXPECT_EQ(truth.reference_pixels, truth.confirmed + truth.contradicted + truth.hidden);
}

TEST(ViewScale, FollowsTheClosedForm) {
  // 10000 points spread evenly on a 2 m square: the median distance from the centre of a
  // uniform square of side a is sqrt(1 / (2 pi)) a (the disc of radius r inside the
  // square holds pi r^2 / a^2 of it, a half at r = a / sqrt(2 pi) < a / 2).
  Points points(10000, 3);
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j) points.row(i * 100 + j) << -1.0 + 0.02 * i, -1.0 + 0.02 * j, 3.0;
  const PointCloud view(points, Points::Zero(10000, 3).rowwise() + Eigen::RowVector3d(0, 0, -1));
  const ViewScale scale = view_scale(view, view, 24.0);
  EXPECT_NEAR(scale.extent, 2.0 * 2.0 / std::sqrt(2.0 * M_PI), 0.01);  // metres
  EXPECT_NEAR(scale.voxel_size, scale.extent / 24.0, 1e-12);
  EXPECT_DOUBLE_EQ(scale.search_voxel_size, 2.0 * scale.voxel_size);
  // A sparse view: 3 extent / sqrt(N) takes over.
  const PointCloud sparse(points.topRows(100),
                          Points::Zero(100, 3).rowwise() + Eigen::RowVector3d(0, 0, -1));
  const ViewScale coarse = view_scale(sparse, sparse, 24.0);
  EXPECT_NEAR(coarse.voxel_size, 3.0 * coarse.extent / 10.0, 1e-12);
}

TEST(AlignViews, RefusesBadInput) {
  std::mt19937 rng(3);
  const PointCloud view = test::box_and_sphere(2000, rng);
  const auto message = [&](const PointCloud& a, const PointCloud& b, const ViewAlignParams& p) {
    try {
      align_views(a, b, p);
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(PointCloud(), view, {}).find("reference"), std::string::npos);
  EXPECT_NE(message(view, PointCloud(view.points()), {}).find("current"), std::string::npos);
  ViewAlignParams p;
  p.hypotheses = 0;
  EXPECT_NE(message(view, view, p).find("hypotheses"), std::string::npos);
  p = {};
  p.refinements = 20;
  EXPECT_NE(message(view, view, p).find("refinements"), std::string::npos);
  p = {};
  p.voxel_size = -1.0;
  EXPECT_NE(message(view, view, p).find("voxel_size"), std::string::npos);
  p = {};
  p.sensor_origin.x() = NAN;
  EXPECT_NE(message(view, view, p).find("sensor_origin"), std::string::npos);
  p = {};
  p.voxels_across = 2.0;
  EXPECT_NE(message(view, view, p).find("voxels_across"), std::string::npos);
  for (const double below : {-0.1, 1.5, double(NAN)}) {
    p = {};
    p.window_search_below = below;
    EXPECT_NE(message(view, view, p).find("window_search_below must be in [0, 1]"),
              std::string::npos);
  }
  Transform not_rigid = Transform::Identity();
  not_rigid(0, 0) = 2.0;
  EXPECT_THROW(view_support(view, view, not_rigid), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
