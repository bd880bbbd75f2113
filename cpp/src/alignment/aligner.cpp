#include <spectral_vs/alignment/aligner.hpp>

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/algorithm1.hpp"
#include "alignment/align_detail.hpp"
#include "alignment/alternatives.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/range_image.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>

namespace spectral_vs {

using detail::deadline_of;
using detail::fail;
using detail::phase_params;
using detail::RangeImage;
using detail::SceneMap;
using detail::SceneTranslation;
using detail::TranslationWindow;

namespace {

// Largest global-search grid before its voxel is coarsened: 2^19 voxels, about 4 ms per
// FFT pair here, so that 16 hypotheses fit the time budget on a room-sized scan.
constexpr double kSearchGridVoxels = 524288.0;

// The rotation steps of the final polish, radians: 4 down to 1/4 degree.
constexpr double kPolishFirstStep = 4.0 * M_PI / 180.0;
constexpr double kPolishLastStep = 0.25 * M_PI / 180.0;
constexpr int kPolishFirstStepRounds = 5;  // at most 20 degrees walked at the first step
constexpr double kPolishMinDensity = 2.0;  // model points per occupied voxel
// A part's hypotheses are placed first on a grid this many times coarser than the
// alignment's voxel (an eighth of the voxels to transform), then on the alignment's.
constexpr double kCoarsePlacement = 2.0;
// A model EGI whose smallest curvature is under this share of its largest has a flat
// axis (measured at B = 16: mug 0.015, duck 0.08; bunny 0.44, box 0.31, others 0.57-0.8).
constexpr double kFlatAxisRatio = 0.1;
constexpr double kFlatAxisStep = 15.0 * M_PI / 180.0;  // turns tried about the flat axis

void check_params(const AlignParams& p) {
  if (!(p.voxel_size >= 0.0 && std::isfinite(p.voxel_size))) {
    fail("voxel_size must be >= 0 metres (0: derived from the model), got ", p.voxel_size);
  }
  if (p.bandwidth < 2 || p.bandwidth > kMaxBandwidth) {
    fail("bandwidth must be in [2, ", kMaxBandwidth, "], got ", p.bandwidth);
  }
  if (!(p.translation_gain > 0.0 && p.translation_gain <= 1.0)) {
    fail("translation_gain must be in (0, 1], got ", p.translation_gain);
  }
  detail::require_positive_finite(p.rotation_gain, "rotation_gain");
  if (p.rotation_step == RotationStep::newton && p.rotation_gain > 1.0) {
    fail("rotation_gain must be in (0, 1] with Newton steps, got ", p.rotation_gain);
  }
  detail::require_positive_finite(p.max_rotation_step, "max_rotation_step");
  detail::require_positive_finite(p.tolerance, "tolerance");
  if (p.max_iterations < 1) fail("max_iterations must be >= 1, got ", p.max_iterations);
  if (p.refinement_iterations < 1) {
    fail("refinement_iterations must be >= 1, got ", p.refinement_iterations);
  }
  if (p.hypotheses < 1) fail("hypotheses must be >= 1, got ", p.hypotheses);
  if (p.refinements < 1 || p.refinements > p.hypotheses) {
    fail("refinements must be in [1, hypotheses = ", p.hypotheses, "], got ", p.refinements);
  }
  if (!(p.search_voxel_size >= 0.0 && std::isfinite(p.search_voxel_size))) {
    fail("search_voxel_size must be >= 0 metres (0: automatic), got ", p.search_voxel_size);
  }
  if (!(p.max_translation >= 0.0 && std::isfinite(p.max_translation))) {
    fail("max_translation must be >= 0 metres (0: unbounded), got ", p.max_translation);
  }
  if (!(p.window_margin >= 0.0 && std::isfinite(p.window_margin))) {
    fail("window_margin must be >= 0 metres (0: automatic), got ", p.window_margin);
  }
  if (p.threads < 1 || p.threads > 256) fail("threads must be in [1, 256], got ", p.threads);
  if (!(p.max_seconds >= 0.0 && std::isfinite(p.max_seconds))) {
    fail("max_seconds must be >= 0 seconds (0: no limit), got ", p.max_seconds);
  }
  require_rigid_transform(p.initial_guess, "initial_guess");
  if (!(p.guess_angle_deg >= 0.0 && p.guess_angle_deg <= 180.0)) {
    fail("guess_angle_deg must be in [0, 180] degrees (0: no limit), got ", p.guess_angle_deg);
  }
  if (!(p.guess_distance >= 0.0 && std::isfinite(p.guess_distance))) {
    fail("guess_distance must be >= 0 metres (0: no limit), got ", p.guess_distance);
  }
  if (!p.sensor_origin.allFinite()) fail("sensor_origin must be finite");
  if (p.scene_viewpoint && !p.scene_viewpoint->allFinite()) fail("scene_viewpoint must be finite");
  if (p.max_alternatives < 0 || p.max_alternatives > 64) {
    fail("max_alternatives must be in [0, 64], got ", p.max_alternatives);
  }
}

// A guess's neighbourhood (AlignParams::guess_angle_deg, guess_distance) is set.
bool has_neighbourhood(const AlignParams& p) {
  return p.guess_angle_deg > 0.0 || p.guess_distance > 0.0;
}

using detail::Pose;

// The moving model scored against the scene: against what its sensor saw, with depths
// within `tolerance` metres, when the scene is one view.
class MovingModel : public detail::MovingModel {
 public:
  using detail::MovingModel::MovingModel;

