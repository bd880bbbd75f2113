// The aligner's internals: the range image that checks a pose against what a single
// view saw, the connected parts of a cluttered scene, its support plane, how much of a
// part a pose explains, how a pose rests on the support plane, the final point-to-plane
// ICP, and the fitness of a pose.

#include "alignment/icp_refinement.hpp"
#include "alignment/normal_directions.hpp"
#include "alignment/part_coverage.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/range_image.hpp"
#include "alignment/resting.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/scene_preparation.hpp"
#include "alignment/support_plane.hpp"
#include "alignment/verifier.hpp"
#include "test_support.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <vector>

namespace spectral_vs::detail {
namespace {

// A square patch of the plane z = depth, `half` metres each side of (x, y), sampled
// every `step` metres, with the given normal.
PointCloud patch(double x, double y, double depth, double half, double step,
                 const Eigen::Vector3d& normal) {
  std::vector<Eigen::Vector3d> points;
  for (double u = -half; u <= half + 1e-12; u += step) {
    for (double v = -half; v <= half + 1e-12; v += step) points.emplace_back(x + u, y + v, depth);
  }
  Points p(Eigen::Index(points.size()), 3), n(Eigen::Index(points.size()), 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    p.row(Eigen::Index(i)) = points[i].transpose();
    n.row(Eigen::Index(i)) = normal.transpose();
  }
  return PointCloud(p, n);
}

// The clouds one after another, points and normals.
PointCloud joined(std::initializer_list<PointCloud> clouds) {
  Eigen::Index rows = 0;
  for (const PointCloud& cloud : clouds) rows += cloud.points().rows();
  Points points(rows, 3), normals(rows, 3);
  Eigen::Index at = 0;
  for (const PointCloud& cloud : clouds) {
    points.middleRows(at, cloud.points().rows()) = cloud.points();
    normals.middleRows(at, cloud.points().rows()) = cloud.normals();
    at += cloud.points().rows();
  }
  return PointCloud(points, normals);
}

const Eigen::Vector3d kToSensor(0.0, 0.0, -1.0);  // the sensor at the origin looks along +z

class ViewOfAWall : public ::testing::Test {
 protected:
  // A wall 1 m in front of the sensor, 0.6 m wide, scanned every 2 mm; pixels of 4 mm.
  PointCloud wall = patch(0.0, 0.0, 1.0, 0.3, 0.002, kToSensor);
  RangeImage image{wall, Eigen::Vector3d::Zero(), 0.004};
  double tolerance = 0.008;
};

TEST_F(ViewOfAWall, ASurfaceOnTheWallIsConfirmed) {
  const PointCloud model = patch(0.05, -0.02, 1.003, 0.05, 0.003, kToSensor);
  const ViewCheck check = image.check(model.points(), model.normals(), tolerance);
  EXPECT_GT(check.confirmed, 400);  // a 0.1 m square in 4 mm pixels: about 625
  EXPECT_EQ(check.contradicted, 0);
  EXPECT_EQ(check.hidden, 0);
  EXPECT_DOUBLE_EQ(check.fitness(), 1.0);
}

// The verification's screen of a single view is the pixel check at half-voxel pixels: a
// surface on the wall fits, one in front of it (seen through) does not.
TEST_F(ViewOfAWall, TheVerificationScreensAViewByItsPixels) {
  const double voxel = 0.008;
  const Verifier verifier(wall, voxel, Eigen::Vector3d::Zero());
  const RangeImage half_voxel(wall, Eigen::Vector3d::Zero(), 0.5 * voxel);
  for (const double depth : {1.003, 0.95}) {
    const PointCloud model = patch(0.05, -0.02, depth, 0.05, 0.003, kToSensor);
    const double expected = half_voxel.check(model.points(), model.normals(), voxel).fitness();
    EXPECT_EQ(verifier.fitness(model.points(), model.normals(), voxel), expected);
  }
  const PointCloud on_wall = patch(0.05, -0.02, 1.003, 0.05, 0.003, kToSensor);
  EXPECT_DOUBLE_EQ(verifier.fitness(on_wall.points(), on_wall.normals(), voxel), 1.0);
  const PointCloud in_front = patch(0.05, -0.02, 0.95, 0.05, 0.003, kToSensor);
  EXPECT_DOUBLE_EQ(verifier.fitness(in_front.points(), in_front.normals(), voxel), 0.0);
}

TEST_F(ViewOfAWall, ASurfaceInFrontOfTheWallIsContradicted) {
  // The sensor saw the wall through where this surface would be.
  const PointCloud model = patch(0.0, 0.0, 0.95, 0.05, 0.003, kToSensor);
  const ViewCheck check = image.check(model.points(), model.normals(), tolerance);
  EXPECT_GT(check.contradicted, 400);
  EXPECT_EQ(check.confirmed, 0);
  EXPECT_DOUBLE_EQ(check.fitness(), 0.0);
}

TEST_F(ViewOfAWall, ASurfaceBehindTheWallIsHidden) {
  const PointCloud model = patch(0.0, 0.0, 1.05, 0.05, 0.003, kToSensor);
  const ViewCheck check = image.check(model.points(), model.normals(), tolerance);
  EXPECT_GT(check.hidden, 400);
  EXPECT_EQ(check.confirmed + check.contradicted, 0);
}

TEST_F(ViewOfAWall, ASurfaceTurnedAwayFromTheWallsNormalIsContradicted) {
  // On the wall, but its normal 60 degrees from the wall's: not the surface scanned.
  const Eigen::Vector3d turned(std::sin(M_PI / 3.0), 0.0, -std::cos(M_PI / 3.0));
  const PointCloud model = patch(0.0, 0.0, 1.0, 0.05, 0.003, turned);
  const ViewCheck check = image.check(model.points(), model.normals(), tolerance);
  EXPECT_GT(check.contradicted, 400);
  EXPECT_EQ(check.confirmed, 0);
}

TEST_F(ViewOfAWall, OnlyTheNearestSideFacingTheSensorCounts) {
  // Two sheets, one in front on the wall and one 5 cm behind it: the second is the model's
  // own hidden side, and the sheet facing away is not seen at all.
  const PointCloud front = patch(0.0, 0.0, 1.0, 0.05, 0.003, kToSensor);
  const PointCloud back = patch(0.0, 0.0, 1.05, 0.05, 0.003, kToSensor);
  const PointCloud away = patch(0.0, 0.0, 0.9, 0.05, 0.003, -kToSensor);
  const PointCloud sheets = joined({front, back, away});
  const ViewCheck check = image.check(sheets.points(), sheets.normals(), tolerance);
  EXPECT_EQ(check.contradicted + check.hidden, 0);
  EXPECT_GT(check.confirmed, 400);
}

TEST_F(ViewOfAWall, HiddenPixelsWeighHalf) {
  ViewCheck check;
  check.confirmed = 100;
  check.hidden = 100;
  EXPECT_DOUBLE_EQ(check.fitness(), 100.0 / 150.0);
  check.contradicted = 50;
  EXPECT_DOUBLE_EQ(check.fitness(), 100.0 / 200.0);
  EXPECT_DOUBLE_EQ(ViewCheck{}.fitness(), 0.0);
}

TEST_F(ViewOfAWall, MissingReturnsAreFilledFromTheirNeighbours) {
  // Every other scan row missing: the 2 mm rows left are still no look through.
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < wall.points().rows(); ++i) {
    if (std::lround(wall.points()(i, 1) / 0.002) % 3 != 0) rows.push_back(i);
  }
  Points p(Eigen::Index(rows.size()), 3), n(Eigen::Index(rows.size()), 3);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    p.row(Eigen::Index(i)) = wall.points().row(rows[i]);
    n.row(Eigen::Index(i)) = wall.normals().row(rows[i]);
  }
  const RangeImage sparse(PointCloud(p, n), Eigen::Vector3d::Zero(), 0.002);
  const PointCloud model = patch(0.0, 0.0, 1.0, 0.05, 0.001, kToSensor);
  const ViewCheck check = sparse.check(model.points(), model.normals(), tolerance);
  EXPECT_EQ(check.contradicted, 0);
}

