#include <spectral_vs/representation/organized.hpp>
#include <spectral_vs/representation/preprocessing.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>

namespace spectral_vs {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const PinholeIntrinsics kCamera{100.0, 100.0, 31.5, 23.5};

// The depth image of the plane n . x = d (camera frame): along the ray (a, b, 1) of
// pixel (v, u), x = z (a, b, 1) with z = d / (n . (a, b, 1)).
DepthImage plane_depth(const Eigen::Vector3d& n, double d, int height = 48, int width = 64) {
  DepthImage depth(height, width);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d ray((u - kCamera.cx) / kCamera.fx, (v - kCamera.cy) / kCamera.fy, 1.0);
      depth(v, u) = d / n.dot(ray);
    }
  return depth;
}

TEST(OrganizedCloud, PlaneGivesItsPointsAndNormalTowardTheCamera) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, -1.0).normalized();  // faces the camera
  const DepthImage depth = plane_depth(n, -0.8 * std::abs(n.z()));
  const PointCloud cloud = organized_cloud(depth, kCamera);
  // Every pixel but the border of normal_step = 2.
  ASSERT_EQ(cloud.size(), std::size_t(44 * 60));
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    const Eigen::Vector3d p = cloud.points().row(i).transpose();
    EXPECT_NEAR(n.dot(p), -0.8 * std::abs(n.z()), 1e-12);  // on the plane
    EXPECT_NEAR((cloud.normals().row(i).transpose() - n).norm(), 0.0, 1e-9);
    EXPECT_GT(cloud.normals().row(i).dot(-p.transpose()), 0.0);  // toward the camera
  }
  // The first kept pixel is (2, 2): its point is the back-projection of that pixel.
  const double z = depth(2, 2);
  EXPECT_NEAR(cloud.points()(0, 0), z * (2 - kCamera.cx) / kCamera.fx, 1e-15);
  EXPECT_NEAR(cloud.points()(0, 1), z * (2 - kCamera.cy) / kCamera.fy, 1e-15);
  EXPECT_EQ(cloud.points()(0, 2), z);
}

TEST(OrganizedCloud, NormalsFlipTowardTheCameraWhateverTheWinding) {
  // The same plane with its normal given away from the camera: the output still faces it.
  const Eigen::Vector3d n = Eigen::Vector3d(-0.1, 0.4, 1.0).normalized();
  const PointCloud cloud = organized_cloud(plane_depth(n, 0.9 * n.z()), kCamera);
  ASSERT_GT(cloud.size(), 0u);
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    EXPECT_NEAR((cloud.normals().row(i).transpose() + n).norm(), 0.0, 1e-9);
  }
}

TEST(OrganizedCloud, StrideKeepsEveryStrideThPixelWithTheSameValues) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, 0.1, -1.0).normalized();
  DepthImage depth = plane_depth(n, -0.7 * std::abs(n.z()));
  depth(20, 30) = kNaN;  // a hole: its neighbours within the stencil lose their normals
  const PointCloud all = organized_cloud(depth, kCamera);
  OrganizedNormalParams params;
  params.stride = 3;
  const PointCloud some = organized_cloud(depth, kCamera, params);
  // Each kept point is the full cloud's point of the same pixel (found by its position).
  std::map<std::tuple<double, double, double>, Eigen::Index> row_of;
  for (Eigen::Index i = 0; i < Eigen::Index(all.size()); ++i) {
    row_of[{all.points()(i, 0), all.points()(i, 1), all.points()(i, 2)}] = i;
  }
  std::size_t expected = 0;
  for (int v = 3; v < 46; v += 3)
    for (int u = 3; u < 62; u += 3) {
      // The hole and the pixels whose stencil (2 pixels along the row or column) has it.
      const bool hole_near =
          (v == 20 && (u == 28 || u == 30 || u == 32)) || (u == 30 && (v == 18 || v == 22));
      expected += !hole_near;
    }
  ASSERT_EQ(some.size(), expected);
  for (Eigen::Index i = 0; i < Eigen::Index(some.size()); ++i) {
    const auto found = row_of.find({some.points()(i, 0), some.points()(i, 1), some.points()(i, 2)});
    ASSERT_NE(found, row_of.end());
    EXPECT_EQ((some.normals().row(i) - all.normals().row(found->second)).norm(), 0.0);
  }
}

