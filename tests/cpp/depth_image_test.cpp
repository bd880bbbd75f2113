// cloud_from_depth against closed forms: a tilted plane and a sphere rendered into depth
// images by ray intersection, in metres and in a sensor's millimetres.
#include <spectral_vs/representation/depth_image.hpp>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

namespace spectral_vs {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

// A Kinect-class camera: 640 x 480, fx = fy = 525 pixels.
constexpr int kWidth = 640, kHeight = 480;
Eigen::Matrix3d kinect() {
  Eigen::Matrix3d K;
  K << 525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0;
  return K;
}

Eigen::Vector3d ray(const Eigen::Matrix3d& K, int v, int u) {
  return {(u - K(0, 2)) / K(0, 0), (v - K(1, 2)) / K(1, 1), 1.0};
}

// The plane n . x = offset: along the ray r of a pixel, x = z r with z = offset / (n . r).
DepthImage plane_depth(const Eigen::Matrix3d& K, const Eigen::Vector3d& n, double offset,
                       int height = kHeight, int width = kWidth) {
  DepthImage depth(height, width);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) depth(v, u) = offset / n.dot(ray(K, v, u));
  return depth;
}

// The nearer intersection of each pixel's ray with the sphere |x - c| = radius (NaN where
// the ray misses): z^2 |r|^2 - 2 z r.c + |c|^2 - radius^2 = 0.
DepthImage sphere_depth(const Eigen::Matrix3d& K, const Eigen::Vector3d& c, double radius) {
  DepthImage depth(kHeight, kWidth);
  for (int v = 0; v < kHeight; ++v)
    for (int u = 0; u < kWidth; ++u) {
      const Eigen::Vector3d r = ray(K, v, u);
      const double a = r.squaredNorm(), b = -2.0 * r.dot(c), e = c.squaredNorm() - radius * radius;
      const double discriminant = b * b - 4.0 * a * e;
      depth(v, u) = discriminant >= 0.0 ? (-b - std::sqrt(discriminant)) / (2.0 * a) : kNaN;
    }
  return depth;
}

RawDepthImage to_millimetres(const DepthImage& depth) {
  RawDepthImage raw(depth.rows(), depth.cols());
  for (Eigen::Index v = 0; v < depth.rows(); ++v)
    for (Eigen::Index u = 0; u < depth.cols(); ++u)
      raw(v, u) = std::isfinite(depth(v, u)) ? std::uint16_t(std::lround(1000.0 * depth(v, u))) : 0;
  return raw;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / kPi;
}

// The pixel (v, u) a camera-frame point projects to.
Eigen::Vector2d pixel_of(const Eigen::Matrix3d& K, const Eigen::Vector3d& p) {
  return {K(1, 1) * p.y() / p.z() + K(1, 2), K(0, 0) * p.x() / p.z() + K(0, 2)};
}

template <typename Call>
std::string error_of(Call&& call) {
  try {
    call();
  } catch (const std::invalid_argument& error) {
    return error.what();
  }
  return "(no error)";
}

TEST(CloudFromDepth, TiltedPlaneInMetresGivesItsPointsAndNormal) {
  const Eigen::Matrix3d K = kinect();
  // 25 degrees off the optical axis, 0.9 m from the camera along its normal.
  const Eigen::Vector3d n =
      Eigen::Vector3d(std::sin(25.0 * kPi / 180.0), 0.0, -std::cos(25.0 * kPi / 180.0));
  const double offset = -0.9;
  const DepthImage depth = plane_depth(K, n, offset);
  const PointCloud cloud = cloud_from_depth(depth, K);
  // Every pixel but the border of normal_step = 2 pixels.
  ASSERT_EQ(cloud.size(), std::size_t((kHeight - 4) * (kWidth - 4)));
  double worst_distance = 0.0, worst_angle = 0.0;
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    const Eigen::Vector3d p = cloud.points().row(i).transpose();
    worst_distance = std::max(worst_distance, std::abs(n.dot(p) - offset));
    worst_angle = std::max(worst_angle, angle_deg(cloud.normals().row(i).transpose(), n));
  }
  EXPECT_LT(worst_distance, 1e-6);  // metres
  EXPECT_LT(worst_angle, 0.5);      // degrees; n faces the camera (n . p < 0)
  // Row-major from pixel (2, 2), each point the back-projection of its pixel.
  const Eigen::Vector3d first = cloud.points().row(0).transpose();
  EXPECT_LT((first - depth(2, 2) * ray(K, 2, 2)).norm(), 1e-12);
  const Eigen::Vector3d next = cloud.points().row(1).transpose();
  EXPECT_LT((next - depth(2, 3) * ray(K, 2, 3)).norm(), 1e-12);
}