TEST(RangeImage, RefusesAViewpointWithNoDirectionToLookIn) {
  const PointCloud wall = patch(0.0, 0.0, 1.0, 0.1, 0.01, kToSensor);
  EXPECT_THROW(RangeImage(wall, wall.centroid(), 0.004), std::invalid_argument);
  EXPECT_NO_THROW(RangeImage(wall, Eigen::Vector3d(0.0, 0.0, 2.0), 0.004));  // the wall's back
}

// Single linkage by brute force: the reference for connected_parts.
std::set<std::vector<Eigen::Index>> brute_force_parts(const Points& points, double tolerance) {
  const Eigen::Index n = points.rows();
  std::vector<int> label(std::size_t(n), -1);
  int parts = 0;
  for (Eigen::Index seed = 0; seed < n; ++seed) {
    if (label[std::size_t(seed)] >= 0) continue;
    std::vector<Eigen::Index> stack{seed};
    label[std::size_t(seed)] = parts;
    while (!stack.empty()) {
      const Eigen::Index i = stack.back();
      stack.pop_back();
      for (Eigen::Index j = 0; j < n; ++j) {
        if (label[std::size_t(j)] < 0 && (points.row(i) - points.row(j)).norm() <= tolerance) {
          label[std::size_t(j)] = parts;
          stack.push_back(j);
        }
      }
    }
    ++parts;
  }
  std::vector<std::vector<Eigen::Index>> grouped(static_cast<std::size_t>(parts));
  for (Eigen::Index i = 0; i < n; ++i) grouped[std::size_t(label[std::size_t(i)])].push_back(i);
  return {grouped.begin(), grouped.end()};
}

