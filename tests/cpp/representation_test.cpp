#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/dominant_plane.hpp>
#include <spectral_vs/representation/egi.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <vector>

namespace spectral_vs {
namespace {

std::string temp_file(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("spectral_vs_test_" + name)).string();
}

TEST(PointCloud, NormalsAreStoredUnitLength) {
  Points p(2, 3), n(2, 3);
  p << 0, 0, 0, 1, 2, 3;
  n << 0, 0, 2, 3, 4, 0;
  const PointCloud cloud(p, n);
  EXPECT_NEAR(cloud.normals().row(0).norm(), 1.0, 1e-15);
  EXPECT_NEAR(cloud.normals()(1, 0), 0.6, 1e-15);
  EXPECT_EQ(cloud.size(), 2u);
  EXPECT_TRUE(cloud.has_normals());
}

TEST(PointCloud, RefusesNonFiniteRowsAndMismatchedNormals) {
  Points p(3, 3);
  p << 0, 0, 0, NAN, 0, 0, 1, 1, 1;
  EXPECT_THROW(PointCloud{p}, std::invalid_argument);
  Points good = Points::Zero(3, 3);
  EXPECT_THROW(PointCloud(good, Points::Ones(2, 3)), std::invalid_argument);
  EXPECT_THROW(PointCloud(good, Points::Zero(3, 3)), std::invalid_argument);
}

TEST(PointCloud, RemoveNonFiniteKeepsFiniteRowsInOrder) {
  Points p(4, 3), n(4, 3);
  p << 0, 0, 0, NAN, 0, 0, 1, 1, 1, 2, 2, 2;
  n << 0, 0, 1, 0, 0, 1, 0, 0, 0, 1, 0, 0;  // row 2 has a zero normal
  EXPECT_EQ(remove_non_finite(p, &n), 2u);
  ASSERT_EQ(p.rows(), 2);
  EXPECT_EQ(p(1, 0), 2.0);
  EXPECT_EQ(n(1, 0), 1.0);
}

TEST(PointCloud, TransformedRotatesNormalsAndMovesPoints) {
  Points p(1, 3), n(1, 3);
  p << 1, 0, 0;
  n << 1, 0, 0;
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.topRightCorner<3, 1>() << 0, 0, 1;
  const PointCloud moved = PointCloud(p, n).transformed(T);
  EXPECT_NEAR((moved.points().row(0) - Eigen::RowVector3d(0, 1, 1)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((moved.normals().row(0) - Eigen::RowVector3d(0, 1, 0)).norm(), 0.0, 1e-15);
}

TEST(RigidTransform, RefusesReflectionsScalingAndBadLastRow) {
  Transform T = Transform::Identity();
  EXPECT_NO_THROW(require_rigid_transform(T, "T"));
  T(0, 0) = -1.0;
  EXPECT_THROW(require_rigid_transform(T, "T"), std::invalid_argument);
  T = Transform::Identity() * 2.0;
  T(3, 3) = 1.0;
  EXPECT_THROW(require_rigid_transform(T, "T"), std::invalid_argument);
  T = Transform::Identity();
  T(3, 0) = 1.0;
  EXPECT_THROW(require_rigid_transform(T, "T"), std::invalid_argument);
}

TEST(CloudIo, LoadsTheMilkCartonScan) {
  CloudFileInfo info;
  const PointCloud milk = load_cloud(test::data_path("milk.pcd"), &info);
  EXPECT_EQ(milk.size() + info.non_finite_dropped, info.points_in_file);
  EXPECT_EQ(info.points_in_file, 13704u);
  EXPECT_FALSE(milk.has_normals());
  // A carton on a table about a metre from the Kinect.
  const Eigen::Vector3d extent = bounding_box(milk).sizes();
  EXPECT_GT(extent.maxCoeff(), 0.05);
  EXPECT_LT(extent.maxCoeff(), 0.5);
}

TEST(CloudIo, LoadsTheOrganizedSceneDroppingNaNs) {
  CloudFileInfo info;
  const PointCloud scene = load_cloud(test::data_path("milk_cartoon_all_small_clorox.pcd"), &info);
  EXPECT_EQ(info.width, 640u);
  EXPECT_EQ(info.height, 480u);
  EXPECT_EQ(info.points_in_file, 640u * 480u);
  EXPECT_GT(info.non_finite_dropped, 0u);
  EXPECT_EQ(scene.size() + info.non_finite_dropped, info.points_in_file);
  EXPECT_TRUE(scene.points().allFinite());
}

class CloudRoundTrip : public ::testing::TestWithParam<std::pair<std::string, PcdEncoding>> {};

TEST_P(CloudRoundTrip, KeepsPointsAndNormalsToFloatPrecision) {
  std::mt19937 rng(3);
  const PointCloud cloud = test::box_and_sphere(300, rng);
  const std::string path = temp_file(GetParam().first);
  save_cloud(path, cloud, GetParam().second);
  CloudFileInfo info;
  const PointCloud loaded = load_cloud(path, &info);
  std::filesystem::remove(path);
  ASSERT_EQ(loaded.size(), cloud.size());
  ASSERT_TRUE(loaded.has_normals());
  EXPECT_LT((loaded.points() - cloud.points()).cwiseAbs().maxCoeff(), 1e-7);  // 0.1 um
  EXPECT_LT((loaded.normals() - cloud.normals()).cwiseAbs().maxCoeff(), 1e-6);
}

INSTANTIATE_TEST_SUITE_P(Formats, CloudRoundTrip,
                         ::testing::Values(std::make_pair("a.pcd", PcdEncoding::ascii),
                                           std::make_pair("b.pcd", PcdEncoding::binary),
                                           std::make_pair("c.pcd", PcdEncoding::binary_compressed),
                                           std::make_pair("d.ply", PcdEncoding::binary)));

TEST(CloudIo, RefusesMissingAndForeignFiles) {
  EXPECT_THROW(load_cloud(temp_file("missing.pcd")), std::invalid_argument);
  const std::string text = temp_file("not_a_cloud.pcd");
  std::ofstream(text) << "hello, this is not a point cloud\n";
  EXPECT_THROW(load_cloud(text), std::invalid_argument);
  const std::string ply = temp_file("not_a_cloud.ply");
  std::ofstream(ply) << "solid cube\n";
  EXPECT_THROW(load_cloud(ply), std::invalid_argument);
  EXPECT_THROW(load_cloud(temp_file("cloud.xyz")), std::invalid_argument);
  std::filesystem::remove(text);
  std::filesystem::remove(ply);
}

// PLY files as other tools write them, checked against the values written.
std::string write_ply(const std::string& name, const std::string& header_and_data) {
  const std::string path = temp_file(name);
  std::ofstream(path, std::ios::binary) << "ply\nformat ascii 1.0\n" << header_and_data;
  return path;
}

TEST(CloudIo, ReadsAsciiPlyWithColoursAndNormals) {
  const std::string path = write_ply(
      "colours.ply",
      "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0.1 0.2 0.3 255 0 0 255 0 0 1\n-0.5 0.25 2 0 255 0 128 1 0 0\n3 0 1 1\n");
  const PointCloud cloud = load_cloud(path);
  std::filesystem::remove(path);
  ASSERT_EQ(cloud.size(), 2u);
  ASSERT_TRUE(cloud.has_normals());
  EXPECT_NEAR(cloud.points()(0, 2), 0.3, 1e-7);
  EXPECT_NEAR(cloud.points()(1, 0), -0.5, 1e-7);
  EXPECT_NEAR(cloud.normals()(0, 2), 1.0, 1e-7);
  EXPECT_NEAR(cloud.normals()(1, 0), 1.0, 1e-7);
}

// PCL's ASCII writer gives a cloud with NaN points the full num_cols but only its valid
// vertices; the reader must not pad them with zero points.
TEST(CloudIo, ReadsPlyWhoseObjInfoCountsMorePointsThanVertices) {
  const std::string path =
      write_ply("padded.ply",
                "obj_info num_cols 4\nobj_info num_rows 1\nelement vertex 3\nproperty float x\n"
                "property float y\nproperty float z\nend_header\n1 1 1\n2 2 2\n3 3 3\n");
  CloudFileInfo info;
  const PointCloud cloud = load_cloud(path, &info);
  std::filesystem::remove(path);
  ASSERT_EQ(cloud.size(), 3u);
  EXPECT_EQ(info.points_in_file, 3u);
  EXPECT_NEAR(cloud.points().minCoeff(), 1.0, 1e-7);
}

// An organized PLY (PCL's writer without a camera): a range_grid maps each cell of the
// lattice to its vertex, or to none for an invalid pixel.
TEST(CloudIo, ReadsOrganizedPlyWithRangeGrid) {
  const std::string path =
      write_ply("organized.ply",
                "obj_info num_cols 2\nobj_info num_rows 2\nelement vertex 3\nproperty float x\n"
                "property float y\nproperty float z\nelement range_grid 4\n"
                "property list uchar int vertex_indices\nend_header\n"
                "0 0 1\n0.1 0 1\n0 0.1 1\n1 0\n1 1\n0\n1 2\n");
  CloudFileInfo info;
  const PointCloud cloud = load_cloud(path, &info);
  std::filesystem::remove(path);
  EXPECT_EQ(info.width, 2u);
  EXPECT_EQ(info.height, 2u);
  EXPECT_EQ(info.points_in_file, 4u);
  EXPECT_EQ(info.non_finite_dropped, 1u);
  ASSERT_EQ(cloud.size(), 3u);
  EXPECT_NEAR(cloud.points()(2, 1), 0.1, 1e-7);
}

TEST(Preprocessing, VoxelDownsampleAveragesPointsAndNormals) {
  Points p(4, 3), n(4, 3);
  p << 0.001, 0.001, 0.001, 0.003, 0.003, 0.003,  // one 1 cm voxel
      0.051, 0.001, 0.001, 0.052, 0.001, 0.001;   // another
  n << 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1;
  const PointCloud reduced = voxel_downsample(PointCloud(p, n), 0.01);
  ASSERT_EQ(reduced.size(), 2u);
  for (Eigen::Index i = 0; i < 2; ++i) {
    EXPECT_NEAR(reduced.normals().row(i).norm(), 1.0, 1e-6);
    if (reduced.points()(i, 0) < 0.01) {
      EXPECT_NEAR(reduced.points()(i, 0), 0.002, 1e-6);
      EXPECT_NEAR(reduced.normals()(i, 0), std::sqrt(0.5), 1e-6);
    } else {
      EXPECT_NEAR(reduced.points()(i, 0), 0.0515, 1e-6);
    }
  }
}

// Brute force: every voxel's points gathered in a std::map by voxel index (z, y, x), in
// row order, then averaged; the hash of voxel_downsample must give the same rows.
TEST(Preprocessing, VoxelDownsampleMatchesBruteForceOnSeededClouds) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coordinate(-0.4, 0.6), direction(-1.0, 1.0);
  for (const double voxel : {0.004, 0.015, 0.05}) {
    const Eigen::Index n = 20000;
    Points p(n, 3), nr(n, 3);
    for (Eigen::Index i = 0; i < n; ++i) {
      // Clustered like a capture: runs of nearby points, some far apart.
      const double base = coordinate(rng);
      p.row(i) << base, 0.3 * coordinate(rng), 0.5 + 0.01 * coordinate(rng);
      nr.row(i) << direction(rng), direction(rng), 1.0;
    }
    const PointCloud cloud(p, nr);
    const PointCloud reduced = voxel_downsample(cloud, voxel);
    const Eigen::Vector3d low = cloud.points().colwise().minCoeff();
    std::map<std::array<long, 3>, std::vector<Eigen::Index>> voxels;  // key (z, y, x)
    for (Eigen::Index i = 0; i < n; ++i) {
      std::array<long, 3> key;
      for (int axis = 0; axis < 3; ++axis)
        key[2 - axis] = long(std::floor(cloud.points()(i, axis) / voxel));
      voxels[key].push_back(i);
    }
    ASSERT_EQ(reduced.size(), voxels.size()) << voxel;
    Eigen::Index row = 0;
    for (const auto& [key, rows] : voxels) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero(), normal = Eigen::Vector3d::Zero();
      for (const Eigen::Index i : rows) {
        sum += cloud.points().row(i).transpose() - low;
        normal += cloud.normals().row(i).transpose();
      }
      const Eigen::Vector3d centroid = low + sum / double(rows.size());
      EXPECT_LT((reduced.points().row(row).transpose() - centroid).norm(), 1e-12) << voxel;
      EXPECT_LT((reduced.normals().row(row).transpose() - normal.normalized()).norm(), 1e-12);
      ++row;
    }
  }
}

TEST(Preprocessing, VoxelDownsampleRefusesBadSizes) {
  const PointCloud cloud(Points::Random(10, 3) * 100.0);
  EXPECT_THROW(voxel_downsample(cloud, 0.0), std::invalid_argument);
  EXPECT_THROW(voxel_downsample(cloud, NAN), std::invalid_argument);
  EXPECT_THROW(voxel_downsample(cloud, 1e-20), std::invalid_argument);  // index past 2^62
  EXPECT_THROW(voxel_downsample(PointCloud(), 0.01), std::invalid_argument);
  // Voxel indices are per axis: a box of 1e8^3 voxels (PCL's int index overflowed) is fine.
  EXPECT_EQ(voxel_downsample(cloud, 1e-6).size(), 10u);
}

// A plane of 2000 points 1 m in front of the sensor, 0.2 m square, and far outliers.
Points plane_points(std::mt19937& rng) {
  std::uniform_real_distribution<double> uniform(-0.1, 0.1);
  Points p(2000, 3);
  for (Eigen::Index i = 0; i < p.rows(); ++i) p.row(i) << uniform(rng), uniform(rng), 1.0;
  return p;
}

Points with_rows(const Points& p, const Points& extra) {
  Points out(p.rows() + extra.rows(), 3);
  out << p, extra;
  return out;
}

// The first rows of `noisy` are those of `clean`, points equal and normals within tolerance.
void expect_same_normals(const PointCloud& clean, const PointCloud& noisy, double tolerance) {
  ASSERT_GE(noisy.size(), clean.size());
  for (Eigen::Index i = 0; i < Eigen::Index(clean.size()); ++i) {
    ASSERT_EQ(noisy.points().row(i), clean.points().row(i)) << "row " << i;
    ASSERT_LT((noisy.normals().row(i) - clean.normals().row(i)).norm(), tolerance) << "row " << i;
  }
}

// One point at 1e12 m on every axis moved the float offset (then the centroid) to 2e9 m,
// where float's step is 256 m: every point of the plane fell on one, and no normal was
// left. Now the offset is the median (zero here) and the far point alone has no normal.
TEST(Preprocessing, AFarOutlierChangesNoOtherNormal) {
  std::mt19937 rng(11);
  const Points p = plane_points(rng);
  for (const NormalOrientation orientation :
       {NormalOrientation::toward_viewpoint, NormalOrientation::outward}) {
    for (const int k : {0, 20}) {
      NormalEstimationParams params;
      params.radius = 0.02;
      params.k_neighbors = k;
      params.orientation = orientation;
      const PointCloud clean = estimate_normals(PointCloud(p), params);
      ASSERT_EQ(clean.size(), 2000u);
      const PointCloud noisy =
          estimate_normals(PointCloud(with_rows(p, Points::Constant(1, 3, 1e12))), params);
      EXPECT_EQ(noisy.size(), 2000u) << "k " << k;  // the outlier has no normal
      expect_same_normals(clean, noisy, 1e-6);
    }
  }
}

// 1% of the points at random depths up to 100 m along the rays of random plane points,
// none within 2 radii of the plane: the plane's normals are the same, bit for bit.
TEST(Preprocessing, FarOutliersAlongTheRaysChangeNoOtherNormal) {
  std::mt19937 rng(12);
  const Points p = plane_points(rng);
  std::uniform_real_distribution<double> depth(1.05, 100.0);
  std::uniform_int_distribution<Eigen::Index> pick(0, p.rows() - 1);
  Points outliers(20, 3);
  for (Eigen::Index i = 0; i < outliers.rows(); ++i)
    outliers.row(i) = p.row(pick(rng)) * depth(rng);
  NormalEstimationParams params;
  params.radius = 0.02;
  const PointCloud clean = estimate_normals(PointCloud(p), params);
  const PointCloud noisy = estimate_normals(PointCloud(with_rows(p, outliers)), params);
  expect_same_normals(clean, noisy, 1e-12);
}

// Beyond float's reach (1e18 m from the median on an axis) a point is not searched; when
// no point is left with a normal, the error counts them.
TEST(Preprocessing, PointsBeyondFloatReachAreCountedInTheError) {
  std::mt19937 rng(13);
  const Points p = plane_points(rng);
  NormalEstimationParams params;
  params.radius = 0.02;
  const PointCloud far(with_rows(p, Points::Constant(1, 3, 1e30)));
  EXPECT_EQ(estimate_normals(far, params).size(), 2000u);
  try {
    estimate_normals(PointCloud(with_rows(p.topRows(3), Points::Constant(2, 3, 1e30))), params);
    FAIL() << "no point has a normal";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("not searched: 2 of 5"), std::string::npos)
        << error.what();
  }
}