TEST(OrganizedCloud, DepthJumpsAndMissingPixelsHaveNoNormal) {
  // Two planes at 0.5 m (left) and 0.8 m (right): the columns within normal_step of the
  // edge see a jump of 60% > max_depth_jump and are dropped; NaN pixels too.
  DepthImage depth(20, 40);
  for (int u = 0; u < 40; ++u) depth.col(u).setConstant(u < 20 ? 0.5 : 0.8);
  depth(10, 5) = kNaN;
  const PointCloud cloud = organized_cloud(depth, kCamera);
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    const double u = cloud.points()(i, 0) / cloud.points()(i, 2) * kCamera.fx + kCamera.cx;
    EXPECT_TRUE(std::abs(u - 19.5) > 2.0) << "column " << u;
    EXPECT_NEAR(cloud.normals()(i, 2), -1.0, 1e-12);
  }
  // Rows 2..17 by columns 2..17 and 22..37, less the hole and its four stencil neighbours
  // (the pixel and those 2 pixels away along its row and column).
  EXPECT_EQ(cloud.size(), std::size_t(16 * 16 * 2 - 5));
}

TEST(OrganizedCloud, SmallOrEmptyImagesGiveEmptyClouds) {
  EXPECT_EQ(organized_cloud(DepthImage::Constant(4, 40, 1.0), kCamera).size(), 0u);
  EXPECT_EQ(organized_cloud(DepthImage::Constant(30, 40, kNaN), kCamera).size(), 0u);
}

TEST(OrganizedCloud, RefusesBadParameters) {
  const DepthImage depth = DepthImage::Constant(10, 10, 1.0);
  OrganizedNormalParams params;
  EXPECT_THROW(organized_cloud(depth, {0.0, 1.0, 0.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(organized_cloud(depth, {1.0, kNaN, 0.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(organized_cloud(depth, {1.0, 1.0, kNaN, 0.0}), std::invalid_argument);
  params.window = 4;
  EXPECT_THROW(organized_cloud(depth, kCamera, params), std::invalid_argument);
  params = {};
  params.normal_step = 0;
  EXPECT_THROW(organized_cloud(depth, kCamera, params), std::invalid_argument);
  params = {};
  params.stride = 0;
  EXPECT_THROW(organized_cloud(depth, kCamera, params), std::invalid_argument);
  params = {};
  params.max_depth_jump = 0.0;
  EXPECT_THROW(organized_cloud(depth, kCamera, params), std::invalid_argument);
}

TEST(VoxelDownsample, EqualsCentroidsPerVoxelInVoxelOrder) {
  // An independent reference: std::map keyed by (z, y, x) voxel indices.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coordinate(-0.3, 0.5), direction(-1.0, 1.0);
  Points points(3000, 3), normals(3000, 3);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    points.row(i) << coordinate(rng), coordinate(rng), coordinate(rng);
    normals.row(i) << 0.2 * direction(rng), 0.2 * direction(rng), 1.0;
  }
  const double voxel = 0.05;
  const PointCloud reduced = voxel_downsample(PointCloud(points, normals), voxel);
  struct Sum {
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
    int count = 0;
  };
  std::map<std::tuple<long, long, long>, Sum> voxels;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const auto key = std::make_tuple(long(std::floor(points(i, 2) / voxel)),
                                     long(std::floor(points(i, 1) / voxel)),
                                     long(std::floor(points(i, 0) / voxel)));
    Sum& sum = voxels[key];
    sum.p += points.row(i).transpose();
    sum.n += normals.row(i).normalized().transpose();
    ++sum.count;
  }
  ASSERT_EQ(reduced.size(), voxels.size());
  Eigen::Index row = 0;
  for (const auto& [key, sum] : voxels) {
    EXPECT_NEAR((reduced.points().row(row).transpose() - sum.p / sum.count).norm(), 0.0, 1e-12);
    EXPECT_NEAR((reduced.normals().row(row).transpose() - sum.n.normalized()).norm(), 0.0, 1e-12);
    ++row;
  }
}

}  // namespace
}  // namespace spectral_vs
