#include "alignment/hypotheses.hpp"

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/point_sets.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

// Largest global-search grid before its voxel is coarsened: 2^19 voxels, about 4 ms per
// FFT pair here, so that 16 hypotheses fit the time budget on a room-sized scan.
constexpr double kSearchGridVoxels = 524288.0;

// A part's hypotheses are placed first on a grid this many times coarser than the
// alignment's voxel (an eighth of the voxels to transform), then on the alignment's.
constexpr double kCoarsePlacement = 2.0;

// For a model whose EGI has a flat axis (see flat_axis below), the EGI cannot tell its
// turns about that axis apart, but the scene can: the best-ranked hypotheses are turned
// to the fittest of the turns every kFlatAxisStep, scored with depths within `tolerance`.
constexpr std::size_t kTurnedHypotheses = 16;

// A part's rotations are distinct: a maximum of the SO(3) search that its refinement on
// the EGI correlation brings within kDistinctRotationDeg of an earlier one of the same
// part is not placed, and the search offers kPartCandidateSurplus times as many maxima, so
// that the part still gets its share of rotations. Neighbouring grid maxima (11 degrees
// apart at B = 16) often climb to one peak; placing both spent the part's share on one
// rotation. Measured on 280 tuning clutter scenes (C-3, 40 per angle, in their camera's
// frame): 252 right before, 255 at 5 degrees and 256 at 10 (4 gained, none lost), at the
// same CPU time; single views (140) 132 before and after, the milk scene 140 of 140.
constexpr double kDistinctRotationDeg = 10.0;
constexpr int kPartCandidateSurplus = 3;

// In clutter a part's rotations are screened before they are placed: kScreenedPerPlaced
// times as many maxima of its SO(3) search as it places are placed on the coarse grid at
// the grid's rotation and scored on the sparse model (kSparseStride), with depths within
// the coarse voxel; the fittest go on as above. An object with few flat faces (the bunny,
// a blob) seen from one side among others correlates weakly with its model's EGI: its
// true rotation is often not among the part's 24 best-correlated maxima. Measured on 280
// tuning clutter scenes (C-3, 40 per angle, in their camera's frame): 255 right without
// it; screening 3 / 4 / 6 times as many, 260 / 263 / 265 (at 4, 13 gained and 1 lost,
// mostly the bunny and the duck) at 1.10 / 1.09 / 1.26 times the CPU time (3 and 6 on
// every 4th model point, 4 on every 8th). Placing 48 rotations per part instead of 24
// gave 259 at 1.47 times, 96 gave 263 at 2.4 times. On the single views (140; the whole
// view is one part of 48 rotations) screening gained none and lost 2 (near-symmetric
// bricks flipped), so a view without a support plane is not screened.
constexpr int kScreenedPerPlaced = 4;

// Turn between two rotations, degrees.
double turn_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return rotation_distance(a, b) * 180.0 / M_PI;
}

}  // namespace

double search_voxel_size(const PointCloud& scene, double reach, const GlobalSearchParams& search,
                         double voxel_size) {
  if (search.search_voxel_size > 0.0) return search.search_voxel_size;
  const Eigen::Vector3d extent = bounding_box(scene).sizes().array() + 4.0 * reach;
  const double fitting = std::cbrt(extent.prod() / kSearchGridVoxels);
  return std::max(2.0 * voxel_size, fitting);
}

// Beyond the paper: the best rotations of the SO(3) search, each refined on the EGI
// correlation and placed by a phase correlation over the whole scene (coarse voxels),
// ranked by fitness.
std::vector<Hypothesis> global_hypotheses(const Problem& problem, const GlobalSearchParams& search,
                                          const LocalParams& local, So3Correlation& correlation,
                                          const ShCoefficients& scene_coefficients,
                                          double search_voxel) {
  So3SearchParams so3;
  so3.candidates = search.hypotheses;
  so3.threads = problem.threads;
  std::vector<RotationCandidate> candidates;
  {
    const StageTimer timer(problem.timings, &AlignTimings::rotation_search);
    candidates =
        so3_search(scene_coefficients, problem.model_coefficients, problem.scale.bandwidth, so3);
  }
  const Eigen::Vector3d start = problem.scene.cloud().centroid();
  SceneTranslation coarse(problem.scene, start, problem.model.reach(), search_voxel,
                          problem.scale.occupancy, problem.phase, problem.phase.limits);
  RotationRefineParams refine;
  refine.newton = local.rotation_step == RotationStep::newton;
  std::vector<Hypothesis> hypotheses = placed_rotations(
      candidates, correlation, refine, problem.model, start - problem.model.centroid(),
      problem.deadline, [&](const Points& at) { return coarse.estimate(at).shift; },
      [&](Hypothesis& hypothesis) {
        hypothesis.fitness = problem.model.fitness(problem.verifier, hypothesis.pose, search_voxel);
      });
  rank(hypotheses);
  return hypotheses;
}