  double fitness(const SceneMap& scene, const RangeImage* view, const Pose& pose,
                 double tolerance) {
    const Points& normals = turned_normals(pose);
    const Points& moved = move(pose);
    return view ? view->check(moved, normals, tolerance).fitness() : scene.fitness(moved, normals);
  }
};

Eigen::AlignedBox3d box_of(const Points& points) {
  return Eigen::AlignedBox3d(points.colwise().minCoeff().transpose(),
                             points.colwise().maxCoeff().transpose());
}

double search_voxel_size(const PointCloud& scene, double reach, const AlignParams& params) {
  if (params.search_voxel_size > 0.0) return params.search_voxel_size;
  const Eigen::Vector3d extent = bounding_box(scene).sizes().array() + 4.0 * reach;
  const double fitting = std::cbrt(extent.prod() / kSearchGridVoxels);
  return std::max(2.0 * params.voxel_size, fitting);
}

double window_margin(double search_voxel, const AlignParams& params) {
  if (params.window_margin > 0.0) return params.window_margin;
  return std::max(5.0 * params.voxel_size, 2.5 * search_voxel);
}

using Clock = std::chrono::steady_clock;

// What Algorithm 1 works with: the scene, the model, the EGI correlation it ascends,
// and the translation grids. The paper's mode starts on the grid over the whole scene
// and moves to a window once the translation steps fit in it.
struct Problem {
  const SceneMap& scene;
  const RangeImage* view;  // the scene's range image, for a single view
  MovingModel& model;
  const ShCoefficients& model_coefficients;
  const AlignParams& params;
  double margin;
  Clock::time_point deadline = Clock::time_point::max();    // of params.max_seconds
  std::optional<Eigen::Vector3d> flat_axis = std::nullopt;  // of the model's EGI, if it has one
  bool dense_model = true;  // at least kPolishMinDensity points per occupied voxel
  std::optional<Eigen::Vector3d> viewpoint = std::nullopt;  // the sensor of a single view
};

bool expired(const Problem& problem) { return Clock::now() > problem.deadline; }

// Made once (its FFT plans are re-used), then moved to each place Algorithm 1 runs.
void place_window(const Problem& problem, std::optional<TranslationWindow>& window,
                  const Eigen::Vector3d& centre) {
  if (window) {
    window->place(centre);
    return;
  }
  window.emplace(problem.scene, problem.model.reach(), problem.margin, centre,
                 problem.params.voxel_size, problem.params.occupancy, phase_params(problem.params),
                 problem.params.limits);
}

// The paper's translation source: the grid over the whole scene until a step fits in a
// window (the model is near), then a window that follows the model. A bounded grid
// (max_translation) is kept throughout.
class SceneThenWindow : public detail::TranslationSource {
 public:
  SceneThenWindow(const Problem& problem, SceneTranslation& scene,
                  std::optional<TranslationWindow>& window)
      : problem_(problem), scene_(scene), window_(window) {}

  TranslationEstimate estimate(const Points& moved) override {
    return on_window_ ? window_->estimate(moved) : scene_.estimate(moved);
  }
  double translation_cost() const override {
    return on_window_ ? window_->translation_cost() : scene_.translation_cost();
  }
  void follow(const Eigen::Vector3d& centre, const Eigen::Vector3d& step, bool more) override {
    if (on_window_) {
      window_->follow(centre);
    } else if (problem_.params.max_translation == 0.0 && more &&
               step.norm() < 0.5 * problem_.margin) {
      place_window(problem_, window_, centre);  // near: go local
      on_window_ = true;
    }
  }
  std::optional<Eigen::Vector3i> window_dims() const override {
    return on_window_ ? std::optional<Eigen::Vector3i>(window_->dims()) : std::nullopt;
  }