TEST(CloudFromDepth, TiltedPlaneInMillimetres) {
  const Eigen::Matrix3d K = kinect();
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.3, -1.0).normalized();
  const double offset = -1.1 * std::abs(n.z());
  const RawDepthImage raw = to_millimetres(plane_depth(K, n, offset));
  const PointCloud cloud = cloud_from_depth(raw, K);  // depth_scale 1000 by default
  ASSERT_EQ(cloud.size(), std::size_t((kHeight - 4) * (kWidth - 4)));
  Eigen::Vector3d mean_normal = Eigen::Vector3d::Zero();
  double worst_pixel = 0.0, worst_depth = 0.0;
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    const Eigen::Vector3d p = cloud.points().row(i).transpose();
    // Each point is its pixel's ray at the stored depth: value / 1000 metres.
    const Eigen::Vector2d px = pixel_of(K, p);
    const int v = int(std::lround(px.x())), u = int(std::lround(px.y()));
    worst_pixel = std::max(worst_pixel, (px - Eigen::Vector2d(v, u)).norm());
    worst_depth = std::max(worst_depth, std::abs(p.z() - raw(v, u) / 1000.0));
    mean_normal += cloud.normals().row(i).transpose();
  }
  EXPECT_LT(worst_pixel, 1e-9);
  EXPECT_LT(worst_depth, 1e-12);
  // The 1 mm steps tilt single normals; their mean is the plane's.
  EXPECT_LT(angle_deg(mean_normal, n), 0.5);
}

TEST(CloudFromDepth, SphereGivesRadialNormalsTowardTheCamera) {
  const Eigen::Matrix3d K = kinect();
  const Eigen::Vector3d c(0.05, -0.03, 1.0);
  const double radius = 0.2;
  const PointCloud cloud = cloud_from_depth(sphere_depth(K, c, radius), K);
  ASSERT_GT(cloud.size(), 30000u);
  double worst_distance = 0.0, worst_facing = 0.0, worst = 0.0;
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    const Eigen::Vector3d p = cloud.points().row(i).transpose();
    const Eigen::Vector3d radial = (p - c).normalized();
    worst_distance = std::max(worst_distance, std::abs((p - c).norm() - radius));
    const double error = angle_deg(cloud.normals().row(i).transpose(), radial);
    worst = std::max(worst, error);
    // Where the surface faces the camera within 60 degrees (away from the silhouette, where
    // the stencil spans a strongly curved, foreshortened patch).
    if (angle_deg(radial, -p) < 60.0) worst_facing = std::max(worst_facing, error);
  }
  EXPECT_LT(worst_distance, 1e-6);
  EXPECT_LT(worst_facing, 0.5);
  EXPECT_LT(worst, 3.0);
}