// A far point is one more voxel: the others' centroids are those without it, and a cloud
// whose box held more voxels than an int (PCL's limit, refused before) is downsampled.
TEST(Preprocessing, VoxelDownsampleOfAFarOutlierChangesNoOtherVoxel) {
  std::mt19937 rng(14);
  const Points p = plane_points(rng);
  const PointCloud clean = voxel_downsample(PointCloud(p), 0.004);
  for (const double far : {1e12, -1e12}) {
    const PointCloud noisy =
        voxel_downsample(PointCloud(with_rows(p, Points::Constant(1, 3, far))), 0.004);
    ASSERT_EQ(noisy.size(), clean.size() + 1);
    const Eigen::Index first = far < 0 ? 1 : 0;  // ordered by z index: -1e12 first
    EXPECT_EQ(noisy.points().row(far < 0 ? 0 : Eigen::Index(clean.size())),
              Eigen::RowVector3d::Constant(far));
    EXPECT_EQ(noisy.points().middleRows(first, Eigen::Index(clean.size())), clean.points());
  }
}

TEST(Preprocessing, NormalsOfAPlaneFaceTheViewpoint) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(-0.1, 0.1);
  Points p(2000, 3);
  for (Eigen::Index i = 0; i < p.rows(); ++i) p.row(i) << uniform(rng), uniform(rng), 1.0;
  NormalEstimationParams params;
  params.radius = 0.02;
  const PointCloud with_normals = estimate_normals(PointCloud(p), params);  // viewpoint at origin
  ASSERT_EQ(with_normals.size(), 2000u);
  EXPECT_LT((with_normals.normals().col(2).array() + 1.0).abs().maxCoeff(), 1e-6);
}