 private:
  const Problem& problem_;
  SceneTranslation& scene_;
  std::optional<TranslationWindow>& window_;
  bool on_window_ = false;
};

// Algorithm 1 (eq. 16-17) from `pose` with the translation from `source`, and the
// fitness of where it ends.
AlignResult run_algorithm1(const Problem& problem, So3Correlation& correlation,
                           const ShCoefficients& scene_coefficients, Pose pose,
                           detail::TranslationSource& source, int max_iterations) {
  const detail::Algorithm1Problem loop{
      correlation,   scene_coefficients, problem.model_coefficients,
      problem.model, problem.params,     problem.deadline};
  AlignResult result = detail::run_algorithm1(loop, pose, source, max_iterations);
  result.fitness =
      problem.model.fitness(problem.scene, problem.view, pose, problem.params.voxel_size);
  return result;
}

// The EGI of the scene points in a window: in clutter, the object's own normals
// rather than the whole scene's.
std::optional<ShCoefficients> window_coefficients(const SceneMap& scene,
                                                  const Eigen::Vector3d& centre, double half_width,
                                                  const AlignParams& params) {
  const Eigen::AlignedBox3d box(centre - Eigen::Vector3d::Constant(half_width),
                                centre + Eigen::Vector3d::Constant(half_width));
  const std::vector<Eigen::Index> rows = scene.points_in(box);
  if (rows.size() < 3) return std::nullopt;
  return egi_coefficients(detail::rows_of(scene.cloud().normals(), rows), params.bandwidth,
                          params.egi_method);
}

struct Hypothesis {
  int index = 0;
  Pose pose;
  double fitness = 0.0;
};

// Fittest first; equals keep their order.
void rank(std::vector<Hypothesis>& hypotheses) {
  std::stable_sort(hypotheses.begin(), hypotheses.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.fitness > b.fitness; });
}

// Beyond the paper: the best rotations of the SO(3) search, each refined on the EGI
// correlation and placed by a phase correlation over the whole scene (coarse voxels),
// ranked by fitness.
std::vector<Hypothesis> global_hypotheses(const Problem& problem, So3Correlation& correlation,
                                          const ShCoefficients& scene_coefficients,
                                          double search_voxel) {
  const AlignParams& params = problem.params;
  So3SearchParams search;
  search.candidates = params.hypotheses;
  search.threads = params.threads;
  const auto candidates =
      so3_search(scene_coefficients, problem.model_coefficients, params.bandwidth, search);
  const Eigen::Vector3d start = problem.scene.cloud().centroid();
  SceneTranslation coarse(problem.scene, start, problem.model.reach(), search_voxel,
                          params.occupancy, phase_params(params), params.limits);
  RotationRefineParams refine;
  refine.newton = params.rotation_step == RotationStep::newton;
  std::vector<Hypothesis> hypotheses;
  for (std::size_t h = 0; h < candidates.size(); ++h) {
    if (h > 0 && expired(problem)) break;  // the best-correlated ones are first
    Hypothesis hypothesis;
    hypothesis.index = static_cast<int>(h);
    hypothesis.pose.R = refine_rotation(correlation, candidates[h].R, refine).R;
    hypothesis.pose.offset = start - problem.model.centroid();
    hypothesis.pose.offset += coarse.estimate(problem.model.move(hypothesis.pose)).shift;
    hypothesis.fitness =
        problem.model.fitness(problem.scene, problem.view, hypothesis.pose, search_voxel);
    hypotheses.push_back(hypothesis);
  }
  rank(hypotheses);
  return hypotheses;
}

// A connected part of the scene that could be the object, or the part of it a view
// shows: at least kPartMinPoints points, no smaller than a quarter of the model's reach
// and no larger than two of its diameters (two objects touching).
constexpr std::size_t kPartMinPoints = 30;
// Points this many voxels apart are in one part: the scene comes downsampled to half a
// voxel, and objects a few millimetres apart stay apart.
constexpr double kPartTolerance = 0.75;
constexpr std::size_t kMaxParts = 8;

std::vector<std::vector<Eigen::Index>> object_parts(
    const PointCloud& searched, const std::optional<detail::SupportPlane>& plane, double reach,
    double voxel_size) {
  // Without the points near the plane (their normals tilted at the objects' feet) that
  // would join every object into one part, or below it.
  std::vector<Eigen::Index> above;
  for (Eigen::Index i = 0; i < searched.points().rows(); ++i) {
    if (!plane || searched.points().row(i).dot(plane->normal) - plane->offset > 1.5 * voxel_size)
      above.push_back(i);
  }
  const Points points = detail::rows_of(searched.points(), above);
  const auto plausible = [&](const std::vector<Eigen::Index>& part) {
    Eigen::AlignedBox3d box;
    for (const Eigen::Index i : part) box.extend(searched.points().row(i).transpose());
    const double size = box.sizes().norm();
    return size >= 0.25 * reach && size <= 4.0 * reach;
  };
  std::vector<std::vector<Eigen::Index>> kept;
  for (auto& part : detail::connected_parts(points, kPartTolerance * voxel_size)) {
    if (part.size() < kPartMinPoints || kept.size() == kMaxParts) break;
    for (Eigen::Index& i : part) i = above[std::size_t(i)];
    if (plausible(part)) kept.push_back(std::move(part));
  }
  // A view of one object that its depth edges cut in parts: the parts, and the whole.
  if (kept.size() != 1 && plausible(above)) kept.insert(kept.begin(), std::move(above));
  return kept;
}

// A single view without a support plane (the object alone, or the part of it a view
// shows): the whole view is the one part, placed from the model's side facing the sensor.
std::vector<Eigen::Index> whole_view(const PointCloud& searched) {
  std::vector<Eigen::Index> all(searched.size());
  std::iota(all.begin(), all.end(), Eigen::Index(0));
  return all;
}

// Beyond the paper: in clutter the EGI of the whole scene mixes every object's normals,
// and its best rotations are mostly other objects'. Per connected part of the scene that
// could be the object, the SO(3) search runs on the part's own EGI, and its rotations are
// placed by phase correlation in a window around the part at the alignment's voxel.
std::vector<Hypothesis> part_hypotheses(const Problem& problem,
                                        const std::vector<std::vector<Eigen::Index>>& parts,
                                        int per_part, std::optional<TranslationWindow>& window) {
  const AlignParams& params = problem.params;
  const PointCloud& scene = problem.scene.cloud();
  So3SearchParams search;
  search.candidates = per_part;
  search.threads = params.threads;
  RotationRefineParams refine;
  refine.newton = params.rotation_step == RotationStep::newton;
  std::vector<Hypothesis> hypotheses;
  std::optional<TranslationWindow> coarse;
  for (const auto& part : parts) {
    if (!hypotheses.empty() && expired(problem)) break;
    const Points normals = detail::rows_of(scene.normals(), part);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Index i : part) centroid += scene.points().row(i).transpose();
    centroid /= double(part.size());
    const ShCoefficients coefficients =
        egi_coefficients(normals, params.bandwidth, params.egi_method);
    std::optional<So3Correlation> correlation;
    try {
      correlation.emplace(coefficients, problem.model_coefficients, params.bandwidth, true);
    } catch (const std::invalid_argument&) {
      continue;  // a part whose normals have no structure
    }
    place_window(problem, window, centroid);
    if (coarse) {
      coarse->place(centroid);
    } else {
      coarse.emplace(problem.scene, problem.model.reach(), problem.margin, centroid,
                     kCoarsePlacement * params.voxel_size, params.occupancy, phase_params(params),
                     params.limits);
    }
    for (const RotationCandidate& candidate :
         so3_search(coefficients, problem.model_coefficients, params.bandwidth, search)) {
      Hypothesis hypothesis;
      hypothesis.index = int(hypotheses.size());
      hypothesis.pose.R = refine_rotation(*correlation, candidate.R, refine).R;
      hypothesis.pose.offset = centroid - problem.model.centroid();
      if (problem.viewpoint) {
        hypothesis.pose.offset -=
            problem.model.facing_side(hypothesis.pose.R, centroid - *problem.viewpoint);
      }
      // Twice: the coarse shift brings the model near enough for the fine one to be exact.
      hypothesis.pose.offset += coarse->estimate(problem.model.move(hypothesis.pose)).shift;
      hypothesis.pose.offset += window->estimate(problem.model.move(hypothesis.pose)).shift;
      hypothesis.fitness =
          problem.model.fitness(problem.scene, problem.view, hypothesis.pose, params.voxel_size);
      hypotheses.push_back(hypothesis);
    }
  }
  rank(hypotheses);
  return hypotheses;
}

