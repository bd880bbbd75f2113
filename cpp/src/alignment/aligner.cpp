// align(): the model onto the scene, as the list of its stages (stages.hpp). The paper's
// mode (global_search off) runs Algorithm 1 once from the initial guess; the global
// search prepares the scene, generates hypotheses, refines them, verifies the best and
// reports the alternatives.
#include <spectral_vs/alignment/aligner.hpp>

#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/alternatives.hpp"
#include "alignment/hypotheses.hpp"
#include "alignment/part_coverage.hpp"
#include "alignment/refinement.hpp"
#include "alignment/resting.hpp"
#include "alignment/scale.hpp"
#include "alignment/scene_preparation.hpp"
#include "alignment/stages.hpp"
#include "alignment/support_plane.hpp"
#include "alignment/verdict_detail.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <optional>
#include <vector>

namespace spectral_vs {

using namespace detail;

namespace {

// The first stage, what both modes start from: the scene as searched (without its
// support plane), its map and EGI, the model's EGI and their correlation, and the
// scene's sensor. Built in place: the scene map points into `searched`.
struct Prepared {
  Prepared(const PointCloud& model, const PointCloud& scene, const AlignParams& params,
           const ScoredModel& moving)
      // Beyond the paper: a table under the objects dominates both the scene's EGI and its
      // voxel grid; searched without it, the object stands out. Fitness still sees it.
      : band(support_band(model.points(), params.scene.voxel_size)),
        plane(params.search.global_search && params.scene.suppress_support_plane
                  ? support_plane(scene, params.scene.voxel_size, 4.0 * moving.reach())
                  : std::nullopt),
        searched(plane ? without_support_plane(scene, *plane, params.scene.voxel_size, band)
                       : scene),
        scene_map(searched),
        model_coefficients(
            egi_coefficients(model, params.scene.bandwidth, params.scene.egi_method)),
        scene_coefficients(
            egi_coefficients(searched, params.scene.bandwidth, params.scene.egi_method)),
        correlation(scene_coefficients, model_coefficients, params.scene.bandwidth, true),
        viewpoint(single_view_origin(scene, params)),
        // The whole scene, its support plane included: a pose that sinks the model into
        // the table is no fit.
        verifier(scene, params.scene.voxel_size, viewpoint,
                 FitnessMap::spec_of(scene, params.scene.voxel_size, params.limits)) {}
  Prepared(const Prepared&) = delete;
  Prepared& operator=(const Prepared&) = delete;

  // What Algorithm 1 and the stages work with, on this scene.
  Problem problem(ScoredModel& moving, const AlignParams& params, double margin,
                  Clock::time_point deadline, std::optional<Eigen::Vector3d> flat_axis,
                  bool dense_model) const {
    return Problem{scene_map, verifier,  moving,      model_coefficients, params,  margin,
                   deadline,  flat_axis, dense_model, viewpoint,          &timings};
  }

  const double band;  // of the support plane, metres
  const std::optional<SupportPlane> plane;
  const PointCloud searched;
  const SceneMap scene_map;
  const ShCoefficients model_coefficients;
  const ShCoefficients scene_coefficients;
  So3Correlation correlation;
  const std::optional<Eigen::Vector3d> viewpoint;  // the sensor of a single view
  const Verifier verifier;
  mutable AlignTimings timings;  // added to by the stages through Problem::timings
};

// The paper's mode: Algorithm 1 from the initial guess, on the grid over the whole scene
// (or bounded around the model by max_translation), then in a window that follows it.
AlignResult align_from_guess(const PointCloud& model, const PointCloud& scene,
                             const AlignParams& params, ScoredModel& moving, Prepared& prepared,
                             Clock::time_point deadline) {
  const Problem problem =
      prepared.problem(moving, params, window_margin(0.0, params), deadline, std::nullopt, true);
  const Clock::time_point started = Clock::now();
  const Pose start = moving.pose_of(params.initial_guess);
  SceneTranslation whole_scene =
      params.local.max_translation > 0.0
          ? SceneTranslation(prepared.scene_map, box_of(moving.move(start)),
                             params.local.max_translation, params.scene.voxel_size,
                             params.scene.occupancy, phase_params(params), params.limits)
          : SceneTranslation(prepared.scene_map, moving.centre(start), moving.reach(),
                             params.scene.voxel_size, params.scene.occupancy, phase_params(params),
                             params.limits);
  std::optional<TranslationWindow> window;
  SceneThenWindow source(problem, whole_scene, window);
  AlignResult result =
      algorithm1_with_fitness(problem, prepared.correlation, prepared.scene_coefficients, start,
                              source, params.local.max_iterations);
  prepared.timings.algorithm1 = seconds_since(started);
  // The servo reads only the fitness; the check (AlignParams::verification.verify) is its to skip.
  const StageTimer timer(&prepared.timings, &AlignTimings::alternatives);
  if (params.verification.verify)
    set_verification(result, prepared.verifier.verify(model, result.T_scene_model));
  return result;
}

// The second stage: hypotheses per part of the scene that could be the object, or over
// the whole scene when it has no parts.
std::vector<Hypothesis> hypotheses_of(const Problem& problem, Prepared& prepared,
                                      double search_voxel,
                                      std::optional<TranslationWindow>& window) {
  const AlignParams& params = problem.params;
  std::vector<std::vector<Eigen::Index>> parts;
  if (prepared.plane) {
    parts = object_parts(prepared.searched, prepared.plane, problem.model.reach(),
                         params.scene.voxel_size, prepared.band);
    keep_parts_near_guess(problem, prepared.searched, parts);
  } else if (prepared.viewpoint) {
    parts.push_back(whole_view(prepared.searched));
  }
  std::vector<Hypothesis> hypotheses;
  if (parts.empty() && !(prepared.plane && params.search.guess_distance > 0.0)) {
    hypotheses =
        global_hypotheses(problem, prepared.correlation, prepared.scene_coefficients, search_voxel);
    seed_with_guess(problem, hypotheses, search_voxel);
  } else {
    const int per_part =
        prepared.plane ? std::max(1, params.search.hypotheses / 2) : params.search.hypotheses;
    hypotheses = part_hypotheses(problem, parts, per_part, prepared.plane.has_value(), window);
    seed_with_guess(problem, hypotheses, params.scene.voxel_size);
    turn_about_flat_axis(problem, hypotheses, params.scene.voxel_size);
  }
  return hypotheses;
}

// The hypotheses refined: the fittest, and with a neighbourhood always the guess.
std::vector<const Hypothesis*> refined_hypotheses(const std::vector<Hypothesis>& hypotheses,
                                                  const AlignParams& params) {
  std::vector<const Hypothesis*> refined;
  const std::size_t runs =
      std::min<std::size_t>(std::size_t(params.search.refinements), hypotheses.size());
  for (std::size_t i = 0; i < runs; ++i) refined.push_back(&hypotheses[i]);
  if (has_neighbourhood(params.search)) {
    const auto guess = std::find_if(hypotheses.begin(), hypotheses.end(),
                                    [](const Hypothesis& h) { return h.index == -1; });
    if (guess != hypotheses.end() && std::size_t(guess - hypotheses.begin()) >= runs)
      refined.push_back(&*guess);
  }
  return refined;
}

// A hypothesis that fits under kRefinedFitnessShare of the fitness of the best pose
// refined before it is not refined: the further refinements are there for near-symmetric
// flips, which fit about as well. Over 1904 refinements of a second or third hypothesis
// on 952 tuning cases (every tuning family and the thin objects, in their camera's frame),
// none that ended fitter than the best before it had started under 0.70 of its fitness;
// 0.65 leaves a margin. It skips 9% of them, and on a room's depth frame (where the
// hypotheses after the first fit 0.36-0.61 of it) the two that took 40% of the time.
constexpr double kRefinedFitnessShare = 0.65;

// Whether `hypothesis` is refined after a pose of fitness `best_fitness`; with a
// neighbourhood the guess always is.
bool worth_refining(const Hypothesis& hypothesis, double best_fitness, const AlignParams& params) {
  if (hypothesis.index == -1 && has_neighbourhood(params.search)) return true;
  return hypothesis.fitness >= kRefinedFitnessShare * best_fitness;
}

// The third stage: each refined hypothesis through Algorithm 1 and the sweep, the best
// polished and through the ICP.
AlignResult refine_best(const Problem& problem, const PointCloud& model, const PointCloud& scene,
                        Prepared& prepared, const std::vector<const Hypothesis*>& refined,
                        std::optional<TranslationWindow>& window) {
  const AlignParams& params = problem.params;
  AlignResult best;
  bool out_of_time = false;
  int runs = 0;
  for (std::size_t i = 0; i < refined.size() && !out_of_time; ++i) {
    if (i > 0 && !worth_refining(*refined[i], best.fitness, params)) continue;
    ++runs;
    AlignResult result = refine_hypothesis(problem, prepared.correlation,
                                           prepared.scene_coefficients, *refined[i], window);
    // Fitness tells a mug upright from upside down only with its handle in place, and a
    // view's fitness a pose from its near-symmetric flip only at a precise pose: each
    // result is swept and refined before they are compared.
    if (params.refinement.polish && problem.flat_axis)
      sweep_result_about(problem, window, result, *problem.flat_axis);
    if (params.refinement.icp_refinement && prepared.viewpoint) {
      const StageTimer timer(problem.timings, &AlignTimings::icp);
      refine_with_icp(problem, model, scene, result);
    }
    out_of_time = result.stop_reason == AlignStopReason::max_seconds || expired(problem);
    if (i == 0 || better(result, best)) best = std::move(result);
  }
  best.refinements_run = runs;
  if (out_of_time) {
    // An unfinished search claims nothing: the pose is the best found in time.
    best.converged = false;
    best.stop_reason = AlignStopReason::max_seconds;
    return best;
  }
  // Without the ICP, which reaches past it at a fraction of its cost.
  if (params.refinement.polish && !params.refinement.icp_refinement)
    polish_result_rotation(problem, window, best);
  if (params.refinement.icp_refinement) {
    const StageTimer timer(problem.timings, &AlignTimings::icp);
    refine_with_icp(problem, model, scene, best);
  }
  return best;
}

// A cluttered scene's alternative as confident as the refined pose within kCoverageTie
// that explains a share of its object's part larger by over kCoverageGap is returned
// instead. Chosen on tuning thin objects in clutter (benchmarks/thin_objects.py): 120 to
// 123 of 126 at ties of 0.01 and 0.02 and gaps of 0.1 and 0.2, 121 at a tie of 0; 280
// tuning clutter scenes and the milk scene unchanged.
constexpr double kCoverageTie = 0.01;
constexpr double kCoverageGap = 0.2;

// The alternative that explains the most of its part, if it beats the refined pose by
// the rule above.
const AlignAlternative* most_covering(const AlignResult& best, const PointCloud& model,
                                      const PartCoverage& coverage) {
  double most = coverage.explained_share(model, best.T_scene_model) + kCoverageGap;
  const AlignAlternative* chosen = nullptr;
  for (const AlignAlternative& alternative : best.alternatives) {
    if (alternative.confidence < best.confidence - kCoverageTie) continue;
    const double share = coverage.explained_share(model, alternative.T_scene_model);
    if (share > most) {
      most = share;
      chosen = &alternative;
    }
  }
  return chosen;
}

// The last stage: the refinements are ranked by fitness, and the confidence tells right
// from wrong better (ROC AUC 0.997 against 0.974 on the tuning families). The alternative
// returned instead of the refined pose, if any: the most confident, when it is more
// confident by over reselect_margin; else, in clutter, the most covering (most_covering);
// else the one with the most inliers of those as confident with more inliers than it.
// The confidence counts what the sensor would see: a flat box whose hidden faces sit
// inside another object scores as high as the same box lying on the table, whose
// underside the table confirms and whose part of the scene it explains whole. The
// alternative came from the verification's ICP, not from a run of Algorithm 1.
const AlignAlternative* replacement(const AlignResult& best, double margin, const PointCloud& model,
                                    const std::optional<PartCoverage>& coverage) {
  if (best.alternatives.empty() || margin >= 1.0) return nullptr;
  const AlignAlternative& most_confident = best.alternatives.front();
  if (most_confident.confidence > best.confidence + margin) return &most_confident;
  if (coverage) {
    if (const AlignAlternative* covering = most_covering(best, model, *coverage)) return covering;
  }
  const AlignAlternative* chosen = nullptr;
  for (const AlignAlternative& alternative : best.alternatives) {
    if (alternative.confidence >= best.confidence && alternative.inliers > best.inliers &&
        (!chosen || alternative.inliers > chosen->inliers))
      chosen = &alternative;
  }
  return chosen;
}

// `chosen` returned instead of the refined pose.
void adopt(const Problem& problem, Prepared& prepared, const AlignAlternative& chosen,
           AlignResult& best) {
  // Verified by the same verifier as the refined pose: its figures are the pose's.
  best.T_scene_model = chosen.T_scene_model;
  best.confidence = chosen.confidence;
  best.inliers = chosen.inliers;
  best.inlier_rmse = chosen.inlier_rmse;
  const Pose pose = problem.model.pose_of(best.T_scene_model);
  best.fitness = problem.model.fitness(problem.verifier, pose, problem.params.scene.voxel_size);
  best.correlation = prepared.correlation.evaluate(pose.R).value;
  best.translation_peak = 0.0;
  best.converged = false;
  best.stop_reason = AlignStopReason::reselected;
  best.iterations = 0;
  best.history.clear();
  best.hypothesis = -2;
  best.polish_evaluations = 0;
  best.icp_iterations = 0;
}

// Whether an alternative replaced the refined pose (replacement).
bool reselect(const Problem& problem, Prepared& prepared, const PointCloud& model,
              const std::optional<PartCoverage>& coverage, AlignResult& best) {
  const AlignAlternative* replacing =
      replacement(best, problem.params.verification.reselect_margin, model, coverage);
  if (!replacing) return false;
  adopt(problem, prepared, *replacing, best);
  return true;
}

// In clutter, a returned pose that does not rest (RestingCheck: a flat model flush with a
// face of a larger object, the rest of it inside that object with nothing under it) is
// replaced by the most confident pose that rests, of the alternatives and of
// kRestingPerPart resting poses per part of the scene (resting_poses), each refined by
// the ICP, when that pose is at most kRestingMargin less confident. Chosen on tuning
// thin objects in clutter, standing ones among them (benchmarks/thin_objects.py) and the
// tuning clutter scenes: see docs/experiments.md, "Thin objects".
constexpr int kRestingPerPart = 2;
constexpr double kRestingMargin = 0.1;

// The most confident resting pose of the candidates, refined by the ICP, if any rests.
std::optional<AlignAlternative> most_confident_resting(const PointCloud& model,
                                                       const Verifier& verifier,
                                                       const RestingCheck& check,
                                                       const std::vector<Transform>& candidates,
                                                       const Prepared& prepared, double voxel) {
  std::optional<AlignAlternative> resting;
  for (const Transform& candidate : candidates) {
    const Transform T = refine_by_icp(model, verifier, candidate, voxel, prepared.viewpoint);
    if (!check.rests(model, T)) continue;
    const PoseVerification v = verifier.verify(model, T);
    if (resting && v.confidence <= resting->confidence) continue;
    resting.emplace();
    resting->T_scene_model = T;
    resting->confidence = v.confidence;
    resting->inliers = v.inliers;
    resting->inlier_rmse = v.inlier_rmse;
  }
  return resting;
}

// Whether a resting pose replaced one that does not rest (kRestingMargin).
bool rest_on_support(const Problem& problem, Prepared& prepared, const PointCloud& model,
                     const Verifier& verifier, AlignResult& best) {
  // Past max_seconds the returned pose stands: the search is not reopened.
  if (problem.params.verification.reselect_margin >= 1.0 || expired(problem)) return false;
  const double voxel = problem.params.scene.voxel_size;
  const RestingCheck check(prepared.searched, *prepared.plane, voxel);
  if (check.rests(model, best.T_scene_model)) return false;
  std::vector<Transform> candidates;
  for (const AlignAlternative& alternative : best.alternatives)
    candidates.push_back(alternative.T_scene_model);
  const auto parts =
      object_parts(prepared.searched, prepared.plane, problem.model.reach(), voxel, prepared.band);
  for (const Transform& T :
       resting_poses(problem, prepared.searched, parts, *prepared.plane, kRestingPerPart))
    candidates.push_back(T);
  const std::optional<AlignAlternative> resting =
      most_confident_resting(model, verifier, check, candidates, prepared, voxel);
  if (!resting || resting->confidence < best.confidence - kRestingMargin) return false;
  adopt(problem, prepared, *resting, best);
  return true;
}

// Beyond the paper: the global search over SO(3) and R^3, its stages in order.
AlignResult align_globally(const PointCloud& model, const PointCloud& scene,
                           const AlignParams& params, ScoredModel& moving, Prepared& prepared,
                           Clock::time_point deadline) {
  AlignTimings& timings = prepared.timings;
  Clock::time_point started = Clock::now();
  const double search_voxel = search_voxel_size(scene, moving.reach(), params);
  const std::optional<Eigen::Vector3d> axis =
      flat_axis(prepared.model_coefficients, params.scene.bandwidth);
  const bool dense = dense_for_polish(model.points(), params.scene.voxel_size);
  const Problem problem =
      prepared.problem(moving, params, window_margin(search_voxel, params), deadline, axis, dense);
  timings.preparation += seconds_since(started);
  started = Clock::now();
  std::optional<TranslationWindow> window;
  const std::vector<Hypothesis> hypotheses = hypotheses_of(problem, prepared, search_voxel, window);
  timings.placement = seconds_since(started) - timings.rotation_search;
  started = Clock::now();
  AlignResult best =
      refine_best(problem, model, scene, prepared, refined_hypotheses(hypotheses, params), window);
  timings.algorithm1 = seconds_since(started) - timings.icp;
  const StageTimer timer(&timings, &AlignTimings::alternatives);
  best.search_voxel_size = search_voxel;
  const Verifier& verifier = prepared.verifier;
  set_verification(best, verifier.verify(model, best.T_scene_model));
  if (best.stop_reason != AlignStopReason::max_seconds &&
      params.verification.max_alternatives > 0) {
    AlternativeSources sources{
        model_symmetries(prepared.model_coefficients, params.scene.bandwidth, params.threads),
        axis,
        {}};
    for (const Hypothesis& h : hypotheses)
      sources.hypotheses.push_back(moving.transform_of(h.pose));
    find_alternatives(model, verifier, sources, params, prepared.viewpoint, best);
    // The parts are cut only when there is an alternative to weigh (a few percent of a
    // cluttered alignment's time otherwise).
    std::optional<PartCoverage> coverage;
    if (prepared.plane && !best.alternatives.empty())
      coverage.emplace(prepared.searched, *prepared.plane, prepared.band, params.scene.voxel_size);
    if (reselect(problem, prepared, model, coverage, best))
      find_alternatives(model, verifier, sources, params, prepared.viewpoint, best);
    if (prepared.plane && rest_on_support(problem, prepared, model, verifier, best))
      find_alternatives(model, verifier, sources, params, prepared.viewpoint, best);
  }
  return best;
}

}  // namespace

AlignResult align(const PointCloud& model, const PointCloud& scene, const AlignParams& given) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  check_align_params(given);
  const Clock::time_point deadline = deadline_of(given, Clock::now());
  AlignParams params = given;
  if (params.scene.voxel_size == 0.0) params.scene.voxel_size = alignment_voxel_size(model, scene);
  ScoredModel moving(model);
  const Clock::time_point started = Clock::now();
  Prepared prepared(model, scene, params, moving);
  prepared.timings.preparation = seconds_since(started);
  AlignResult result = params.search.global_search
                           ? align_globally(model, scene, params, moving, prepared, deadline)
                           : align_from_guess(model, scene, params, moving, prepared, deadline);
  result.voxel_size = params.scene.voxel_size;
  result.single_view = prepared.viewpoint.has_value();
  // The last stage: the verdict, wherever a pose was verified.
  const Clock::time_point judged = Clock::now();
  if (params.verification.verify || params.search.global_search) {
    judge(result, model, prepared.verifier, typical_size(model.points()),
          typical_size(scene.points()));
  } else {
    leave_unjudged(result);
  }
  result.timings = prepared.timings;
  result.timings.verdict = seconds_since(judged);
  result.timings.total = seconds_since(started);
  return result;
}

}  // namespace spectral_vs