// `n` points uniform on the sphere of `radius` metres about the origin.
Points sphere_points(Eigen::Index n, double radius, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gaussian;
  Points p(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    p.row(i) =
        Eigen::RowVector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized() * radius;
  }
  return p;
}

TEST(Preprocessing, OutwardNormalsOfASphere) {
  const Points p = sphere_points(3000, 0.1, 6);
  NormalEstimationParams params;
  params.k_neighbors = 15;
  params.orientation = NormalOrientation::outward;
  params.threads = 2;
  const PointCloud with_normals = estimate_normals(PointCloud(p), params);
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    const double alignment =
        with_normals.normals().row(i).dot(with_normals.points().row(i).normalized());
    ASSERT_GT(alignment, 0.99) << "point " << i;
  }
}

// A 0.1 m square of z = 1 m sampled every 5 mm, points at the cells' centres.
Points square_at_one_metre() {
  Points p(400, 3);
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) p.row(i * 20 + j) << 0.005 * (i + 0.5), 0.005 * (j + 0.5), 1.0;
  }
  return p;
}

TEST(Preparation, DownsamplesToHalfAVoxelAndTurnsNormalsTowardTheSensor) {
  // At a 20 mm voxel the cubes are 10 mm: 2 x 2 points each, 100 cubes, their centroids
  // at the cubes' centres; the plane's normals face the sensor at the origin (-z).
  const PointCloud prepared =
      prepare_cloud(PointCloud(square_at_one_metre()), 0.02, true, Eigen::Vector3d::Zero());
  ASSERT_EQ(prepared.size(), 100u);
  for (Eigen::Index k = 0; k < prepared.points().rows(); ++k) {
    const Eigen::Vector3d p = prepared.points().row(k).transpose();
    EXPECT_NEAR(std::fmod(p.x(), 0.01), 0.005, 1e-12);
    EXPECT_NEAR(std::fmod(p.y(), 0.01), 0.005, 1e-12);
    EXPECT_NEAR(prepared.normals()(k, 2), -1.0, 1e-9);
  }
  // Seen from above the plane instead, and without downsampling: every point, facing +z.
  const PointCloud all =
      prepare_cloud(PointCloud(square_at_one_metre()), 0.02, false, Eigen::Vector3d(0, 0, 2));
  ASSERT_EQ(all.size(), 400u);
  EXPECT_NEAR(all.normals().col(2).minCoeff(), 1.0, 1e-9);
}

