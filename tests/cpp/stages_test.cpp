// The stages on their own (stages.hpp), each against a known truth rather than through
// align(): the hypotheses of the global search, the refinement's two steps (both modes')
// and Algorithm 1 from one hypothesis, the model's near-symmetries the alternatives start
// from, and the one verdict of both modes.

#include "alignment/alternatives.hpp"
#include "alignment/hypotheses.hpp"
#include "alignment/polish.hpp"
#include "alignment/prepared.hpp"
#include "alignment/refinement.hpp"
#include "alignment/reselection.hpp"
#include "alignment/scale.hpp"
#include "alignment/verdict_detail.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace spectral_vs::detail {
namespace {

constexpr double kDeg = M_PI / 180.0;

double angle_deg(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle() / kDeg; }

Eigen::Matrix3d about(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * kDeg, axis.normalized()).toRotationMatrix();
}

// The box with a sphere beside it (no symmetry), and a second sample of it moved by a
// known pose with 0.5 mm of noise: the scene.
struct MovedObject {
  PointCloud model, scene;
  Transform T_scene_model = Transform::Identity();
  AlignParams params;

  explicit MovedObject(unsigned seed) {
    std::mt19937 rng(seed);
    model = test::box_and_sphere(6000, rng);
    const PointCloud other = test::box_and_sphere(6000, rng);
    T_scene_model.topLeftCorner<3, 3>() = about({1.0, 2.0, 3.0}, 70.0);
    T_scene_model.topRightCorner<3, 1>() << 0.3, -0.1, 0.2;
    const Eigen::Matrix3d R = T_scene_model.topLeftCorner<3, 3>();
    std::normal_distribution<double> noise(0.0, 0.0005);
    Points points = (other.points() * R.transpose()).rowwise() +
                    T_scene_model.topRightCorner<3, 1>().transpose();
    for (Eigen::Index i = 0; i < points.size(); ++i) points.data()[i] += noise(rng);
    scene = PointCloud(points, other.normals() * R.transpose());
    params.scene.voxel_size = 0.008;
  }

  std::pair<double, double> error(const Transform& T) const {
    return test::pose_error(T, T_scene_model, model.centroid());
  }
};

// What align() builds before its stages (aligner.cpp, align_globally).
struct Stages {
  explicit Stages(const MovedObject& o)
      : moving(o.model),
        prepared(o.model, o.scene, o.params, moving),
        search_voxel(
            search_voxel_size(o.scene, moving.reach(), o.params.search, o.params.scene.voxel_size)),
        problem(prepared.problem(
            moving, o.params,
            window_margin(o.params.search, o.params.scene.voxel_size, search_voxel),
            Clock::time_point::max(),
            flat_axis(prepared.model_coefficients, o.params.scene.bandwidth),
            dense_for_polish(o.model.points(), o.params.scene.voxel_size))) {}

  ScoredModel moving;
  Prepared prepared;
  double search_voxel;
  Problem problem;
};

TEST(Hypotheses, TheFittestIsTheTruePoseWithinTheSearchGrid) {
  for (const unsigned seed : {1u, 2u}) {
    const MovedObject object(seed);
    Stages stages(object);
    const std::vector<Hypothesis> hypotheses = global_hypotheses(
        stages.problem, object.params.search, object.params.local, stages.prepared.correlation,
        stages.prepared.scene_coefficients, stages.search_voxel);
    ASSERT_FALSE(hypotheses.empty());
    EXPECT_LE(int(hypotheses.size()), object.params.search.hypotheses);
    for (std::size_t i = 1; i < hypotheses.size(); ++i)
      EXPECT_GE(hypotheses[i - 1].fitness, hypotheses[i].fitness) << "ranked fittest first";
    // The grid's nodes are pi / B = 11 degrees apart, refined on the EGI correlation; the
    // placement is on a grid of search voxels (16 mm).
    const auto [degrees, metres] =
        object.error(stages.moving.transform_of(hypotheses.front().pose));
    EXPECT_LT(degrees, 5.0) << "seed " << seed;
    EXPECT_LT(metres, 2.0 * stages.search_voxel) << "seed " << seed;
  }
}

