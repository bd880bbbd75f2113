// Threads: alignments running at once, one ModelAligner shared by two threads, and the
// same result with one thread and with two. These run in the ordinary suite and, under
// ThreadSanitizer, in `make test-tsan` (CMakePresets.json, preset "tsan"), where any data
// race on the shared caches (FFTW plans, Wigner tables, spherical harmonic transforms),
// in FFTW's threads or in the SO(3) search's workers fails them.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/alignment/model_aligner.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3_search.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

namespace spectral_vs {
namespace {

// The asymmetric 0.25 m box-and-sphere object, 1500 points with normals.
const PointCloud& object() {
  static const PointCloud cloud = [] {
    std::mt19937 rng(17);
    return test::box_and_sphere(1500, rng);
  }();
  return cloud;
}

Transform pose(double angle_deg, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  Transform T = test::translation(t);
  T.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(angle_deg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  return T;
}

// The global search with few hypotheses: the settings of a test, not of a user.
AlignParams global_params(int bandwidth) {
  AlignParams p;
  p.scene.bandwidth = bandwidth;
  p.search.hypotheses = 4;
  p.search.refinements = 1;
  return p;
}

// The servo's bounded local search (ModelAligner prepares the model's side once).
AlignParams local_params() {
  AlignParams p;
  p.scene.voxel_size = 0.012;
  p.scene.bandwidth = 8;
  p.search.global_search = false;
  p.local.max_iterations = 3;
  p.local.max_translation = 0.1;
  return p;
}

double rotation_error_deg(const Transform& a, const Transform& b) {
  const Eigen::Matrix3d d = a.topLeftCorner<3, 3>().transpose() * b.topLeftCorner<3, 3>();
  return std::acos(std::clamp((d.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
}

double translation_error_mm(const Transform& a, const Transform& b) {
  return 1000.0 * (a.topRightCorner<3, 1>() - b.topRightCorner<3, 1>()).norm();
}

void expect_identical(const AlignResult& a, const AlignResult& b) {
  EXPECT_EQ(a.T_scene_model, b.T_scene_model);
  EXPECT_EQ(a.fitness, b.fitness);
  EXPECT_EQ(a.correlation, b.correlation);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.hypothesis, b.hypothesis);
  EXPECT_EQ(a.history.size(), b.history.size());
}

template <class Job>
void run_at_once(std::vector<Job>& jobs) {
  // Released together so that the alignments overlap from their first instruction.
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (auto& job : jobs) {
    threads.emplace_back([&job, &go] {
      while (!go.load()) std::this_thread::yield();
      job.run();
    });
  }
  go = true;
  for (auto& thread : threads) thread.join();
}

struct AlignJob {
  PointCloud scene;
  AlignParams params;
  AlignResult result;
  void run() { result = align(object(), scene, params); }
};

// Four threads align the same model onto the same scene at once: each gets, bit for bit,
// what the alignment gives alone, and the motion it was made with.
TEST(Threads, FourAlignmentsOfTheSameInputAtOnce) {
  const Transform T = pose(70.0, {1.0, 0.5, -0.3}, {0.03, -0.02, 0.01});
  std::vector<AlignJob> jobs(4, AlignJob{object().transformed(T), global_params(10), {}});
  run_at_once(jobs);
  const AlignResult alone = align(object(), object().transformed(T), global_params(10));
  EXPECT_LT(rotation_error_deg(alone.T_scene_model, T), 2.0);
  EXPECT_LT(translation_error_mm(alone.T_scene_model, T), 4.0);
  for (const AlignJob& job : jobs) expect_identical(job.result, alone);
}

// Four threads with different inputs and settings (global and local, one and two
// threads of their own; bandwidths 5 and 11 are used by no other test of this program,
// so the threads also race to build their tables first).
TEST(Threads, FourAlignmentsOfDifferentInputsAtOnce) {
  std::vector<AlignJob> jobs;
  for (int i = 0; i < 4; ++i) {
    AlignParams p = i == 3 ? local_params() : global_params(i % 2 ? 11 : 5);
    p.threads = i == 1 || i == 3 ? 2 : 1;
    const Transform T = i == 3 ? pose(6.0, {0.0, 1.0, 1.0}, {0.01, 0.005, 0.0})
                               : pose(40.0 + 45.0 * i, {1.0 + i, -1.0, 0.5}, {0.02 * i, 0.01, 0.0});
    jobs.push_back({object().transformed(T), p, {}});
  }
  run_at_once(jobs);
  for (const AlignJob& job : jobs) {
    expect_identical(job.result, align(object(), job.scene, job.params));
  }
}

struct SharedAlignerJob {
  ModelAligner* aligner;
  std::vector<PointCloud> scenes;
  std::vector<AlignResult> results;
  void run() {
    for (const PointCloud& scene : scenes) results.push_back(aligner->align(scene));
  }
};

// One ModelAligner used by two threads: the calls wait for each other (the object's
// buffers are shared), and each result is what the scene gives alone. A third thread
// reads last_timings() meanwhile.
TEST(Threads, OneModelAlignerFromTwoThreads) {
  ModelAligner aligner(object(), local_params());
  std::vector<SharedAlignerJob> jobs(2);
  for (int i = 0; i < 6; ++i) {
    // Two grid sizes, so that the kept plans of other sizes are used too.
    const Transform T = pose(2.0 + i, {1.0, 0.0, 1.0}, {0.004 * i, i % 2 ? 0.05 : -0.003, 0.0});
    jobs[i % 2].scenes.push_back(object().transformed(T));
    jobs[i % 2].aligner = &aligner;
  }
  std::atomic<bool> done{false};
  double seen_total = 0.0;
  std::thread reader([&] {
    while (!done.load()) seen_total = std::max(seen_total, aligner.last_timings().total);
  });
  run_at_once(jobs);
  done = true;
  reader.join();
  EXPECT_GT(seen_total + aligner.last_timings().total, 0.0);
  for (const SharedAlignerJob& job : jobs) {
    ASSERT_EQ(job.results.size(), job.scenes.size());
    for (std::size_t k = 0; k < job.scenes.size(); ++k) {
      const AlignResult alone = align(object(), job.scenes[k], local_params());
      // The ModelAligner gives align()'s pose to rounding (model_aligner_test).
      EXPECT_LT((job.results[k].T_scene_model - alone.T_scene_model).cwiseAbs().maxCoeff(), 1e-9);
      EXPECT_EQ(job.results[k].iterations, alone.iterations);
      EXPECT_NEAR(job.results[k].fitness, alone.fitness, 1e-12);
    }
  }
}

// --- The same result with one thread and with two -----------------------------------

TEST(ThreadCounts, GlobalAlignmentIsBitIdentical) {
  for (const double angle : {30.0, 120.0, 175.0}) {
    const Transform T = pose(angle, {0.3, 1.0, -0.6}, {0.05, 0.0, -0.02});
    AlignParams one = global_params(12), two = one;
    two.threads = 2;
    expect_identical(align(object(), object().transformed(T), one),
                     align(object(), object().transformed(T), two));
  }
}

TEST(ThreadCounts, LocalAlignmentIsBitIdentical) {
  const Transform T = pose(5.0, {1.0, 1.0, 0.0}, {0.01, -0.02, 0.005});
  AlignParams one = local_params(), two = one;
  two.threads = 2;
  expect_identical(align(object(), object().transformed(T), one),
                   align(object(), object().transformed(T), two));
  ModelAligner a(object(), one), b(object(), two);
  expect_identical(a.align(object().transformed(T)), b.align(object().transformed(T)));
}

TEST(ThreadCounts, NormalsAreBitIdentical) {
  const PointCloud points(object().points());
  NormalEstimationParams one, two;
  one.k_neighbors = two.k_neighbors = 12;
  two.threads = 2;
  const PointCloud a = estimate_normals(points, one), b = estimate_normals(points, two);
  EXPECT_EQ(a.points(), b.points());
  EXPECT_EQ(a.normals(), b.normals());
}

TEST(ThreadCounts, PhaseCorrelationIsBitIdentical) {
  const PointCloud scene = object().transformed(test::translation({0.031, -0.017, 0.008}));
  const GridSpec spec = make_grid_spec(bounding_box(object()), bounding_box(scene), 0.006);
  const VoxelGrid target = voxelize(scene, spec, Occupancy::trilinear);
  const VoxelGrid moving = voxelize(object(), spec, Occupancy::trilinear);
  PhaseCorrelationParams one, two;
  two.threads = 2;
  const TranslationEstimate a = phase_correlation(moving, target, one);
  const TranslationEstimate b = phase_correlation(moving, target, two);
  EXPECT_EQ(a.shift, b.shift);
  EXPECT_EQ(a.peak, b.peak);
  EXPECT_LT(1000.0 * (a.shift - Eigen::Vector3d(0.031, -0.017, 0.008)).norm(), 1.5);
}

TEST(ThreadCounts, So3SearchIsBitIdentical) {
  const Transform T = pose(140.0, {1.0, -2.0, 0.5}, Eigen::Vector3d::Zero());
  const ShCoefficients model = egi_coefficients(object(), 12);
  const ShCoefficients scene = egi_coefficients(object().transformed(T), 12);
  So3SearchParams one, two;
  two.threads = 2;
  const auto a = so3_search(scene, model, 12, one), b = so3_search(scene, model, 12, two);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].R, b[i].R);
    EXPECT_EQ(a[i].correlation, b[i].correlation);
  }
}

}  // namespace
}  // namespace spectral_vs