Pose facing_at_part(const Problem& problem, MovingModel& model, const Eigen::Matrix3d& R,
                    const Eigen::Vector3d& centroid) {
  Pose pose{R, centroid - model.centroid()};
  if (problem.viewpoint) pose.offset -= model.facing_side(R, centroid - *problem.viewpoint);
  return pose;
}

namespace {

// A part's rotation placed at its centroid (facing_at_part), then by the phase
// correlation of `grid`.
Pose placed_at_part(const Problem& problem, MovingModel& model, const Eigen::Matrix3d& R,
                    const Eigen::Vector3d& centroid, TranslationWindow& grid) {
  Pose pose = facing_at_part(problem, model, R, centroid);
  pose.offset += grid.estimate(model.move(pose)).shift;
  return pose;
}

// The maxima of a part's SO(3) search in the order they are tried: by correlation, or
// with `sparse` the fittest first once placed coarsely (see kScreenedPerPlaced).
std::vector<Eigen::Matrix3d> part_rotations(const Problem& problem,
                                            const ShCoefficients& coefficients, int per_part,
                                            ScoredModel* sparse, const Eigen::Vector3d& centroid,
                                            TranslationWindow& coarse) {
  So3SearchParams search;
  search.candidates = (sparse ? kScreenedPerPlaced : kPartCandidateSurplus) * per_part;
  search.threads = problem.threads;
  std::vector<RotationCandidate> candidates;
  {
    const StageTimer timer(problem.timings, &AlignTimings::rotation_search);
    candidates =
        so3_search(coefficients, problem.model_coefficients, problem.scale.bandwidth, search);
  }
  std::vector<std::pair<double, Eigen::Matrix3d>> scored;
  for (const RotationCandidate& candidate : candidates) {
    double fitness = 0.0;
    if (sparse) {
      const Pose pose = placed_at_part(problem, *sparse, candidate.R, centroid, coarse);
      fitness =
          sparse->fitness(problem.verifier, pose, kCoarsePlacement * problem.scale.voxel_size);
    }
    scored.emplace_back(fitness, candidate.R);
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<Eigen::Matrix3d> rotations;
  for (const auto& [fitness, R] : scored) rotations.push_back(R);
  return rotations;
}

}  // namespace

// Beyond the paper: in clutter the EGI of the whole scene mixes every object's normals,
// and its best rotations are mostly other objects'. Per connected part of the scene that
// could be the object, the SO(3) search runs on the part's own EGI, and its rotations are
// placed by phase correlation in a window around the part at the alignment's voxel.
std::vector<Hypothesis> part_hypotheses(const Problem& problem, const LocalParams& local,
                                        const std::vector<std::vector<Eigen::Index>>& parts,
                                        int per_part, bool screen, WindowCache& windows) {
  const PointCloud& scene = problem.scene.cloud();
  RotationRefineParams refine;
  refine.newton = local.rotation_step == RotationStep::newton;
  std::optional<ScoredModel> sparse;
  if (screen) sparse.emplace(every_nth(problem.model.cloud(), kSparseStride));
  std::vector<Hypothesis> hypotheses;
  std::optional<TranslationWindow> coarse;
  for (const auto& part : parts) {
    if (!hypotheses.empty() && expired(problem)) break;
    const Points normals = detail::rows_of(scene.normals(), part);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Index i : part) centroid += scene.points().row(i).transpose();
    centroid /= double(part.size());
    const ShCoefficients coefficients =
        egi_coefficients(normals, problem.scale.bandwidth, problem.scale.egi_method);
    std::optional<So3Correlation> correlation;
    try {
      correlation.emplace(coefficients, problem.model_coefficients, problem.scale.bandwidth, true);
    } catch (const std::invalid_argument&) {
      continue;  // a part whose normals have no structure
    }
    TranslationWindow& window = windows.at(problem, centroid);
    if (coarse) {
      coarse->place(centroid);
    } else {
      coarse.emplace(problem.scene, problem.model.reach(), problem.margin, centroid,
                     kCoarsePlacement * problem.scale.voxel_size, problem.scale.occupancy,
                     problem.phase, problem.phase.limits);
    }
    std::vector<Eigen::Matrix3d> kept;
    for (const Eigen::Matrix3d& R : part_rotations(
             problem, coefficients, per_part, sparse ? &*sparse : nullptr, centroid, *coarse)) {
      if (int(kept.size()) == per_part) break;
      Hypothesis hypothesis;
      hypothesis.index = int(hypotheses.size());
      const Eigen::Matrix3d refined = refine_rotation(*correlation, R, refine).R;
      if (std::any_of(kept.begin(), kept.end(), [&](const Eigen::Matrix3d& other) {
            return turn_deg(other, refined) < kDistinctRotationDeg;
          }))
        continue;
      kept.push_back(refined);
      // Twice: the coarse shift brings the model near enough for the fine one to be exact.
      hypothesis.pose = placed_at_part(problem, problem.model, refined, centroid, *coarse);
      hypothesis.pose.offset += window.estimate(problem.model.move(hypothesis.pose)).shift;
      hypothesis.fitness =
          problem.model.fitness(problem.verifier, hypothesis.pose, problem.scale.voxel_size);
      hypotheses.push_back(hypothesis);
    }
  }
  rank(hypotheses);
  return hypotheses;
}