TEST(Hypotheses, PlacedRotationsRefineEachCandidatePlaceItAndScoreItInTheSearchOrder) {
  const MovedObject object(3);
  Stages stages(object);
  const Eigen::Matrix3d R_true = object.T_scene_model.topLeftCorner<3, 3>();
  // The truth turned by 4 degrees (within the EGI correlation's basin), and a wrong turn.
  const std::vector<RotationCandidate> candidates = {{R_true * about({0.0, 1.0, 1.0}, 4.0), 0.0},
                                                     {R_true * about({1.0, 0.0, 0.0}, 120.0), 0.0}};
  const Eigen::Vector3d start = stages.problem.scene.cloud().centroid();
  const AlignParams& params = object.params;
  SceneTranslation placement(stages.problem.scene, start, stages.moving.reach(),
                             stages.search_voxel, params.scene.occupancy, phase_params(params),
                             params.limits);
  const Eigen::Vector3d start_offset = start - stages.moving.centroid();
  const auto place = [&](const Points& at) { return placement.estimate(at).shift; };
  std::vector<int> scored;
  const auto score = [&](Hypothesis& h) {
    scored.push_back(h.index);
    h.fitness = 1.0 / (1.0 + h.index);
  };
  const std::vector<Hypothesis> placed =
      placed_rotations(candidates, stages.prepared.correlation, RotationRefineParams(),
                       stages.moving, start_offset, Clock::time_point::max(), place, score);
  ASSERT_EQ(placed.size(), 2u);
  EXPECT_EQ(scored, (std::vector<int>{0, 1}));
  EXPECT_EQ(placed[0].index, 0);
  EXPECT_DOUBLE_EQ(placed[1].fitness, 0.5);
  // Refined on the EGI correlation to the truth's rotation, placed on the grid of search
  // voxels over the scene.
  const auto [degrees, metres] = object.error(stages.moving.transform_of(placed[0].pose));
  EXPECT_LT(degrees, 1.0);
  EXPECT_LT(metres, stages.search_voxel);
  // Past the deadline the first is still placed, the rest left out.
  scored.clear();
  const std::vector<Hypothesis> late =
      placed_rotations(candidates, stages.prepared.correlation, RotationRefineParams(),
                       stages.moving, start_offset, Clock::time_point::min(), place, score);
  ASSERT_EQ(late.size(), 1u);
  EXPECT_EQ(late[0].pose.offset, placed[0].pose.offset);
  EXPECT_EQ(scored, (std::vector<int>{0}));
}

TEST(Refinement, BothModesKeepAlgorithmOnesEndAndTheICPByOneRuleEach) {
  // Algorithm 1's end stands unless its start scores strictly higher (ties: the end).
  EXPECT_TRUE(keeps_algorithm1(0.80, 0.80));
  EXPECT_TRUE(keeps_algorithm1(0.81, 0.80));
  EXPECT_FALSE(keeps_algorithm1(0.79, 0.80));
  // The ICP's pose stands unless it scores more than kIcpScoreLoss lower.
  EXPECT_TRUE(keeps_icp(0.80 - kIcpScoreLoss, 0.80));
  EXPECT_FALSE(keeps_icp(0.80 - kIcpScoreLoss - 1e-9, 0.80));
  EXPECT_TRUE(keeps_icp(0.90, 0.80));
}