// For a model whose EGI has a flat axis (see flat_axis below), the EGI cannot tell its
// turns about that axis apart, but the scene can: the best-ranked hypotheses are turned
// to the fittest of the turns every kFlatAxisStep, scored with depths within `tolerance`.
constexpr std::size_t kTurnedHypotheses = 16;

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
      const double fitness = problem.model.fitness(problem.scene, problem.view, trial, tolerance);
      if (fitness > hypothesis.fitness) {
        hypothesis.fitness = fitness;
        hypothesis.pose = trial;
      }
    }
  }
  rank(hypotheses);
}

// Re-places `trial`'s translation by phase correlation in the window; its voxel overlap.
double placed_overlap(const Problem& problem, TranslationWindow& window, Pose& trial,
                      int& evaluations) {
  trial.offset += window.estimate(problem.model.move(trial)).shift;
  ++evaluations;
  return window.overlap(problem.model.move(trial));
}

// Beyond the paper: with noisy normals the EGI correlation peaks about a degree from the
// truth, and it cannot see small asymmetric parts (a mug's handle). The 3D voxel
// correlation sees the whole shape: the rotation is polished for the best overlap of the
// model's voxels with the window's, the translation re-placed by phase correlation at
// each trial. Per
// step size (4 down to 1/4 degree), trials at +-step about each model axis give a
// parabola per axis, whose vertex is tried as one combined step; the best trial wins.
Pose polish(const Problem& problem, TranslationWindow& window, Pose pose, int& evaluations) {
  window.follow(problem.model.centre(pose));
  const auto place = [&](Pose& trial) {
    return placed_overlap(problem, window, trial, evaluations);
  };
  double best = place(pose);
  int rounds_at_first_step = 0;
  for (double step = kPolishFirstStep; step >= kPolishLastStep;) {
    Eigen::Vector3d vertex = Eigen::Vector3d::Zero();
    Pose best_trial = pose;
    double best_trial_peak = best;
    for (int axis = 0; axis < 3; ++axis) {
      double peaks[2];
      for (int side = 0; side < 2; ++side) {
        Pose trial = pose;
        trial.R = pose.R * exp_so3((side ? step : -step) * Eigen::Vector3d::Unit(axis));
        peaks[side] = place(trial);
        if (peaks[side] > best_trial_peak) {
          best_trial_peak = peaks[side];
          best_trial = trial;
        }
      }
      const double curvature = peaks[0] + peaks[1] - 2.0 * best;
      if (curvature < 0.0)
        vertex[axis] = std::clamp(0.5 * step * (peaks[0] - peaks[1]) / curvature, -step, step);
    }
    Pose combined = pose;
    combined.R = pose.R * exp_so3(vertex);
    const double combined_peak = vertex.isZero() ? -1.0 : place(combined);
    if (combined_peak > best_trial_peak) {
      best_trial_peak = combined_peak;
      best_trial = combined;
    }
    const bool improved = best_trial_peak > best;
    if (improved) {
      best = best_trial_peak;
      pose = best_trial;
    }
    // The first step size walks on while it improves (a pose a few steps off, such as a
    // mug turned about its axis); the finer ones refine once each.
    if (!(improved && step == kPolishFirstStep && ++rounds_at_first_step < kPolishFirstStepRounds))
      step *= 0.5;
  }
  return pose;
}