TEST(Preparation, TurnsNormalsOutwardWhenTheSensorIsInsideTheCloud) {
  const Points p = sphere_points(3000, 0.1, 7);
  // A model centred at the origin, "seen" from the origin: toward it would be inward.
  const PointCloud prepared = prepare_cloud(PointCloud(p), 0.01, false, Eigen::Vector3d::Zero());
  for (Eigen::Index i = 0; i < prepared.points().rows(); ++i) {
    ASSERT_GT(prepared.normals().row(i).dot(prepared.points().row(i).normalized()), 0.95) << i;
  }
}

TEST(Preparation, KeepsGivenNormalsAndNamesTheArgumentAndTheStep) {
  const Points p = square_at_one_metre();
  const Points up = Points::Zero(p.rows(), 3).rowwise() + Eigen::RowVector3d(0, 0, 1);
  const PointCloud given(p, up);
  const PointCloud kept = prepare_cloud(given, 0.02, false, Eigen::Vector3d::Zero());
  EXPECT_EQ(kept.normals(), given.normals());  // not re-fitted toward the sensor
  const auto message = [](const auto& call) {
    try {
      call();
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message([] { prepare_cloud(PointCloud(), 0.02, true, {}, "model"); }),
            "model is empty: at least 1 finite point is needed");
  EXPECT_EQ(message([&] { prepare_cloud(given, 0.0, true, {}, "model"); }),
            "voxel_size must be finite and > 0 metres, got 0");
  // Points on one line: no plane to fit.
  Points line(50, 3);
  for (Eigen::Index i = 0; i < line.rows(); ++i) line.row(i) << 0.001 * double(i), 0.0, 1.0;
  EXPECT_NE(message([&] {
              prepare_cloud(PointCloud(line), 0.01, false, {}, "scene");
            }).find("scene: estimating normals over a radius of 2 x voxel_size = 0.02 m: "),
            std::string::npos);
  EXPECT_NE(message([&] {
              prepare_cloud(given, 1e-300, true, {}, "scene");
            }).find("scene: downsampling to half of voxel_size = 1e-300 m: "),
            std::string::npos);
}

TEST(VoxelGrid, FftFriendlySizes) {
  EXPECT_EQ(fft_friendly_size(1), 2);
  EXPECT_EQ(fft_friendly_size(11), 12);
  EXPECT_EQ(fft_friendly_size(55), 64);  // not 60: FFTW's estimated plan is slow there
  EXPECT_EQ(fft_friendly_size(97), 100);
  EXPECT_EQ(fft_friendly_size(128), 128);
  EXPECT_EQ(fft_friendly_size(161), 200);
  EXPECT_EQ(fft_friendly_size(1025), 1080);  // beyond the table: even, factors 2, 3, 5
}

TEST(VoxelGrid, GridForAPairCannotAlias) {
  const Eigen::AlignedBox3d a(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.2, 0.1, 0.05));
  const Eigen::AlignedBox3d b(Eigen::Vector3d(0.5, -0.3, 0), Eigen::Vector3d(0.6, 0.3, 0.05));
  const GridSpec spec = make_grid_spec(a, b, 0.01);
  for (int axis = 0; axis < 3; ++axis) {
    const double union_extent = a.merged(b).sizes()[axis] / 0.01;
    const double pair_extent = (a.sizes()[axis] + b.sizes()[axis]) / 0.01;
    EXPECT_GE(spec.dims[axis], union_extent + 1);
    EXPECT_GE(spec.dims[axis], pair_extent + 2);
    EXPECT_EQ(fft_friendly_size(spec.dims[axis]), spec.dims[axis]);
    EXPECT_NEAR(std::remainder(spec.origin[axis], 0.01), 0.0, 1e-12);
  }
  EXPECT_TRUE(spec.contains(spec.index_of(a.min())));
  EXPECT_TRUE(spec.contains(spec.index_of(b.max())));
}