// The refinement's first step, as both modes run it: the loop's end, scored by the mode's
// measure, unless the start scores higher; then the start itself, claiming no iterations.
TEST(Refinement, AlgorithmOneStepKeepsItsEndUnlessTheStartScoresHigher) {
  const MovedObject object(3);
  Stages stages(object);
  const double voxel = object.params.scene.voxel_size;
  Transform start_T = object.T_scene_model;
  start_T.topLeftCorner<3, 3>() = about({0.3, -1.0, 0.4}, 8.0) * start_T.topLeftCorner<3, 3>();
  start_T.topRightCorner<3, 1>() += Eigen::Vector3d(0.006, -0.004, 0.005);
  const Pose start = stages.moving.pose_of(start_T);
  const Algorithm1Problem loop{stages.prepared.correlation,
                               stages.prepared.scene_coefficients,
                               stages.prepared.model_coefficients,
                               stages.moving,
                               object.params.local,
                               voxel,
                               object.params.scene.bandwidth};
  const PoseScore fitness = [&](const Pose& pose) {
    return stages.moving.fitness(stages.prepared.verifier, pose, voxel);
  };
  const double start_fitness = fitness(start);
  WindowCache windows;
  // A start that scores lower: the loop's end, at the truth and fitter than the start.
  const AlignResult ended =
      algorithm1_step(loop, windows.at(stages.problem, stages.moving.centre(start)), 30, start,
                      start_fitness, fitness);
  EXPECT_NE(ended.stop_reason, AlignStopReason::kept_start);
  EXPECT_GT(ended.iterations, 0);
  EXPECT_EQ(int(ended.history.size()), ended.iterations);
  const auto [degrees, metres] = object.error(ended.T_scene_model);
  EXPECT_LT(degrees, 1.0);
  EXPECT_LT(metres, 0.002);
  EXPECT_GT(ended.fitness, start_fitness);
  // A start that scores higher than any end can (a fitness is at most 1): the start.
  const AlignResult kept = algorithm1_step(
      loop, windows.at(stages.problem, stages.moving.centre(start)), 30, start, 1.5, fitness);
  EXPECT_EQ(kept.stop_reason, AlignStopReason::kept_start);
  EXPECT_FALSE(kept.converged);
  EXPECT_EQ(kept.iterations, 0);
  EXPECT_TRUE(kept.history.empty());
  EXPECT_EQ(kept.fitness, 1.5);
  EXPECT_EQ(kept.translation_peak, 0.0);
  EXPECT_TRUE(kept.T_scene_model.isApprox(start_T, 1e-12));
  EXPECT_NEAR(kept.correlation, stages.prepared.correlation.evaluate(start.R).value, 1e-12);
}

// The refinement's last step: the ICP's pose replaces the one it started from unless it
// took no step or scores more than kIcpScoreLoss lower.
TEST(Refinement, TheIcpStepTakesTheIcpsPoseUnlessItSlidesOff) {
  AlignResult result;
  result.fitness = 0.80;
  IcpOutcome icp;
  icp.T_scene_model.topRightCorner<3, 1>() << 0.004, 0.0, -0.002;
  double icp_score = 0.95;
  const TransformScore score = [&](const Transform&) { return icp_score; };
  take_icp(icp, score, result);  // no step taken
  EXPECT_TRUE(result.T_scene_model.isIdentity());
  EXPECT_EQ(result.icp_iterations, 0);
  icp.iterations = 4;
  icp_score = 0.80 - kIcpScoreLoss - 0.01;  // slid off
  take_icp(icp, score, result);
  EXPECT_TRUE(result.T_scene_model.isIdentity());
  EXPECT_EQ(result.fitness, 0.80);
  icp_score = 0.78;  // a small loss at a voxel's tolerance: a precise pose, kept
  take_icp(icp, score, result);
  EXPECT_EQ(result.T_scene_model, icp.T_scene_model);
  EXPECT_EQ(result.fitness, 0.78);
  EXPECT_EQ(result.icp_iterations, 4);
}

TEST(Refinement, AlgorithmOneFromAHypothesisOffTheTruthReachesIt) {
  const MovedObject object(3);
  Stages stages(object);
  std::mt19937 rng(4);
  std::normal_distribution<double> gaussian;
  WindowCache windows;
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::Vector3d axis(gaussian(rng), gaussian(rng), gaussian(rng));
    Transform start = object.T_scene_model;
    start.topLeftCorner<3, 3>() = about(axis, 8.0) * start.topLeftCorner<3, 3>();
    start.topRightCorner<3, 1>() += Eigen::Vector3d(0.006, -0.004, 0.005);
    Hypothesis hypothesis;
    hypothesis.pose = stages.moving.pose_of(start);
    hypothesis.fitness = stages.moving.fitness(stages.prepared.verifier, hypothesis.pose,
                                               object.params.scene.voxel_size);
    const AlignResult result = refine_hypothesis(
        stages.problem, object.params.refinement, object.params.local, stages.prepared.correlation,
        stages.prepared.scene_coefficients, hypothesis, windows);
    const auto [degrees, metres] = object.error(result.T_scene_model);
    EXPECT_LT(degrees, 1.0) << "trial " << trial;
    EXPECT_LT(metres, 0.002) << "trial " << trial;
    EXPECT_GT(result.fitness, hypothesis.fitness) << "trial " << trial;
  }
}