// Algorithm 1 from a hypothesis, in a window of the scene around it, on the EGI of the
// scene inside that window.
AlignResult refine_hypothesis(const Problem& problem, So3Correlation& scene_correlation,
                              const ShCoefficients& scene_coefficients,
                              const Hypothesis& hypothesis,
                              std::optional<TranslationWindow>& window) {
  const double half_width = problem.model.reach() + problem.margin;
  const auto local = window_coefficients(problem.scene, problem.model.centre(hypothesis.pose),
                                         half_width, problem.params);
  std::optional<So3Correlation> local_correlation;
  if (local) {
    try {
      local_correlation.emplace(*local, problem.model_coefficients, problem.params.bandwidth, true);
    } catch (const std::invalid_argument&) {
      // A window whose normals have no structure (a uniform EGI): keep the scene's.
    }
  }
  So3Correlation& correlation = local_correlation ? *local_correlation : scene_correlation;
  const ShCoefficients& coefficients = local_correlation ? *local : scene_coefficients;
  place_window(problem, window, problem.model.centre(hypothesis.pose));
  AlignResult result = run_algorithm1(problem, correlation, coefficients, hypothesis.pose, *window,
                                      problem.params.refinement_iterations);
  result.hypothesis = hypothesis.index;
  // In clutter the window's EGI holds other objects' normals too, and Algorithm 1 can
  // walk off a right hypothesis: the fitter of the two poses is kept.
  const double start_fitness = problem.model.fitness(problem.scene, problem.view, hypothesis.pose,
                                                     problem.params.voxel_size);
  if (start_fitness > result.fitness) {
    // The returned pose is then not where this run ended: it claims no iterations.
    result.T_scene_model = problem.model.transform_of(hypothesis.pose);
    result.fitness = start_fitness;
    result.correlation = correlation.evaluate(hypothesis.pose.R).value;
    result.translation_peak = 0.0;
    result.converged = false;
    result.stop_reason = AlignStopReason::kept_start;
    result.iterations = 0;
    result.history.clear();
  }
  return result;
}