TEST(VoxelGrid, RefusesGridsOverTheLimit) {
  const Eigen::AlignedBox3d box(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones());
  EXPECT_THROW(make_grid_spec(box, box, 0.001), std::invalid_argument);  // 2001^3 voxels
  try {
    make_grid_spec(box, box, 0.001);
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("16777216"), std::string::npos) << error.what();
  }
  EXPECT_THROW(make_grid_spec(box, box, -1.0), std::invalid_argument);
  EXPECT_NO_THROW(make_grid_spec(box, box, 0.001, GridLimits{std::size_t{1} << 34}));
}

TEST(VoxelGrid, IndexIsFloorSoNegativeCoordinatesGetTheirOwnVoxel) {
  GridSpec spec;
  spec.origin = Eigen::Vector3d::Constant(-0.1);
  spec.resolution = 0.01;
  spec.dims = Eigen::Vector3i::Constant(20);
  EXPECT_EQ(spec.index_of(Eigen::Vector3d(-0.005, 0.005, 0.0)), Eigen::Vector3i(9, 10, 10));
  Points p(3, 3);
  p << -0.005, 0, 0, 0.005, 0, 0, 5.0, 0, 0;
  const VoxelGrid grid = voxelize(PointCloud(p), spec, Occupancy::binary);
  EXPECT_EQ(grid.at(9, 10, 10), 1.0f);
  EXPECT_EQ(grid.at(10, 10, 10), 1.0f);
  EXPECT_EQ(grid.points_outside, 1u);
  EXPECT_EQ(grid.occupied_min, Eigen::Vector3i(9, 10, 10));
  EXPECT_EQ(grid.occupied_max, Eigen::Vector3i(10, 10, 10));
}