// A box's EGI: six normals weighted by their faces' areas, three different ones. It maps
// onto itself by the half turns about the three axes (correlation 1, the highest): the
// first three of the near-symmetries, which go on with the lower maxima.
TEST(Symmetries, OfABoxBeginWithItsThreeHalfTurns) {
  std::mt19937 rng(5);
  const Eigen::Vector3d half(0.12, 0.06, 0.04);
  const Eigen::Vector3d areas(half.y() * half.z(), half.x() * half.z(), half.x() * half.y());
  std::discrete_distribution<int> face({areas.x(), areas.y(), areas.z()});
  std::bernoulli_distribution sign;
  Points normals = Points::Zero(4000, 3);
  for (Eigen::Index i = 0; i < normals.rows(); ++i) normals(i, face(rng)) = sign(rng) ? 1.0 : -1.0;
  const int bandwidth = 16;
  const std::vector<Eigen::Matrix3d> symmetries =
      model_symmetries(egi_coefficients(normals, bandwidth), bandwidth, 1);
  ASSERT_GE(symmetries.size(), 3u);
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::Matrix3d half_turn = about(Eigen::Matrix3d::Identity().col(axis), 180.0);
    double nearest = 180.0;
    for (std::size_t i = 0; i < 3; ++i)
      nearest = std::min(nearest, angle_deg(symmetries[i].transpose() * half_turn));
    EXPECT_LT(nearest, 2.0) << "the half turn about axis " << axis;
  }
}

// The alternatives on their own (find_alternatives): a box at a known pose, its four
// equal poses the half turns. From its near-symmetries, each half turn is found within 5
// degrees and 10 mm and scores within kAlternativeMargin of the pose; none is sought
// when none is asked for.
TEST(Alternatives, OfABoxAtItsPoseAreItsHalfTurns) {
  std::mt19937 rng(8);
  const PointCloud model = test::box(4000, rng);
  Transform T_scene_model = Transform::Identity();
  T_scene_model.topLeftCorner<3, 3>() = about({0.4, 1.2, -0.5}, 60.0);
  T_scene_model.topRightCorner<3, 1>() << 0.03, -0.02, 0.01;
  const PointCloud scene = test::box(4000, rng).transformed(T_scene_model);
  const double voxel = 0.008;
  const int bandwidth = 16;
  const Verifier verifier(scene, voxel, std::nullopt);
  AlignResult result;
  result.T_scene_model = T_scene_model;
  set_verification(result, verifier.verify(model, T_scene_model));
  AlternativeSources sources;
  sources.symmetries = model_symmetries(egi_coefficients(model, bandwidth), bandwidth, 1);
  const VerificationParams verification;
  const std::vector<AlignAlternative> alternatives =
      find_alternatives(model, verifier, sources, verification, voxel, std::nullopt, T_scene_model,
                        result.confidence);
  ASSERT_LE(int(alternatives.size()), verification.max_alternatives);
  for (int axis = 0; axis < 3; ++axis) {
    Transform turned = T_scene_model;
    turned.topLeftCorner<3, 3>() *= about(Eigen::Matrix3d::Identity().col(axis), 180.0);
    bool found = false;
    for (const AlignAlternative& a : alternatives) {
      const auto [degrees, metres] = test::pose_error(a.T_scene_model, turned, model.centroid());
      found = found || (degrees < 5.0 && metres < 0.010);
    }
    EXPECT_TRUE(found) << "the half turn about axis " << axis;
  }
  for (const AlignAlternative& a : alternatives)
    EXPECT_GE(a.confidence, result.confidence - kAlternativeMargin);
  VerificationParams none = verification;
  none.max_alternatives = 0;
  EXPECT_TRUE(find_alternatives(model, verifier, sources, none, voxel, std::nullopt, T_scene_model,
                                result.confidence)
                  .empty());
}

// The reselection on its own (reselect): an alternative more confident than the pose by
// over reselect_margin replaces it, claiming no run of Algorithm 1; one within the margin
// and with no more inliers does not, nor any with the reselection off (margin 1).
TEST(Reselection, AFarMoreConfidentAlternativeReplacesThePose) {
  const MovedObject object(9);
  Stages stages(object);
  Transform wrong = object.T_scene_model;
  wrong.topLeftCorner<3, 3>() *= about(Eigen::Vector3d::UnitZ(), 90.0);
  AlignResult best;
  best.T_scene_model = wrong;
  best.confidence = 0.40;
  best.inliers = 3000;
  best.iterations = 12;
  AlignAlternative right;
  right.T_scene_model = object.T_scene_model;
  right.inliers = 2000;
  VerificationParams verification;  // reselect_margin 0.1
  for (const double confidence : {0.45, 0.55}) {
    AlignResult trial = best;
    right.confidence = confidence;
    trial.alternatives = {right};
    const bool replaced =
        reselect(stages.problem, verification, stages.prepared, object.model, std::nullopt, trial);
    EXPECT_EQ(replaced, confidence > 0.40 + verification.reselect_margin) << confidence;
    if (!replaced) {
      EXPECT_EQ(trial.T_scene_model, wrong);
      continue;
    }
    EXPECT_EQ(trial.T_scene_model, object.T_scene_model);
    EXPECT_EQ(trial.confidence, confidence);
    EXPECT_EQ(trial.stop_reason, AlignStopReason::reselected);
    EXPECT_EQ(trial.iterations, 0);
    EXPECT_EQ(trial.hypothesis, -2);
    EXPECT_GT(trial.fitness, 0.9) << "the fitness of the pose it now holds";
  }
  verification.reselect_margin = 1.0;
  best.alternatives = {right};
  EXPECT_FALSE(
      reselect(stages.problem, verification, stages.prepared, object.model, std::nullopt, best));
}

// The one verdict of both modes (judge_pose), on its own: the true pose of an object with
// no symmetry, well scored, is reliable and determined to a fraction of a degree and a
// millimetre; each reason not to act, set alone, is named, and an alternative that is no
// symmetry of the object makes the answer ambiguous.
TEST(Verdict, JudgesAVerifiedPoseAndNamesEachReasonNotToAct) {
  const MovedObject object(6);
  const double voxel = object.params.scene.voxel_size;
  const Verifier verifier(object.scene, voxel, std::nullopt);
  VerdictCase c;
  c.score = 0.95;
  c.T = object.T_scene_model;
  c.inlier_distance = voxel;
  c.voxel_size = voxel;
  c.model_extent = typical_size(object.model.points());
  c.scene_extent = typical_size(object.scene.points());
  c.supported = true;
  const auto pose_of = [](const AlignAlternative& a) { return a.T_scene_model; };
  std::vector<AlignAlternative> none;
  const auto status = [&](const VerdictCase& v) {
    return judge_pose(v, object.model, verifier.fine_grid(), none, pose_of).conclusion;
  };
  const Judgement right = judge_pose(c, object.model, verifier.fine_grid(), none, pose_of);
  EXPECT_EQ(right.conclusion.status, Verdict::reliable);
  EXPECT_TRUE(right.conclusion.reliable);
  EXPECT_TRUE(right.conclusion.determined);
  EXPECT_FALSE(right.ambiguous);
  EXPECT_GT(right.conclusion.confidence, 0.9);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(std::sqrt(right.covariance(i, i)) / kDeg, 0.2) << "rotation " << i;
    EXPECT_LT(std::sqrt(right.covariance(3 + i, 3 + i)), 0.001) << "translation " << i;
  }
  VerdictCase v = c;
  v.rests = false;
  EXPECT_EQ(status(v).status, Verdict::floating);
  v = c;
  v.score = 0.05;
  EXPECT_EQ(status(v).status, Verdict::doubtful);
  v = c;
  v.supported = false;
  EXPECT_EQ(status(v).status, Verdict::no_support);
  EXPECT_EQ(status(v).confidence, 0.0);
  v = c;
  v.voxel_size = c.model_extent;  // a voxel as large as the object
  EXPECT_EQ(status(v).status, Verdict::bad_scale);
  EXPECT_EQ(status(v).confidence, 0.0);
  v = c;
  v.timed_out = true;
  EXPECT_EQ(status(v).status, Verdict::max_seconds);
  EXPECT_FALSE(status(v).reliable);
  // The model turned a quarter turn about its own x axis: no symmetry of a box with a
  // sphere beside it.
  std::vector<AlignAlternative> alternatives(1);
  alternatives[0].T_scene_model = c.T;
  alternatives[0].T_scene_model.topLeftCorner<3, 3>() =
      c.T.topLeftCorner<3, 3>() * about(Eigen::Vector3d::UnitX(), 90.0);
  const Judgement other = judge_pose(c, object.model, verifier.fine_grid(), alternatives, pose_of);
  EXPECT_FALSE(alternatives[0].symmetric);
  EXPECT_TRUE(other.ambiguous);
  EXPECT_EQ(other.conclusion.status, Verdict::ambiguous);
}

}  // namespace
}  // namespace spectral_vs::detail