// The polish of the kept result, in a window placed around it.
// Points per occupied voxel of the model: below kPolishMinDensity the voxel overlap
// compares two sparse samplings more than two surfaces (a 400-point scan of a bunny at 8
// mm voxels has about one point per voxel), and the polish would only add noise.
double points_per_voxel(const Points& points, double voxel_size) {
  std::vector<std::array<long, 3>> voxels;
  voxels.reserve(std::size_t(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Array3d v = (points.row(i).transpose() / voxel_size).array().floor();
    voxels.push_back({long(v.x()), long(v.y()), long(v.z())});
  }
  std::sort(voxels.begin(), voxels.end());
  const auto distinct = std::unique(voxels.begin(), voxels.end()) - voxels.begin();
  return distinct ? double(points.rows()) / double(distinct) : 0.0;
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

// The turns of the model about its flat axis, every kFlatAxisStep, each placed by phase
// correlation and scored by voxel overlap: the best.
Pose sweep_flat_axis(const Problem& problem, TranslationWindow& window, const Pose& pose,
                     const Eigen::Vector3d& axis, int& evaluations) {
  window.follow(problem.model.centre(pose));
  Pose best = pose;
  double best_overlap = placed_overlap(problem, window, best, evaluations);
  const int turns = static_cast<int>(std::lround(2.0 * M_PI / kFlatAxisStep));
  for (int k = 1; k < turns; ++k) {
    Pose trial = pose;
    trial.R = pose.R * exp_so3(double(k) * kFlatAxisStep * axis);
    const double overlap = placed_overlap(problem, window, trial, evaluations);
    if (overlap > best_overlap) {
      best_overlap = overlap;
      best = trial;
    }
  }
  return best;
}

// The pose of `result` moved by `step` (the flat-axis sweep or the pattern search) in a
// window placed around it; left as it is for a model too sparse for the voxel overlap.
template <typename Step>
void polish_result(const Problem& problem, std::optional<TranslationWindow>& window,
                   AlignResult& result, Step step) {
  const Pose start = problem.model.pose_of(result.T_scene_model);
  if (points_per_voxel(problem.model.move(start), problem.params.voxel_size) < kPolishMinDensity)
    return;
  place_window(problem, window, problem.model.centre(start));
  const Pose polished = step(*window, start, result.polish_evaluations);
  result.T_scene_model = problem.model.transform_of(polished);
  result.fitness =
      problem.model.fitness(problem.scene, problem.view, polished, problem.params.voxel_size);
}

// The ICP refinement of a result (AlignParams::icp_refinement), against the whole scene;
// kept unless it loses more than kIcpFitnessLoss of fitness (a slide off the object).
constexpr double kIcpFitnessLoss = 0.05;
// Pairs within a voxel first (the spectral result may be most of one off), then, for a
// densely sampled model, within this share of one, which leaves out pairs that only the
// noise brought near: on single views 0.34 to 0.22 degree and 0.29 to 0.13 mm at the
// median, against 0.25 and 0.6. On a sparse scan (one point per voxel) the nearest points
// are mostly farther than that, and the few pairs left turned the bunny scan 0.3 to 4
// degrees.
constexpr double kIcpFineDistance = 0.4;

void refine_with_icp(const Problem& problem, const PointCloud& model, const PointCloud& scene,
                     AlignResult& result) {
  detail::IcpSettings settings;
  settings.viewpoint = problem.viewpoint;
  Transform T_scene_model = result.T_scene_model;
  int iterations = 0;
  const int stages = problem.dense_model ? 2 : 1;
  for (int stage = 0; stage < stages; ++stage) {
    settings.max_distance = (stage == 0 ? 1.0 : kIcpFineDistance) * problem.params.voxel_size;
    const detail::IcpOutcome outcome =
        detail::refine_point_to_plane(model, scene, T_scene_model, settings);
    if (outcome.iterations == 0) break;
    T_scene_model = outcome.T_scene_model;
    iterations += outcome.iterations;
  }
  if (iterations == 0) return;
  const double fitness = problem.model.fitness(
      problem.scene, problem.view, problem.model.pose_of(T_scene_model), problem.params.voxel_size);
  if (fitness < result.fitness - kIcpFitnessLoss) return;
  result.T_scene_model = T_scene_model;
  result.fitness = fitness;
  result.icp_iterations = iterations;
}

bool better(const AlignResult& a, const AlignResult& b) {
  if (a.fitness != b.fitness) return a.fitness > b.fitness;
  return a.correlation > b.correlation;
}

}  // namespace

namespace detail {

void check_align_params(const AlignParams& params) { check_params(params); }

std::chrono::steady_clock::time_point deadline_of(const AlignParams& params,
                                                  std::chrono::steady_clock::time_point start) {
  using Clock = std::chrono::steady_clock;
  if (params.max_seconds == 0.0) return Clock::time_point::max();
  const std::chrono::duration<double> budget(std::min(params.max_seconds, 1e9));  // no overflow
  return start + std::chrono::duration_cast<Clock::duration>(budget);
}

PhaseCorrelationParams phase_params(const AlignParams& params) {
  PhaseCorrelationParams p;
  p.subvoxel = params.subvoxel;
  p.threads = params.threads;
  p.limits = params.limits;
  return p;
}

}  // namespace detail

namespace {

// Pixels of the single-view detection, in tolerances at the scene's median distance: finer
// than the view check's half tolerance, so that a downsampled scan's far surfaces (several
// points per pixel of half a voxel, seen at a slant) are not taken for hidden ones, and
// coarse enough that the empty pixels between a full model's front points, filled from
// their neighbours, still hide its back.
constexpr double kDetectionPixel = 0.25;

// The share of the scene that a sensor at `origin` sees, on the range image `image` made
// from there.
double visible_share(const PointCloud& scene, const RangeImage& image, double tolerance) {
  const detail::ViewCheck seen =
      image.check(scene.points(), scene.normals(), tolerance, RangeImage::Distance::along_normal);
  return double(seen.surface_points) / double(scene.size());
}

// Where the sensor of the scene is, and whether the scene is one view from there.
struct SceneSensor {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  SceneView view = SceneView::automatic;
};

SceneSensor scene_sensor(const AlignParams& params) {
  if (params.scene_viewpoint) return {*params.scene_viewpoint, SceneView::single_view};
  return {params.sensor_origin, params.scene_view};
}

}  // namespace

namespace detail {

std::optional<Eigen::Vector3d> declared_viewpoint(const AlignParams& params) {
  const SceneSensor sensor = scene_sensor(params);
  if (sensor.view != SceneView::single_view) return std::nullopt;
  return sensor.origin;
}

}  // namespace detail

namespace {

// The range image of a single view (half-voxel pixels: a model point a voxel in front of
// or behind the scan is resolved), or none for a scene seen from all sides or one that
// the detection does not find to be a single view.
std::optional<RangeImage> single_view_image(const PointCloud& scene, const AlignParams& params) {
  const SceneSensor sensor = scene_sensor(params);
  if (sensor.view == SceneView::all_sides) return std::nullopt;
  if (sensor.view == SceneView::automatic &&
      !detect_single_view(scene, sensor.origin, params.voxel_size).single_view)
    return std::nullopt;
  return RangeImage(scene, sensor.origin, 0.5 * params.voxel_size);
}

// Turn between two rotations, degrees.
double turn_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const double c = std::clamp(0.5 * ((a.transpose() * b).trace() - 1.0), -1.0, 1.0);
  return std::acos(c) * 180.0 / M_PI;
}

// The initial guess as a hypothesis, ranked with the search's; with a neighbourhood, the
// search's hypotheses outside it are dropped.
void seed_with_guess(const Problem& problem, std::vector<Hypothesis>& hypotheses,
                     double tolerance) {
  const AlignParams& params = problem.params;
  Hypothesis guess;
  guess.index = -1;
  guess.pose = problem.model.pose_of(params.initial_guess);
  guess.fitness = problem.model.fitness(problem.scene, problem.view, guess.pose, tolerance);
  const Eigen::Vector3d centre = problem.model.centre(guess.pose);
  const auto outside = [&](const Hypothesis& h) {
    return (params.guess_angle_deg > 0.0 &&
            turn_deg(h.pose.R, guess.pose.R) > params.guess_angle_deg) ||
           (params.guess_distance > 0.0 &&
            (problem.model.centre(h.pose) - centre).norm() > params.guess_distance);
  };
  hypotheses.erase(std::remove_if(hypotheses.begin(), hypotheses.end(), outside), hypotheses.end());
  hypotheses.push_back(guess);
  rank(hypotheses);
}

// With guess_distance: the parts of the scene that the model could reach from the guess.
void keep_parts_near_guess(const Problem& problem, const PointCloud& searched,
                           std::vector<std::vector<Eigen::Index>>& parts) {
  const AlignParams& params = problem.params;
  if (!(params.guess_distance > 0.0)) return;
  const Eigen::Vector3d centre = problem.model.centre(problem.model.pose_of(params.initial_guess));
  const double reach = params.guess_distance + problem.model.reach();
  const auto far = [&](const std::vector<Eigen::Index>& part) {
    for (const Eigen::Index i : part)
      if ((searched.points().row(i).transpose() - centre).norm() <= reach) return false;
    return true;
  };
  parts.erase(std::remove_if(parts.begin(), parts.end(), far), parts.end());
}

}  // namespace

SingleViewEvidence detect_single_view(const PointCloud& scene, const Eigen::Vector3d& sensor_origin,
                                      double tolerance) {
  require_non_empty(scene, "scene");
  require_normals(scene, "scene");
  if (!sensor_origin.allFinite()) fail("sensor_origin must be finite");
  detail::require_positive_finite(tolerance, "tolerance");
  SingleViewEvidence evidence;
  try {
    const RangeImage image(scene, sensor_origin, kDetectionPixel * tolerance);
    evidence.visible = visible_share(scene, image, tolerance);
  } catch (const std::invalid_argument&) {
    evidence.visible = 0.0;  // nothing in front of the origin, or the origin at the centroid
  }
  evidence.single_view = evidence.visible >= single_view_threshold;
  return evidence;
}

AlignResult align(const PointCloud& model, const PointCloud& scene, const AlignParams& given) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  check_params(given);
  const Clock::time_point deadline = deadline_of(given, Clock::now());
  AlignParams params = given;
  if (params.voxel_size == 0.0) params.voxel_size = alignment_voxel_size(model, scene);
  MovingModel moving(model);
  // Beyond the paper: a table under the objects dominates both the scene's EGI and its
  // voxel grid; searched without it, the object stands out. Fitness still sees it.
  std::optional<detail::SupportPlane> plane;
  if (params.global_search && params.suppress_support_plane) {
    plane = detail::support_plane(scene, params.voxel_size, 4.0 * moving.reach());
  }
  const PointCloud searched =
      plane ? detail::without_support_plane(scene, params.voxel_size, 4.0 * moving.reach()) : scene;
  const SceneMap scene_map(searched, scene, params.voxel_size, params.limits);
  const ShCoefficients model_coefficients =
      egi_coefficients(model, params.bandwidth, params.egi_method);
  const ShCoefficients scene_coefficients =
      egi_coefficients(searched, params.bandwidth, params.egi_method);
  So3Correlation correlation(scene_coefficients, model_coefficients, params.bandwidth, true);
  const std::optional<RangeImage> view = single_view_image(scene, params);
  const RangeImage* view_ptr = view ? &*view : nullptr;
  const std::optional<Eigen::Vector3d> viewpoint =
      view ? std::optional<Eigen::Vector3d>(scene_sensor(params).origin) : std::nullopt;
  const auto finish = [&](AlignResult result) {
    result.voxel_size = params.voxel_size;
    result.single_view = view.has_value();
    return result;
  };

  if (!params.global_search) {
    const Problem problem{
        scene_map, view_ptr,     moving, model_coefficients, params, window_margin(0.0, params),
        deadline,  std::nullopt, true,   viewpoint};
    const Pose start = moving.pose_of(params.initial_guess);
    SceneTranslation whole_scene =
        params.max_translation > 0.0
            ? SceneTranslation(scene_map, box_of(moving.move(start)), params.max_translation,
                               params.voxel_size, params.occupancy, phase_params(params),
                               params.limits)
            : SceneTranslation(scene_map, moving.centre(start), moving.reach(), params.voxel_size,
                               params.occupancy, phase_params(params), params.limits);
    std::optional<TranslationWindow> window;
    SceneThenWindow source(problem, whole_scene, window);
    AlignResult result = run_algorithm1(problem, correlation, scene_coefficients, start, source,
                                        params.max_iterations);
    if (params.verify) {
      detail::set_verification(result, detail::Verifier(scene, params.voxel_size, viewpoint)
                                           .verify(model, result.T_scene_model));
    }
    return finish(std::move(result));
  }
  const double search_voxel = search_voxel_size(scene, moving.reach(), params);
  const std::optional<Eigen::Vector3d> axis = flat_axis(model_coefficients, params.bandwidth);
  const bool dense = points_per_voxel(model.points(), params.voxel_size) >= kPolishMinDensity;
  const Problem problem{
      scene_map, view_ptr, moving, model_coefficients, params, window_margin(search_voxel, params),
      deadline,  axis,     dense,  viewpoint};
  std::optional<TranslationWindow> window;
  std::vector<std::vector<Eigen::Index>> parts;
  if (plane) {
    parts = object_parts(searched, plane, moving.reach(), params.voxel_size);
    keep_parts_near_guess(problem, searched, parts);
  } else if (view) {
    parts.push_back(whole_view(searched));
  }
  std::vector<Hypothesis> hypotheses;
  if (parts.empty() && !(plane && params.guess_distance > 0.0)) {
    hypotheses = global_hypotheses(problem, correlation, scene_coefficients, search_voxel);
    seed_with_guess(problem, hypotheses, search_voxel);
  } else {
    const int per_part = plane ? std::max(1, params.hypotheses / 2) : params.hypotheses;
    hypotheses = part_hypotheses(problem, parts, per_part, window);
    seed_with_guess(problem, hypotheses, params.voxel_size);
    turn_about_flat_axis(problem, hypotheses, params.voxel_size);
  }
  // The refined hypotheses: the fittest, and with a neighbourhood always the guess.
  std::vector<const Hypothesis*> refined;
  const std::size_t runs =
      std::min<std::size_t>(std::size_t(params.refinements), hypotheses.size());
  for (std::size_t i = 0; i < runs; ++i) refined.push_back(&hypotheses[i]);
  if (has_neighbourhood(params)) {
    const auto guess = std::find_if(hypotheses.begin(), hypotheses.end(),
                                    [](const Hypothesis& h) { return h.index == -1; });
    if (guess != hypotheses.end() && std::size_t(guess - hypotheses.begin()) >= runs)
      refined.push_back(&*guess);
  }
  AlignResult best;
  bool out_of_time = false;
  for (std::size_t i = 0; i < refined.size() && !out_of_time; ++i) {
    AlignResult result =
        refine_hypothesis(problem, correlation, scene_coefficients, *refined[i], window);
    // Fitness tells a mug upright from upside down only with its handle in place, and a
    // view's fitness a pose from its near-symmetric flip only at a precise pose: each
    // result is swept and refined before they are compared.
    if (params.polish && axis) {
      polish_result(problem, window, result, [&](TranslationWindow& w, const Pose& p, int& n) {
        return sweep_flat_axis(problem, w, p, *axis, n);
      });
    }
    if (params.icp_refinement && view) refine_with_icp(problem, model, scene, result);
    out_of_time = result.stop_reason == AlignStopReason::max_seconds || expired(problem);
    if (i == 0 || better(result, best)) best = std::move(result);
  }
  if (out_of_time) {
    // An unfinished search claims nothing: the pose is the best found in time.
    best.converged = false;
    best.stop_reason = AlignStopReason::max_seconds;
  } else {
    // Without the ICP, which reaches past it at a fraction of its cost.
    if (params.polish && !params.icp_refinement) {
      polish_result(problem, window, best, [&](TranslationWindow& w, const Pose& p, int& n) {
        return polish(problem, w, p, n);
      });
    }
    if (params.icp_refinement) refine_with_icp(problem, model, scene, best);
  }
  best.search_voxel_size = search_voxel;
  const detail::Verifier verifier(scene, params.voxel_size, viewpoint);
  detail::set_verification(best, verifier.verify(model, best.T_scene_model));
  if (!out_of_time) {
    detail::AlternativeSources sources{model_coefficients, params.bandwidth, axis, {}};
    for (const Hypothesis& h : hypotheses)
      sources.hypotheses.push_back(moving.transform_of(h.pose));
    detail::find_alternatives(model, verifier, sources, params, viewpoint, best);
  }
  return finish(std::move(best));
}

}  // namespace spectral_vs