TEST(VoxelGrid, OccupancyModesAgreeWithBruteForce) {
  std::mt19937 rng(8);
  const PointCloud cloud = test::box_and_sphere(4000, rng);
  const GridSpec spec = make_grid_spec(bounding_box(cloud), bounding_box(cloud), 0.008);
  const VoxelGrid binary = voxelize(cloud, spec, Occupancy::binary);
  const VoxelGrid count = voxelize(cloud, spec, Occupancy::count);
  const VoxelGrid trilinear = voxelize(cloud, spec, Occupancy::trilinear);
  std::vector<int> counts(spec.voxel_count(), 0);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3i v = spec.index_of(cloud.points().row(Eigen::Index(i)).transpose());
    ++counts[(std::size_t(v.x()) * spec.dims.y() + v.y()) * spec.dims.z() + v.z()];
  }
  double total = 0.0;
  for (std::size_t i = 0; i < counts.size(); ++i) {
    ASSERT_EQ(count.values[i], float(counts[i]));
    ASSERT_EQ(binary.values[i], counts[i] > 0 ? 1.0f : 0.0f);
    total += trilinear.values[i];
  }
  EXPECT_NEAR(total, double(cloud.size()), 1e-2);  // trilinear weights sum to 1 per point
}

TEST(Egi, CountsEveryNormalOnce) {
  std::mt19937 rng(9);
  const PointCloud cloud = test::box_and_sphere(5000, rng);
  for (int bandwidth : {4, 16, 32}) {
    const SphereGrid egi = egi_histogram(cloud.normals(), bandwidth);
    EXPECT_EQ(egi.rows(), 2 * bandwidth);
    EXPECT_EQ(egi.cols(), 2 * bandwidth);
    EXPECT_DOUBLE_EQ(egi.sum(), 5000.0);
  }
}