TEST(CloudFromDepth, InvalidPixelsAreDroppedOrNaN) {
  const Eigen::Matrix3d K = kinect();
  DepthImage depth = DepthImage::Constant(40, 60, 0.8);
  depth(10, 10) = kNaN;
  depth(10, 30) = kInf;
  depth(20, 20) = 0.0;
  depth(30, 40) = -0.5;
  depth(25, 50) = 2.5;  // beyond max_depth below
  DepthCloudParams params;
  params.normals = false;
  // Without normals: every finite, positive pixel.
  EXPECT_EQ(cloud_from_depth(depth, K, params).size(), std::size_t(40 * 60 - 4));
  params.max_depth = 2.0;
  EXPECT_EQ(cloud_from_depth(depth, K, params).size(), std::size_t(40 * 60 - 5));
  params.min_depth = 0.9;  // the wall at 0.8 m is nearer, the pixel at 2.5 m farther
  EXPECT_NE(error_of([&] { cloud_from_depth(depth, K, params); }).find("no valid pixel"),
            std::string::npos);

  // Organized: NaN exactly at the invalid pixels; their neighbours lose their normals.
  params = {};
  params.max_depth = 2.0;
  const OrganizedCloud organized = organized_cloud_from_depth(depth, K, params);
  ASSERT_EQ(organized.height, 40);
  ASSERT_EQ(organized.width, 60);
  ASSERT_EQ(organized.points.rows(), 40 * 60);
  ASSERT_TRUE(organized.has_normals());
  int missing = 0;
  for (Eigen::Index i = 0; i < organized.points.rows(); ++i) {
    missing += !std::isfinite(organized.points(i, 2));
  }
  EXPECT_EQ(missing, 5);
  for (const auto& [v, u] : {std::pair{10, 10}, {10, 30}, {20, 20}, {30, 40}, {25, 50}}) {
    EXPECT_TRUE(std::isnan(organized.points(v * 60 + u, 0)));
    EXPECT_FALSE(organized.valid(v * 60 + u));
    // The pixel normal_step = 2 to the right has the hole in its stencil.
    EXPECT_TRUE(std::isfinite(organized.points(v * 60 + u + 2, 2)));
    EXPECT_TRUE(std::isnan(organized.normals(v * 60 + u + 2, 0)));
  }
  EXPECT_NEAR(organized.normals(5 * 60 + 5, 2), -1.0, 1e-12);  // the wall faces the camera
}