void turn_about_flat_axis(const Problem& problem, std::vector<Hypothesis>& hypotheses,
                          double tolerance) {
  if (!problem.flat_axis) return;
  const int turns = static_cast<int>(std::lround(2.0 * M_PI / kFlatAxisStep));
  const std::size_t count = std::min(kTurnedHypotheses, hypotheses.size());
  for (std::size_t h = 0; h < count; ++h) {
    Hypothesis& hypothesis = hypotheses[h];
    const Pose start = hypothesis.pose;
    for (int k = 1; k < turns; ++k) {
      Pose trial = start;
      trial.R = start.R * exp_so3(double(k) * kFlatAxisStep * *problem.flat_axis);
      const double fitness = problem.model.fitness(problem.verifier, trial, tolerance);
      if (fitness > hypothesis.fitness) {
        hypothesis.fitness = fitness;
        hypothesis.pose = trial;
      }
    }
  }
  rank(hypotheses);
}

// Beyond the paper: the axis about which the model's EGI barely changes (a mug's: its
// handle is a few percent of the normals), as the eigenvector of the smallest curvature
// of the model's EGI autocorrelation at the identity, when that curvature is under
// kFlatAxisRatio of the largest. Along it the EGI correlation cannot tell poses apart.
std::optional<Eigen::Vector3d> flat_axis(const ShCoefficients& model_coefficients, int bandwidth) {
  std::optional<So3Correlation> self;
  try {
    self.emplace(model_coefficients, model_coefficients, bandwidth, true);
  } catch (const std::invalid_argument&) {
    return std::nullopt;  // a uniform EGI: no axis to single out
  }
  const CorrelationValue c = self->evaluate(Eigen::Matrix3d::Identity(), true);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(-c.hessian);
  const Eigen::Vector3d curvature = eigen.eigenvalues();  // ascending
  if (!(curvature(2) > 0.0) || curvature(0) > kFlatAxisRatio * curvature(2)) return std::nullopt;
  return eigen.eigenvectors().col(0);
}

// The initial guess as a hypothesis, ranked with the search's; with a neighbourhood, the
// search's hypotheses outside it are dropped.
void seed_with_guess(const Problem& problem, const GlobalSearchParams& search,
                     const Transform& initial_guess, std::vector<Hypothesis>& hypotheses,
                     double tolerance) {
  Hypothesis guess;
  guess.index = -1;
  guess.pose = problem.model.pose_of(initial_guess);
  guess.fitness = problem.model.fitness(problem.verifier, guess.pose, tolerance);
  const Eigen::Vector3d centre = problem.model.centre(guess.pose);
  const auto outside = [&](const Hypothesis& h) {
    return (search.guess_angle_deg > 0.0 &&
            turn_deg(h.pose.R, guess.pose.R) > search.guess_angle_deg) ||
           (search.guess_distance > 0.0 &&
            (problem.model.centre(h.pose) - centre).norm() > search.guess_distance);
  };
  hypotheses.erase(std::remove_if(hypotheses.begin(), hypotheses.end(), outside), hypotheses.end());
  hypotheses.push_back(guess);
  rank(hypotheses);
}

}  // namespace spectral_vs::detail