TEST(Egi, KnownDirectionsLandInTheirCells) {
  const int B = 8;
  // +z: theta = 0 -> row 0. -z: theta = pi -> last row. +x: theta = pi/2 -> row B, phi = 0.
  EXPECT_EQ(egi_cell(Eigen::Vector3d(0, 0, 1), B), Eigen::Vector2i(0, 0));
  EXPECT_EQ(egi_cell(Eigen::Vector3d(0, 0, -1), B), Eigen::Vector2i(2 * B - 1, 0));
  EXPECT_EQ(egi_cell(Eigen::Vector3d(1, 0, 0), B), Eigen::Vector2i(B, 0));
  EXPECT_EQ(egi_cell(Eigen::Vector3d(0, 1, 0), B), Eigen::Vector2i(B, B / 2));       // phi = pi/2
  EXPECT_EQ(egi_cell(Eigen::Vector3d(0, -1, 0), B), Eigen::Vector2i(B, 3 * B / 2));  // phi = 3pi/2
  // The node itself maps to its own cell for every node of the grid.
  for (int j = 0; j < 2 * B; ++j) {
    for (int k = 0; k < 2 * B; ++k) {
      const double t = grid_theta(j, B), p = grid_phi(k, B);
      const Eigen::Vector3d n(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
      ASSERT_EQ(egi_cell(n, B), Eigen::Vector2i(j, k));
    }
  }
}

TEST(Egi, RotationAboutZByOneColumnShiftsColumnsByOne) {
  std::mt19937 rng(10);
  std::normal_distribution<double> gaussian;
  Points normals(3000, 3);
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    normals.row(i) = Eigen::RowVector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized();
  }
  for (int B : {4, 8, 16}) {
    const Eigen::Matrix3d Rz =
        Eigen::AngleAxisd(M_PI / B, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Points rotated = normals * Rz.transpose();
    const SphereGrid before = egi_histogram(normals, B);
    const SphereGrid after = egi_histogram(rotated, B);
    for (int k = 0; k < 2 * B; ++k) {
      ASSERT_TRUE(after.col((k + 1) % (2 * B)).isApprox(before.col(k)))
          << "B " << B << " column " << k;
    }
  }
}

TEST(Egi, RefusesBadBandwidthAndEmptyInput) {
  EXPECT_THROW(egi_histogram(Points::Ones(3, 3), 0), std::invalid_argument);
  EXPECT_THROW(egi_histogram(Points::Ones(3, 3), kMaxBandwidth + 1), std::invalid_argument);
  EXPECT_THROW(egi_histogram(Points(), 8), std::invalid_argument);
  const Eigen::VectorXd weights = Eigen::VectorXd::Ones(2);
  EXPECT_THROW(egi_histogram(Points::Ones(3, 3), 8, &weights), std::invalid_argument);
}

}  // namespace
}  // namespace spectral_vs

