// The verdict stage: the calibration maps, the verdict's order, the voxel's range and the
// pose covariance against closed forms; align() and align_views() carry their verdict.
#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/verdict.hpp>
#include <spectral_vs/alignment/view_aligner.hpp>
#include <spectral_vs/rotation/so3.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "test_support.hpp"

namespace spectral_vs {
namespace {

using test::box_and_sphere;

TEST(CalibratedConfidence, IsMonotoneWithinZeroAndOne) {
  for (const RegistrationKind kind :
       {RegistrationKind::model_to_scene, RegistrationKind::view_to_view,
        RegistrationKind::servo_step, RegistrationKind::servo_carried}) {
    double previous = calibrated_confidence(0.0, kind);
    EXPECT_GE(previous, 0.0);
    for (int i = 1; i <= 1000; ++i) {
      const double p = calibrated_confidence(i / 1000.0, kind);
      EXPECT_GE(p, previous - 1e-12) << "score " << i / 1000.0;
      EXPECT_LE(p, 1.0);
      previous = p;
    }
    // Outside [0, 1] the score is clamped; a NaN score is no evidence.
    EXPECT_EQ(calibrated_confidence(-3.0, kind), calibrated_confidence(0.0, kind));
    EXPECT_EQ(calibrated_confidence(7.0, kind), calibrated_confidence(1.0, kind));
    EXPECT_EQ(calibrated_confidence(std::nan(""), kind), 0.0);
  }
}

TEST(VerdictOf, NamesTheFirstReasonNotToAct) {
  VerdictInputs in;
  in.confidence = 0.99;
  in.supported = true;
  EXPECT_EQ(verdict_of(in), Verdict::reliable);
  in.ambiguous = true;
  EXPECT_EQ(verdict_of(in), Verdict::ambiguous);
  in.determined = false;
  EXPECT_EQ(verdict_of(in), Verdict::undetermined);
  in.rests = false;
  EXPECT_EQ(verdict_of(in), Verdict::floating);  // floating before undetermined
  in.confidence = kReliableConfidence - 1e-9;
  EXPECT_EQ(verdict_of(in), Verdict::doubtful);  // low confidence first, then ambiguity
  in.supported = false;
  EXPECT_EQ(verdict_of(in), Verdict::no_support);
  in.scale_ok = false;
  EXPECT_EQ(verdict_of(in), Verdict::bad_scale);
  in.timed_out = true;
  EXPECT_EQ(verdict_of(in), Verdict::max_seconds);
  EXPECT_STREQ(verdict_name(Verdict::no_support), "no_support");
  EXPECT_STREQ(verdict_name(Verdict::floating), "floating");
}

TEST(VoxelInRange, IsHalfToAThousandthOfTheExtent) {
  EXPECT_TRUE(voxel_in_range(0.008, 0.1));
  EXPECT_TRUE(voxel_in_range(0.05, 0.1));
  EXPECT_FALSE(voxel_in_range(0.0501, 0.1));
  EXPECT_TRUE(voxel_in_range(1e-4, 0.1));
  EXPECT_FALSE(voxel_in_range(0.99e-4, 0.1));
  EXPECT_FALSE(voxel_in_range(0.008, 0.0));  // one point: no scale to judge
}

// A square patch of z = 0, side `side` metres, `n` x `n` points, normals +z.
PointCloud square_patch(int n, double side, double noise_sigma, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, noise_sigma);
  Points points(n * n, 3), normals(n * n, 3);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const int row = i * n + j;
      points.row(row) << side * (i + 0.5) / n - side / 2, side * (j + 0.5) / n - side / 2,
          noise_sigma > 0 ? noise(rng) : 0.0;
      normals.row(row) << 0, 0, 1;
    }
  }
  return PointCloud(points, normals);
}

// Sums over the points of a patch centred at the origin: N, sum x^2 (= sum y^2).
struct PatchSums {
  double N = 0.0, x2 = 0.0;
};
PatchSums sums_of(const PointCloud& patch) {
  PatchSums s;
  s.N = double(patch.points().rows());
  s.x2 = patch.points().col(0).squaredNorm();
  return s;
}

// On a plane the point-to-plane information is block diagonal in closed form: N along z,
// sum y^2 and sum x^2 for the rotations about x and y; the rest is the prior alone. With
// independent noise of variance s^2 the sandwich is k s^2 / N along z and k s^2 / sum x^2
// about x and y, within its sampling error over about 350 cells (7.5%).
TEST(PoseCovariance, MatchesTheClosedFormOfAPlaneWithIndependentNoise) {
  std::mt19937 rng(3);
  const int n = 60;
  const double side = 0.3, sigma = 0.0005, voxel = 0.004;
  const PointCloud scene = square_patch(n, side, 0.0, rng);
  const PointCloud model = square_patch(n, side, sigma, rng);
  const PoseCovariance C = pose_covariance(model, scene, Transform::Identity(), voxel);
  ASSERT_TRUE(C.allFinite());
  EXPECT_LT((C - C.transpose()).norm(), 1e-12 * C.norm());
  const PatchSums s = sums_of(model);
  const double k = covariance_inflation(RegistrationKind::model_to_scene);
  const double v = sigma * sigma;
  EXPECT_NEAR(C(5, 5), k * v / s.N, 0.25 * k * v / s.N);    // t_z
  EXPECT_NEAR(C(0, 0), k * v / s.x2, 0.25 * k * v / s.x2);  // about x
  EXPECT_NEAR(C(1, 1), k * v / s.x2, 0.25 * k * v / s.x2);  // about y
  // Unconstrained by a plane: about z, along x and y. The prior: pi rad, the typical size.
  EXPECT_NEAR(C(2, 2), M_PI * M_PI, 0.01 * M_PI * M_PI);
  EXPECT_GT(C(3, 3), 0.1 * side * side);
  EXPECT_GT(C(4, 4), 0.1 * side * side);
}