TEST(ConnectedParts, AgreeWithSingleLinkageByBruteForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(0.0, 0.1);
  for (int trial = 0; trial < 5; ++trial) {
    Points points(600, 3);
    for (Eigen::Index i = 0; i < points.rows(); ++i)
      points.row(i) << uniform(rng), uniform(rng), uniform(rng);
    const double tolerance = 0.006 + 0.002 * trial;  // from many parts to a few
    const auto parts = connected_parts(points, tolerance);
    const std::set<std::vector<Eigen::Index>> found(parts.begin(), parts.end());
    EXPECT_EQ(found, brute_force_parts(points, tolerance)) << "tolerance " << tolerance;
    for (std::size_t k = 1; k < parts.size(); ++k) EXPECT_GE(parts[k - 1].size(), parts[k].size());
  }
}

TEST(NormalDirection, IsTheNearestOfTheTwentySixByBruteForce) {
  std::vector<Eigen::Vector3d> table;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z)
        if (x || y || z) table.push_back(Eigen::Vector3d(x, y, z).normalized());
  std::mt19937 rng(3);
  std::normal_distribution<double> gauss;
  for (int trial = 0; trial < 20000; ++trial) {
    Eigen::Vector3d n(gauss(rng), gauss(rng), gauss(rng));
    if (trial % 4 == 0) n[trial % 3] = 0.0;  // on the grid's planes too
    n.normalize();
    double best = -2.0;
    for (const auto& d : table) best = std::max(best, d.dot(n));
    const int fast = normal_direction(n);
    std::uint32_t cone = 0;
    const int slow = normal_direction(n, &cone);
    ASSERT_NEAR(table[std::size_t(fast)].dot(n), best, 1e-12) << n.transpose();
    ASSERT_NEAR(table[std::size_t(slow)].dot(n), best, 1e-12) << n.transpose();
    ASSERT_TRUE((cone >> fast) & 1u);
  }
}

TEST(ConnectedParts, ObjectsAGapApartStayApart) {
  const PointCloud left = patch(0.0, 0.0, 1.0, 0.05, 0.004, kToSensor);
  const PointCloud right = patch(0.107, 0.0, 1.0, 0.05, 0.004, kToSensor);  // a 7 mm gap
  Points points(left.points().rows() * 2, 3);
  points << left.points(), right.points();
  EXPECT_EQ(connected_parts(points, 0.006).size(), 2u);
  EXPECT_EQ(connected_parts(points, 0.008).size(), 1u);
}

TEST(SupportPlane, FindsTheTableAndTheSideTheObjectsAreOn) {
  // A 0.7 m table top at z = 0.02 seen from above, a 0.1 m box standing on it.
  const PointCloud table = patch(0.0, 0.0, 0.02, 0.35, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud top = patch(0.1, 0.1, 0.12, 0.05, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud scene = joined({table, top});
  const auto plane = support_plane(scene, 0.008, 0.4);
  ASSERT_TRUE(plane);
  EXPECT_NEAR(plane->normal.z(), 1.0, 1e-9);
  EXPECT_NEAR(plane->offset, 0.02, 1e-12);  // the median of the table's points, not a bin's edge
  EXPECT_EQ(without_support_plane(scene, *plane, 0.008, 0.012).size(),
            std::size_t(top.points().rows()));
  // Seen from below (normals and the box flipped), the plane's normal turns too.
  const Points flipped = -scene.points();
  const auto below = support_plane(PointCloud(flipped, -scene.normals()), 0.008, 0.4);
  ASSERT_TRUE(below);
  EXPECT_NEAR(below->normal.z(), -1.0, 1e-9);
  // Narrower than min_extent: no support plane.
  EXPECT_FALSE(support_plane(scene, 0.008, 2.0));
}

double rotation_error_deg(const Transform& a, const Transform& b) {
  const Eigen::Matrix3d d = a.topLeftCorner<3, 3>().transpose() * b.topLeftCorner<3, 3>();
  return Eigen::AngleAxisd(d).angle() * 180.0 / M_PI;
}

// A scene made of the model itself, independently resampled, moved by a known motion.
class IcpOnAResampledCopy : public ::testing::Test {
 protected:
  std::mt19937 rng{21};
  PointCloud model = test::box_and_sphere(4000, rng);
  Transform truth = [] {
    Transform T = Transform::Identity();
    T.topLeftCorner<3, 3>() = exp_so3(Eigen::Vector3d(0.3, -0.5, 0.8));
    T.topRightCorner<3, 1>() = Eigen::Vector3d(0.05, -0.02, 0.4);
    return T;
  }();
  PointCloud scene = test::box_and_sphere(4000, rng).transformed(truth);
};

TEST_F(IcpOnAResampledCopy, RecoversTheMotionFromAStartADegreeAndMillimetresOff) {
  Transform start = truth;
  start.topLeftCorner<3, 3>() =
      exp_so3(Eigen::Vector3d(0.01, -0.012, 0.008)) * truth.topLeftCorner<3, 3>();
  start.topRightCorner<3, 1>() += Eigen::Vector3d(0.003, -0.002, 0.002);
  const IcpOutcome outcome = refine_point_to_plane(model, scene, start, IcpSettings{});
  EXPECT_GT(outcome.iterations, 1);
  EXPECT_GT(outcome.pairs, 1500);  // of about 2000 points taking part (one in 2 of 4000)
  // Two samplings of one surface: the residual is the sampling, well under a voxel.
  EXPECT_LT(rotation_error_deg(outcome.T_scene_model, truth), 0.1);
  EXPECT_LT((outcome.T_scene_model.topRightCorner<3, 1>() - truth.topRightCorner<3, 1>()).norm(),
            0.0005);
  EXPECT_GT(rotation_error_deg(start, truth), 0.9);
}

TEST_F(IcpOnAResampledCopy, OnlyThePointsFacingTheViewpointTakePart) {
  IcpSettings settings;
  settings.viewpoint = Eigen::Vector3d(0.05, -0.02, 2.0);  // above the moved model
  const IcpOutcome seen = refine_point_to_plane(model, scene, truth, settings);
  const IcpOutcome all = refine_point_to_plane(model, scene, truth, IcpSettings{});
  EXPECT_GT(seen.pairs, 200);
  EXPECT_LT(seen.pairs, all.pairs * 3 / 4);
}

TEST_F(IcpOnAResampledCopy, FarFromTheSceneThePoseIsReturnedUnchanged) {
  const Transform away = test::translation(Eigen::Vector3d(1.0, 0.0, 0.0)) * truth;
  const IcpOutcome outcome = refine_point_to_plane(model, scene, away, IcpSettings{});
  EXPECT_EQ(outcome.iterations, 0);
  EXPECT_TRUE(outcome.T_scene_model.isApprox(away));
}

// The nearest scene point within `max_distance` whose normal agrees, by trying every one.
double brute_force_nearest(const PointCloud& scene, const Eigen::Vector3d& p,
                           const Eigen::Vector3d& n, double max_distance, double min_cosine) {
  double best = max_distance * max_distance;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
    const double squared = (scene.points().row(i).transpose() - p).squaredNorm();
    if (squared < best && scene.normals().row(i).dot(n) >= min_cosine) best = squared;
  }
  return best;
}

TEST(IcpScene, FindsTheNearestAgreeingPointAsBruteForceDoes) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(0.0, 0.1);
  std::normal_distribution<double> gauss;
  const auto direction = [&] {
    return Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
  };
  Points points(3000, 3), normals(3000, 3);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    points.row(i) << uniform(rng), uniform(rng), uniform(rng);
    normals.row(i) = direction().transpose();
  }
  const PointCloud scene(points, normals);
  const double reach = 0.01;  // cells of 1 cm
  const Eigen::AlignedBox3d around(Eigen::Vector3d::Constant(-0.02),
                                   Eigen::Vector3d::Constant(0.12));
  const IcpScene grid(scene, around, reach);
  int found = 0;
  for (int query = 0; query < 3000; ++query) {
    const Eigen::Vector3d p(uniform(rng) * 1.2 - 0.01, uniform(rng), uniform(rng));
    const Eigen::Vector3d n = direction();
    const double distance = reach * (query % 3 == 0 ? 0.4 : 1.0);
    const Eigen::Index row = grid.nearest(p, n, distance, 0.5);
    const double best = brute_force_nearest(scene, p, n, distance, 0.5);
    if (row < 0) {
      EXPECT_EQ(best, distance * distance) << "query " << query;
      continue;
    }
    ++found;
    EXPECT_EQ((points.row(row).transpose() - p).squaredNorm(), best) << "query " << query;
    EXPECT_GE(normals.row(row).dot(n), 0.5);
  }
  EXPECT_GT(found, 1000);
}

TEST(IcpScene, OfEquallyNearPointsTakesTheOneInTheFirstCell) {
  // Queries on a cell boundary, exactly midway between two points (all values binary
  // fractions): the point of the lower cell, although the query's own cell is the upper.
  Points points(3, 3), normals(3, 3);
  points << 0.125, 0.5, 0.5, 0.375, 0.5, 0.5, 0.625, 0.5, 0.5;
  normals << 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0;
  const PointCloud scene(points, normals);
  const IcpScene grid(scene, Eigen::AlignedBox3d(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()),
                      0.25);
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  EXPECT_EQ(grid.nearest(Eigen::Vector3d(0.25, 0.5, 0.5), up, 0.25, 0.5), 0);
  EXPECT_EQ(grid.nearest(Eigen::Vector3d(0.5, 0.5, 0.5), up, 0.25, 0.5), 1);
  EXPECT_EQ(grid.nearest(Eigen::Vector3d(0.26, 0.5, 0.5), up, 0.25, 0.5), 1);  // no tie
}

TEST(Icp, AFlatModelKilometresWideNeedsNoHugeGrid) {
  // A 2 km x 2 km sheet at 8 mm pairs would be 6e10 cells: the cells grow instead.
  const PointCloud sheet = patch(0.0, 0.0, 0.0, 1000.0, 50.0, Eigen::Vector3d::UnitZ());
  Transform nudged = Transform::Identity();
  nudged(2, 3) = 0.004;
  const IcpOutcome outcome = refine_point_to_plane(sheet, sheet, nudged, IcpSettings{});
  EXPECT_GT(outcome.iterations, 0);
  EXPECT_NEAR(outcome.T_scene_model(2, 3), 0.0, 1e-6);  // back onto the plane
}

}  // namespace
}  // namespace spectral_vs::detail

namespace spectral_vs::detail {
namespace {

// Brute force: a point is in reach when every coordinate is within max_translation of
// the model's box; the bounded grid then holds the model's box with that room on both
// sides at most (plus a voxel of margin and the FFT-friendly rounding), however far the
// rest of the scene reaches.
TEST(BoundedGrid, KeepsTheSceneInReachOfTheModel) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(-2.0, 2.0);
  Points scene(5000, 3);
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    scene.row(i) << uniform(rng), uniform(rng), uniform(rng);
  }
  const Eigen::AlignedBox3d model(Eigen::Vector3d(-0.4, -0.3, 0.45),
                                  Eigen::Vector3d(0.4, 0.3, 0.55));
  const double reach = 0.3, voxel = 0.015;
  const Points kept = points_in_reach(scene, model, reach);
  Eigen::Index expected = 0;
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      inside =
          inside && scene(i, a) >= model.min()[a] - reach && scene(i, a) <= model.max()[a] + reach;
    }
    if (!inside) continue;
    ASSERT_LT(expected, kept.rows());
    EXPECT_EQ(kept.row(expected), scene.row(i));  // in the scene's order
    ++expected;
  }
  EXPECT_EQ(kept.rows(), expected);
  const GridSpec bounded =
      bounded_translation_spec(points_box(kept), model, reach, voxel, GridLimits{});
  // The whole 4 m scene at 1.5 cm is 320^3 voxels, over the default limit of 256^3.
  const GridSpec unbounded = bounded_translation_spec(points_box(scene), model, reach, voxel,
                                                      GridLimits{std::size_t{1} << 27});
  for (int a = 0; a < 3; ++a) {
    const int needed = int(std::ceil((model.sizes()[a] + 2 * reach) / voxel)) + 3;
    EXPECT_LE(bounded.dims[a], fft_friendly_size(needed)) << a;
    EXPECT_LE(bounded.origin[a], model.min()[a] - reach) << a;  // holds every shifted model
    EXPECT_GE(bounded.origin[a] + bounded.dims[a] * voxel, model.max()[a] + reach) << a;
    EXPECT_GT(unbounded.dims[a], bounded.dims[a]) << a;
  }
  // None in reach: the whole scene (the search then fails as before, not on an empty grid).
  const Eigen::AlignedBox3d far(Eigen::Vector3d::Constant(10.0), Eigen::Vector3d::Constant(11.0));
  EXPECT_EQ(points_in_reach(scene, far, reach).rows(), scene.rows());
}

// A window around a model whose reach is larger than the scene is wide holds, on each
// such axis, only the scene's extent and the margin: a smaller grid that finds the same
// shift (phase correlation: within a millimetre at 10 mm voxels).
TEST(TranslationWindow, OnAnAxisNarrowerInTheSceneHoldsOnlyTheScene) {
  std::mt19937 rng(8);
  const PointCloud model = test::box_and_sphere(6000, rng);
  const Eigen::Vector3d shift(0.031, -0.017, 0.012);
  const PointCloud scene = model.transformed(test::translation(shift));
  const SceneMap map(scene);
  const double reach = 0.2, margin = 0.05, voxel = 0.01;
  const Eigen::Vector3d centre = scene.centroid();
  TranslationWindow window(map, reach, margin, centre, voxel, Occupancy::trilinear,
                           PhaseCorrelationParams{}, GridLimits{});
  const int cube = fft_friendly_size(int(std::ceil(2.0 * (reach + margin) / voxel)) + 3);  // 64
  const Eigen::AlignedBox3d box = bounding_box(scene);
  for (int a = 0; a < 3; ++a) {
    const int scene_voxels =
        fft_friendly_size(int(std::ceil((box.sizes()[a] + 2 * margin) / voxel)) + 3);
    EXPECT_EQ(window.dims()[a], std::min(cube, scene_voxels)) << a;
    EXPECT_LT(window.dims()[a], cube) << a;  // the scene is under 0.3 m on every axis
  }
  const TranslationEstimate estimate = window.estimate(model.points());
  EXPECT_LT((estimate.shift - shift).norm(), 0.001) << estimate.shift.transpose();
}

// Model points past a window that holds only the scene's extent still weigh in the
// overlap, at the energy per point of those inside. Binary voxels, one point per voxel:
// a 20 x 20 patch matched by a model with as many points again 0.3 m above it (beyond
// the window, inside the model's cube) overlaps by 400 / sqrt(800 * 400) = 1 / sqrt(2).
TEST(TranslationWindow, CountsModelPointsPastTheWindowInTheOverlap) {
  const double voxel = 0.01;
  Points patch(400, 3), model(800, 3);
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) {
      const Eigen::RowVector3d p((i + 0.5) * voxel, (j + 0.5) * voxel, 0.5 * voxel);
      patch.row(20 * i + j) = p;
      model.row(20 * i + j) = p;
      model.row(400 + 20 * i + j) = p + Eigen::RowVector3d(0.0, 0.0, 0.3);
    }
  const PointCloud scene(patch);
  const SceneMap map(scene);
  TranslationWindow window(map, 0.3, 0.05, Eigen::Vector3d(0.1, 0.1, 0.005), voxel,
                           Occupancy::binary, PhaseCorrelationParams{}, GridLimits{});
  EXPECT_NEAR(window.overlap(patch), 1.0, 1e-9);
  EXPECT_NEAR(window.overlap(model), 1.0 / std::sqrt(2.0), 1e-9);
}

}  // namespace
}  // namespace spectral_vs::detail

namespace spectral_vs::detail {
namespace {

// The fitness by its definition, pair by pair: a model voxel is supported when one of its
// points and a scene point at most one voxel away on each axis have normals that agree:
// the model normal's nearest of the 26 directions to a voxel's neighbours is the scene
// normal's nearest, or within 50 degrees of the scene normal. Model voxels outside the
// grid count, unsupported.
double brute_force_fitness(const PointCloud& scene, const GridSpec& spec, const Points& points,
                           const Points& normals) {
  std::vector<Eigen::Vector3d> directions;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z)
        if (x || y || z) directions.push_back(Eigen::Vector3d(x, y, z).normalized());
  const auto nearest = [&](const Eigen::Vector3d& n) {
    std::size_t best = 0;
    for (std::size_t d = 1; d < directions.size(); ++d)
      if (directions[d].dot(n) > directions[best].dot(n)) best = d;
    return best;
  };
  const auto voxel = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector3i(((p - spec.origin) / spec.resolution).array().floor().cast<int>());
  };
  std::map<std::array<int, 3>, bool> supported;  // per model voxel
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3i v = voxel(points.row(i).transpose());
    bool& support = supported[{v.x(), v.y(), v.z()}];
    if (!spec.contains(v)) continue;
    const Eigen::Vector3d& d = directions[nearest(normals.row(i).transpose())];
    for (Eigen::Index j = 0; j < scene.points().rows() && !support; ++j) {
      const Eigen::Vector3i u = voxel(scene.points().row(j).transpose());
      const Eigen::Vector3d m = scene.normals().row(j).transpose();
      support = (u - v).cwiseAbs().maxCoeff() <= 1 &&
                (d.dot(m) > 0.6428 || d == directions[nearest(m)]);  // cos(50 degrees)
    }
  }
  const auto count = std::count_if(supported.begin(), supported.end(),
                                   [](const auto& voxel_support) { return voxel_support.second; });
  return double(count) / double(supported.size());
}

// The one fitness, recorded over the whole scene (align()'s verification) or around the
// model only (ModelAligner's), against the definition: the box and ball placed, moved half a
// voxel, turned by 40 degrees, and reaching out of the scene's grid.
TEST(Fitness, IsTheShareOfModelVoxelsWithAgreeingSceneNormalsNearby) {
  std::mt19937 rng(21);
  const PointCloud sample = test::box_and_sphere(3000, rng);
  std::normal_distribution<double> noise(0.0, 5e-4);
  Points jittered = sample.points();
  for (Eigen::Index i = 0; i < jittered.rows(); ++i)
    jittered.row(i) += Eigen::RowVector3d(noise(rng), noise(rng), noise(rng));
  const PointCloud scene(jittered, sample.normals());
  const PointCloud model = test::box_and_sphere(1500, rng);
  const double voxel = 0.01;
  const GridSpec spec = FitnessMap::spec_of(scene, voxel, GridLimits{});
  const Verifier whole(scene, voxel, std::nullopt, spec);
  const Verifier around(scene, voxel, std::nullopt, spec, FitnessMap::Coverage::around_model);
  Transform turned = Transform::Identity();
  turned.topLeftCorner<3, 3>() = exp_so3(Eigen::Vector3d(0.0, 0.0, 40.0 * M_PI / 180.0));
  const std::vector<Transform> poses = {Transform::Identity(),
                                        test::translation(Eigen::Vector3d(0.005, 0.0, 0.003)),
                                        turned, test::translation(Eigen::Vector3d(0.2, 0.0, 0.0))};
  std::vector<double> scores;
  for (const Transform& pose : poses) {
    const PointCloud moved = model.transformed(pose);
    const double expected = brute_force_fitness(scene, spec, moved.points(), moved.normals());
    EXPECT_EQ(whole.fitness(moved.points(), moved.normals(), voxel), expected);
    EXPECT_EQ(around.fitness(moved.points(), moved.normals(), voxel), expected);
    scores.push_back(expected);
  }
  EXPECT_GT(scores[0], 0.9);        // in place
  EXPECT_GT(scores[1], 0.9);        // half a voxel off: still within one voxel
  EXPECT_LT(scores[2], scores[0]);  // turned: the box's faces no longer agree
  EXPECT_LT(scores[3], 0.5);        // mostly outside the scene's grid
  EXPECT_EQ(around.fitness(Points(0, 3), Points(0, 3), voxel), 0.0);
}

// The six faces of an axis-aligned box of the given sizes, centred at the origin, sampled
// every `step` metres, with outward normals.
PointCloud box_cloud(const Eigen::Vector3d& size, double step) {
  std::vector<Eigen::Vector3d> points, normals;
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (double a = -size(u) / 2; a <= size(u) / 2 + 1e-12; a += step)
      for (double b = -size(v) / 2; b <= size(v) / 2 + 1e-12; b += step)
        for (const double side : {-1.0, 1.0}) {
          Eigen::Vector3d p, n = Eigen::Vector3d::Zero();
          p(axis) = 0.5 * side * size(axis);
          p(u) = a;
          p(v) = b;
          n(axis) = side;
          points.push_back(p);
          normals.push_back(n);
        }
  }
  Points p(Eigen::Index(points.size()), 3), n(p.rows(), 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    p.row(Eigen::Index(i)) = points[i].transpose();
    n.row(Eigen::Index(i)) = normals[i].transpose();
  }
  return PointCloud(p, n);
}

TEST(SupportPlane, ItsBandStaysUnderAThinModel) {
  // 1.5 voxels for a model thicker than 4 of them; 0.4 of a plate's 9 mm, but no less
  // than half a voxel; the thinnest axis found whatever the box's orientation.
  EXPECT_NEAR(support_band(box_cloud({0.10, 0.08, 0.06}, 0.002).points(), 0.008), 0.012, 1e-12);
  EXPECT_NEAR(support_band(box_cloud({0.12, 0.09, 0.009}, 0.002).points(), 0.004), 0.0036, 1e-5);
  EXPECT_NEAR(support_band(box_cloud({0.12, 0.09, 0.009}, 0.002).points(), 0.008), 0.004, 1e-12);
  const Eigen::Matrix3d R = exp_so3(Eigen::Vector3d(0.3, -0.5, 0.9));
  const Points turned = box_cloud({0.009, 0.12, 0.09}, 0.002).points() * R.transpose();
  EXPECT_NEAR(support_band(turned, 0.004), 0.0036, 1e-5);
}

TEST(SupportPlane, APlateLyingOnTheTableIsNotTakenForIt) {
  // A 9 mm plate and a 0.1 m box on the table at z = 0.02: the plate's top face is 9 mm
  // above the plane, inside the 1.5-voxel band at 8 mm voxels, outside the plate's own.
  const PointCloud table = patch(0.0, 0.0, 0.02, 0.35, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud plate = patch(-0.1, -0.1, 0.029, 0.05, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud box = patch(0.1, 0.1, 0.12, 0.05, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud scene = joined({table, plate, box});
  const auto objects = std::size_t(box.points().rows());
  const auto plane = support_plane(scene, 0.008, 0.4);
  ASSERT_TRUE(plane);
  EXPECT_NEAR(plane->offset, 0.02, 1e-12);
  EXPECT_EQ(without_support_plane(scene, *plane, 0.008, 0.012).size(), objects);
  const double band = support_band(box_cloud({0.12, 0.09, 0.009}, 0.002).points(), 0.008);
  EXPECT_EQ(without_support_plane(scene, *plane, 0.008, band).size(), 2 * objects);
}

TEST(PartCoverage, IsTheShareOfItsPartThatAPoseExplains) {
  // On a table at z = 0: a tile's top face (40 mm square, 9 x 9 points 5 mm apart) 10 mm
  // up and a box's top face (100 mm square, 21 x 21 points) 60 mm up. The model is the
  // tile's face. On the tile it explains all 81 of its points; centred on the box it
  // explains the box's points within a voxel (8 mm) of its square, 11 x 11 of 441.
  const PointCloud table = patch(0.0, 0.0, 0.0, 0.35, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud tile = patch(-0.15, -0.15, 0.01, 0.02, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud box = patch(0.15, 0.15, 0.06, 0.05, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud scene = joined({table, tile, box});
  const PointCloud model = patch(0.0, 0.0, 0.0, 0.02, 0.005, Eigen::Vector3d::UnitZ());
  const SupportPlane plane{Eigen::Vector3d::UnitZ(), 0.0};
  const PartCoverage coverage(scene, plane, 0.004, 0.008);
  const auto at = [](double x, double y, double z) {
    Transform T = Transform::Identity();
    T.topRightCorner<3, 1>() = Eigen::Vector3d(x, y, z);
    return T;
  };
  EXPECT_DOUBLE_EQ(coverage.explained_share(model, at(-0.15, -0.15, 0.01)), 1.0);
  EXPECT_DOUBLE_EQ(coverage.explained_share(model, at(0.15, 0.15, 0.06)), 121.0 / 441.0);
  // 20 mm off the tile: 6 of its 9 columns. Away from both, or on the table alone: none.
  EXPECT_DOUBLE_EQ(coverage.explained_share(model, at(-0.13, -0.15, 0.01)), 54.0 / 81.0);
  EXPECT_DOUBLE_EQ(coverage.explained_share(model, at(0.0, 0.0, 0.3)), 0.0);
  EXPECT_DOUBLE_EQ(coverage.explained_share(model, at(0.0, 0.0, 0.0)), 0.0);
}

Transform translation(double x, double y, double z) {
  Transform T = Transform::Identity();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(x, y, z);
  return T;
}

TEST(RestingFaces, AreABoxsSixFacesLargestFirst) {
  const auto faces = resting_faces(box_cloud({0.10, 0.06, 0.02}, 0.002), 0.001);
  ASSERT_EQ(faces.size(), 6u);
  // The 100 x 60 mm faces first, then the 100 x 20 mm ones, then the 60 x 20 mm ones.
  const std::array<int, 6> axes = {2, 2, 1, 1, 0, 0};
  for (std::size_t k = 0; k < faces.size(); ++k) {
    EXPECT_NEAR(std::abs(faces[k](axes[k])), 1.0, 1e-9) << k;
    EXPECT_NEAR(faces[k].norm(), 1.0, 1e-12);
  }
  EXPECT_NEAR(faces[0].dot(faces[1]), -1.0, 1e-9);
  // Sampled every millimetre (about 19,000 points, strided to about 5,000): the same.
  const auto dense = resting_faces(box_cloud({0.10, 0.06, 0.02}, 0.001), 0.001);
  ASSERT_EQ(dense.size(), 6u);
  for (std::size_t k = 0; k < dense.size(); ++k)
    EXPECT_NEAR(std::abs(dense[k](axes[k])), 1.0, 1e-9) << k;
}

TEST(RestingFaces, ASphereHasNone) {
  // Within 1 mm of a supporting plane of a sphere of radius 50 mm lies a cap of
  // 1 / 100 of its surface: under the 2% of a face.
  const int n = 4000;
  Points p(n, 3), normals(n, 3);
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n, r = std::sqrt(1.0 - z * z);
    const double phi = M_PI * (3.0 - std::sqrt(5.0)) * i;
    normals.row(i) << r * std::cos(phi), r * std::sin(phi), z;
    p.row(i) = 0.05 * normals.row(i);
  }
  EXPECT_TRUE(resting_faces(PointCloud(p, normals), 0.001).empty());
}

TEST(RestingRotations, PutTheFaceDownAndTurnEvenlyAboutUp) {
  const Eigen::Vector3d face = Eigen::Vector3d(0.3, -0.4, 0.5).normalized();
  const Eigen::Vector3d up = Eigen::Vector3d(0.1, 0.2, 1.0).normalized();
  const auto rotations = resting_rotations(face, up, 24);
  ASSERT_EQ(rotations.size(), 24u);
  for (std::size_t k = 0; k < rotations.size(); ++k) {
    EXPECT_NEAR((rotations[k] * face + up).norm(), 0.0, 1e-12) << k;
    EXPECT_NEAR(rotations[k].determinant(), 1.0, 1e-12);
    const Eigen::Matrix3d& next = rotations[(k + 1) % rotations.size()];
    EXPECT_NEAR(rotation_distance(rotations[k], next) * 180.0 / M_PI, 15.0, 1e-9) << k;
  }
}

TEST(RestingCheck, TellsAPoseOnTheTableOrAnObjectFromOneInsideOrUnderIt) {
  // A table at z = 0 and a box's top face 30 mm up (100 mm square at x = y = 0.15). The
  // model is a 40 x 40 x 10 mm slab; voxels of 6 mm (a gap of 9 mm).
  const PointCloud table = patch(0.0, 0.0, 0.0, 0.35, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud box = patch(0.15, 0.15, 0.03, 0.05, 0.005, Eigen::Vector3d::UnitZ());
  const PointCloud scene = joined({table, box});
  const RestingCheck check(scene, SupportPlane{Eigen::Vector3d::UnitZ(), 0.0}, 0.006);
  const PointCloud slab = box_cloud({0.04, 0.04, 0.01}, 0.002);
  EXPECT_TRUE(check.rests(slab, translation(-0.15, -0.15, 0.005)));  // on the table
  EXPECT_TRUE(check.rests(slab, translation(-0.15, -0.15, 0.012)));  // 7 mm up: within 9
  EXPECT_TRUE(check.rests(slab, translation(0.15, 0.15, 0.035)));    // on the box
  // Its top face flush with the box's, the rest inside the box: 15 mm above the table,
  // the box's face above its bottom.
  EXPECT_FALSE(check.rests(slab, translation(0.15, 0.15, 0.025)));
  EXPECT_FALSE(check.rests(slab, translation(-0.15, -0.15, 0.05)));   // 45 mm up, nothing under
  EXPECT_FALSE(check.rests(slab, translation(-0.15, -0.15, -0.01)));  // sunk 15 mm into the table
}

}  // namespace
}  // namespace spectral_vs::detail