namespace {

/// A plane n . x = d (`count` points in a 0.6 m square about its foot, normals n, noisy
/// by `noise` m along n) and `clutter` points with random unit normals in a 0.6 m cube.
spectral_vs::PointCloud plane_with_clutter(const Eigen::Vector3d& n, double d, int count,
                                           int clutter, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> side(-0.3, 0.3);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Eigen::Vector3d u = n.unitOrthogonal(), v = n.cross(u);
  spectral_vs::Points points(count + clutter, 3), normals(count + clutter, 3);
  for (int i = 0; i < count; ++i) {
    points.row(i) = (d * n + side(rng) * u + side(rng) * v + noise * gauss(rng) * n).transpose();
    normals.row(i) = n.transpose();
  }
  for (int i = count; i < count + clutter; ++i) {
    points.row(i) = Eigen::Vector3d(side(rng), side(rng), side(rng)).transpose();
    normals.row(i) = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized().transpose();
  }
  return spectral_vs::PointCloud(points, normals);
}

}  // namespace

TEST(DominantPlane, FindsAPlaneWithKnownNormalAndOffsetInClutter) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.3, 1.0).normalized();
  const spectral_vs::PointCloud cloud = plane_with_clutter(n, 0.55, 3000, 1000, 0.0, 7);
  spectral_vs::PlaneDetectionParams params;
  params.offset_bin = 0.001;
  params.band = 0.002;
  const auto plane = spectral_vs::dominant_plane(cloud, params);
  ASSERT_TRUE(plane.has_value());
  // The mean of the plane's exact normals and of the few clutter normals within 10 degrees
  // (0.8% of 1000): about 1e-4 rad off.
  EXPECT_LT(plane->normal.cross(n).norm(), 1e-3);
  EXPECT_NEAR(plane->offset, 0.55, 0.001);  // within a bin
  // The 3000 plane points, and the few clutter points in the band and the cone.
  EXPECT_GE(plane->count, 3000u);
  EXPECT_LT(plane->count, 3020u);
  EXPECT_NEAR(plane->share, double(plane->count) / 4000.0, 1e-12);
  // The axis-aligned box of the square's points (no clutter point reaches the plane).
  Eigen::AlignedBox3d box;
  for (int i = 0; i < 3000; ++i) box.extend(cloud.points().row(i).transpose());
  EXPECT_NEAR(plane->extent, box.sizes().norm(), 1e-9);
  const auto direction = spectral_vs::dominant_direction(cloud.normals(), params);
  EXPECT_LT(direction.axis.cross(n).norm(), 1e-3);
  // 3000 of 4000, and the clutter normals within 20 degrees: (1 - cos 20 deg) / 2 of them.
  EXPECT_NEAR(direction.share, 0.75 + 0.25 * (1 - std::cos(20.0 * M_PI / 180.0)) / 2, 0.01);
}

TEST(DominantPlane, NoisyPlaneWithinTheBandAndNoneBelowTheShare) {
  const Eigen::Vector3d n(0.0, 0.0, -1.0);
  const spectral_vs::PointCloud cloud = plane_with_clutter(n, -0.8, 2000, 2000, 0.001, 3);
  spectral_vs::PlaneDetectionParams params;  // 1 cm bins, 1.5 cm band
  const auto plane = spectral_vs::dominant_plane(cloud, params);
  ASSERT_TRUE(plane.has_value());
  EXPECT_NEAR(plane->offset, -0.8, 0.01);
  EXPECT_NEAR(plane->share, 0.5, 0.02);
  params.min_share = 0.6;
  EXPECT_FALSE(spectral_vs::dominant_plane(cloud, params).has_value());
  params.min_share = 1.5;
  EXPECT_THROW(spectral_vs::dominant_plane(cloud, params), std::invalid_argument);
  EXPECT_THROW(spectral_vs::dominant_plane(spectral_vs::PointCloud(cloud.points())),
               std::invalid_argument);  // no normals
}