// Noise shared by every point of a cell of 4 voxels (as a structured-light sensor's is
// over its neighbourhoods) counts once per cell: along z the variance is k s^2 / cells,
// not k s^2 / points (here 16 times less).
TEST(PoseCovariance, CountsACellOfSharedNoiseOnce) {
  std::mt19937 rng(4);
  const int n = 120;
  const double side = 0.3, sigma = 0.0005, voxel = 0.005;
  const double cell = 4.0 * voxel;
  const PointCloud scene = square_patch(n, side, 0.0, rng);
  Points points = scene.points();
  std::normal_distribution<double> noise(0.0, sigma);
  std::map<std::pair<long, long>, double> offsets;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const auto key = std::make_pair(long(std::floor(points(i, 0) / cell)),
                                    long(std::floor(points(i, 1) / cell)));
    auto [entry, added] = offsets.try_emplace(key, 0.0);
    if (added) entry->second = noise(rng);
    points(i, 2) = entry->second;
  }
  const PointCloud model(points, scene.normals());
  const PoseCovariance C = pose_covariance(model, scene, Transform::Identity(), voxel);
  const double k = covariance_inflation(RegistrationKind::model_to_scene);
  const double cells = double(offsets.size());
  const double expected = k * sigma * sigma / cells;
  EXPECT_NEAR(C(5, 5), expected, 0.25 * expected) << cells << " cells";
  EXPECT_GT(C(5, 5), 8.0 * k * sigma * sigma / double(points.rows()));
}

// The covariance of a left perturbation at T is the one at the identity moved into the
// scene frame: Ad(T) C Ad(T)^T, with the adjoint [[R, 0], [hat(t) R, R]].
TEST(PoseCovariance, MovesWithThePoseByTheAdjoint) {
  std::mt19937 rng(5);
  const PointCloud model = box_and_sphere(3000, rng);
  const double voxel = 0.01;
  const PoseCovariance at_identity = pose_covariance(model, model, Transform::Identity(), voxel);
  const Eigen::Matrix3d R = exp_so3(Eigen::Vector3d(0.3, -0.5, 0.8));
  const Eigen::Vector3d t(0.2, -0.1, 0.4);
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = t;
  const PoseCovariance moved = pose_covariance(model, model.transformed(T), T, voxel);
  Eigen::Matrix<double, 6, 6> adjoint = Eigen::Matrix<double, 6, 6>::Zero();
  adjoint.topLeftCorner<3, 3>() = R;
  adjoint.bottomRightCorner<3, 3>() = R;
  adjoint.bottomLeftCorner<3, 3>() = hat(t) * R;
  const PoseCovariance expected = adjoint * at_identity * adjoint.transpose();
  // The prior is isotropic in rotation and translation apart, and the exact copy's
  // variance is floored alike at both poses: equal up to float rounding of the points.
  EXPECT_LT((moved - expected).norm(), 0.02 * expected.norm());
}

TEST(AlignVerdict, AWholeModelOntoItsCopyIsReliable) {
  std::mt19937 rng(7);
  const PointCloud model = box_and_sphere(4000, rng);
  const Transform T_true = test::translation({0.05, -0.02, 0.03});
  const AlignResult r = align(model, model.transformed(T_true));
  EXPECT_TRUE(r.reliable) << verdict_name(r.status) << " confidence " << r.confidence;
  EXPECT_EQ(r.status, Verdict::reliable);
  EXPECT_TRUE(r.converged);
  EXPECT_GT(r.confidence, kReliableConfidence);
  EXPECT_GE(r.inlier_fraction, 0.9);
  EXPECT_TRUE(r.covariance.allFinite());
  EXPECT_GT(r.covariance.diagonal().minCoeff(), 0.0);
}

TEST(AlignVerdict, AVoxelOverHalfTheModelIsBadScale) {
  std::mt19937 rng(7);
  const PointCloud model = box_and_sphere(500, rng);  // typical size about 0.2 m
  AlignParams params;
  params.scene.voxel_size = 0.3;
  const AlignResult r = align(model, model, params);
  EXPECT_FALSE(r.reliable);
  EXPECT_EQ(r.status, Verdict::bad_scale);
}

TEST(AlignVerdict, AModelWithoutVerificationIsUnverified) {
  std::mt19937 rng(7);
  const PointCloud model = box_and_sphere(2000, rng);
  AlignParams params;
  params.search.global_search = false;
  params.verification.verify = false;
  const AlignResult r = align(model, model, params);
  EXPECT_FALSE(r.reliable);
  EXPECT_EQ(r.status, Verdict::unverified);
}

// Two views that share nothing: a box and ball seen from its front, and a far plane.
TEST(ViewVerdict, ViewsThatShareNothingAreNotReliable) {
  std::mt19937 rng(11);
  PointCloud reference = box_and_sphere(6000, rng).transformed(test::translation({0, 0, 1.0}));
  PointCloud current = square_patch(80, 1.5, 0.0, rng).transformed(test::translation({0, 0, 2}));
  // Normals toward the sensors at the origin.
  Points turned = current.normals() * -1.0;
  current = PointCloud(current.points(), turned);
  const ViewAlignResult r = align_views(reference, current);
  EXPECT_FALSE(r.reliable) << verdict_name(r.status) << " confidence " << r.confidence;
  EXPECT_LT(r.confidence, kReliableConfidence);
}

}  // namespace
}  // namespace spectral_vs