TEST(CloudFromDepth, OrganizedValidCloudIsTheUnorganizedCloud) {
  const Eigen::Matrix3d K = kinect();
  DepthImage depth = sphere_depth(K, {0.0, 0.0, 0.7}, 0.15);
  depth(240, 320) = kNaN;
  for (const int stride : {1, 3}) {
    DepthCloudParams params;
    params.stride = stride;
    const PointCloud cloud = cloud_from_depth(depth, K, params);
    const OrganizedCloud organized = organized_cloud_from_depth(depth, K, params);
    EXPECT_EQ(organized.height, (kHeight + stride - 1) / stride);
    EXPECT_EQ(organized.width, (kWidth + stride - 1) / stride);
    const PointCloud valid = organized.valid_cloud();
    ASSERT_EQ(valid.size(), cloud.size());
    EXPECT_EQ((valid.points() - cloud.points()).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_EQ((valid.normals() - cloud.normals()).cwiseAbs().maxCoeff(), 0.0);
  }
  // With a stride, lattice pixel (i, j) is image pixel (3 i, 3 j) with the full image's
  // normal there.
  DepthCloudParams every, third;
  third.stride = 3;
  const OrganizedCloud full = organized_cloud_from_depth(depth, K, every);
  const OrganizedCloud strided = organized_cloud_from_depth(depth, K, third);
  for (int i = 0; i < strided.height; i += 7)
    for (int j = 0; j < strided.width; j += 5) {
      const Eigen::Index a = Eigen::Index(i) * strided.width + j;
      const Eigen::Index b = Eigen::Index(3 * i) * kWidth + 3 * j;
      for (int k = 0; k < 3; ++k) {
        const double x = strided.points(a, k), y = full.points(b, k);
        EXPECT_TRUE((std::isnan(x) && std::isnan(y)) || x == y);
        const double nx = strided.normals(a, k), ny = full.normals(b, k);
        EXPECT_TRUE((std::isnan(nx) && std::isnan(ny)) || nx == ny);
      }
    }
}

TEST(CloudFromDepth, TheSameSceneInMetresMillimetresAndTumUnits) {
  // A box face at 0.75 m stored three ways: double metres, float metres, uint16 at a
  // depth_scale of 5000 (TUM RGB-D) and at the default 1000.
  const Eigen::Matrix3d K = kinect();
  const DepthImage metres = DepthImage::Constant(30, 40, 0.75);
  const DepthImageF single = metres.cast<float>();
  const RawDepthImage tum = RawDepthImage::Constant(30, 40, 3750);
  const RawDepthImage mm = RawDepthImage::Constant(30, 40, 750);
  DepthCloudParams tum_params;
  tum_params.depth_scale = 5000.0;
  const PointCloud a = cloud_from_depth(metres, K);
  for (const PointCloud& b : {cloud_from_depth(single, K), cloud_from_depth(tum, K, tum_params),
                              cloud_from_depth(mm, K)}) {
    ASSERT_EQ(b.size(), a.size());
    EXPECT_LT((b.points() - a.points()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((b.normals() - a.normals()).cwiseAbs().maxCoeff(), 1e-12);
  }
  // A float image in millimetres, with its scale given.
  DepthCloudParams mm_params;
  mm_params.depth_scale = 1000.0;
  const PointCloud c = cloud_from_depth(DepthImageF(mm.cast<float>()), K, mm_params);
  EXPECT_LT((c.points() - a.points()).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(CloudFromDepth, TheMetricCoreIsOrganizedCloud) {
  // cloud_from_depth on metres is organized_cloud, bit for bit, with any normal settings.
  const Eigen::Matrix3d K = kinect();
  DepthImage depth = sphere_depth(K, {0.1, 0.0, 0.9}, 0.25);
  depth.block(100, 100, 20, 30).setConstant(kNaN);
  DepthCloudParams params;
  params.normal_step = 3;
  params.window = 3;
  params.stride = 2;
  const PointCloud a = cloud_from_depth(depth, K, params);
  const PointCloud b = organized_cloud(depth, intrinsics_from_matrix(K), params);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ((a.points() - b.points()).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((a.normals() - b.normals()).cwiseAbs().maxCoeff(), 0.0);
}

TEST(CloudFromDepth, BadInputNamesTheArgument) {
  const Eigen::Matrix3d K = kinect();
  const DepthImage depth = DepthImage::Constant(10, 10, 1.0);
  auto message = [&](const Eigen::Matrix3d& camera, const DepthCloudParams& params = {}) {
    return error_of([&] { cloud_from_depth(depth, camera, params); });
  };
  auto contains = [](const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
  };
  Eigen::Matrix3d bad = K;
  bad(0, 0) = 0.0;
  EXPECT_TRUE(contains(message(bad), "fx = K[0, 0] > 0")) << message(bad);
  bad = K;
  bad(1, 1) = -525.0;
  EXPECT_TRUE(contains(message(bad), "fy = K[1, 1] > 0")) << message(bad);
  bad = K;
  bad(0, 2) = kNaN;
  EXPECT_TRUE(contains(message(bad), "K must have finite entries")) << message(bad);
  bad = K;
  bad(2, 2) = 0.0;
  EXPECT_TRUE(contains(message(bad), "bottom row")) << message(bad);
  bad = K;
  bad(2, 0) = 1.0;
  EXPECT_TRUE(contains(message(bad), "bottom row")) << message(bad);
  bad = K;
  bad(0, 1) = 0.5;
  EXPECT_TRUE(contains(message(bad), "skew")) << message(bad);
  bad = K.transpose();  // the principal point in the bottom row: a common mistake
  EXPECT_TRUE(contains(message(bad), "bottom row")) << message(bad);

  DepthCloudParams params;
  params.depth_scale = 0.0;
  EXPECT_TRUE(contains(message(K, params), "depth_scale must be finite and > 0"));
  params = {};
  params.min_depth = -1.0;
  EXPECT_TRUE(contains(message(K, params), "min_depth"));
  params = {};
  params.min_depth = 2.0;
  params.max_depth = 1.0;
  EXPECT_TRUE(contains(message(K, params), "max_depth must be > min_depth"));
  params = {};
  params.max_depth = kNaN;
  EXPECT_TRUE(contains(message(K, params), "max_depth"));
  params = {};
  params.window = 4;
  EXPECT_TRUE(contains(message(K, params), "window"));
  params = {};
  params.stride = 0;
  EXPECT_TRUE(contains(message(K, params), "stride"));

  EXPECT_TRUE(contains(error_of([&] { cloud_from_depth(DepthImage(0, 5), K); }), "depth is empty"));
  EXPECT_TRUE(contains(error_of([&] { cloud_from_depth(DepthImage::Constant(10, 10, kNaN), K); }),
                       "no valid pixel"));
  EXPECT_TRUE(contains(error_of([&] { cloud_from_depth(RawDepthImage::Zero(10, 10), K); }),
                       "no valid pixel"));
  EXPECT_TRUE(contains(error_of([&] { organized_cloud_from_depth(RawDepthImage::Zero(4, 4), K); }),
                       "no valid pixel"));
}

TEST(CloudFromDepth, IsolatedPixelsGiveAnEmptyCloudWithNormalsButPointsWithout) {
  const Eigen::Matrix3d K = kinect();
  DepthImage depth = DepthImage::Constant(20, 20, kNaN);
  depth(5, 5) = depth(12, 9) = 0.6;
  EXPECT_EQ(cloud_from_depth(depth, K).size(), 0u);
  DepthCloudParams params;
  params.normals = false;
  const PointCloud points = cloud_from_depth(depth, K, params);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_FALSE(points.has_normals());
  EXPECT_LT((points.points().row(1).transpose() - 0.6 * ray(K, 12, 9)).norm(), 1e-15);
}

// The depth scale check: 60 of 100 pixels at 0.8 m, 30 at 1.2 km read as metres (a float
// image in millimetres), 10 without a return; at 1000 units per metre the reverse.
TEST(DepthScale, CountsThePlausibleDepthsAndGivesTheMedian) {
  DepthImageF depth = DepthImageF::Zero(10, 10);
  depth.topRows(6).setConstant(0.8f);
  depth.middleRows(6, 3).setConstant(1200.0f);
  depth(9, 0) = std::numeric_limits<float>::quiet_NaN();
  DepthScaleCheck check = check_depth_scale(depth);
  EXPECT_EQ(check.depth_scale, 1.0);
  EXPECT_EQ(check.valid, 90u);
  EXPECT_EQ(check.plausible, 60u);
  EXPECT_TRUE(check.ok());
  EXPECT_NEAR(median_depth(depth), 0.8, 1e-6);
  check = check_depth_scale(depth, 1000.0);  // 0.8 mm and 1.2 m
  EXPECT_EQ(check.plausible, 30u);
  EXPECT_FALSE(check.ok());
  EXPECT_NEAR(median_depth(depth, 1000.0), 0.0008, 1e-9);
  // Exactly half plausible is not enough; raw images default to millimetres.
  RawDepthImage raw = RawDepthImage::Zero(4, 4);
  raw.topRows(2).setConstant(800);    // 0.8 m
  raw.bottomRows(2).setConstant(10);  // 1 cm
  check = check_depth_scale(raw);
  EXPECT_EQ(check.depth_scale, 1000.0);
  EXPECT_EQ(check.plausible, 8u);
  EXPECT_FALSE(check.ok());
  EXPECT_TRUE(check_depth_scale(RawDepthImage::Zero(3, 3)).ok());  // nothing to judge
  EXPECT_TRUE(std::isnan(median_depth(RawDepthImage::Zero(3, 3))));
  EXPECT_THROW(check_depth_scale(raw, 0.0), std::invalid_argument);
  EXPECT_THROW(median_depth(raw, -1.0), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs
