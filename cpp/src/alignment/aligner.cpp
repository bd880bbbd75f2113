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
#include "alignment/point_sets.hpp"
#include "alignment/polish.hpp"
#include "alignment/prepared.hpp"
#include "alignment/refinement.hpp"
#include "alignment/reselection.hpp"
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

// The paper's mode: Algorithm 1 from the initial guess, on the grid over the whole scene
// (or bounded around the model by max_translation), then in a window that follows it.
AlignResult align_from_guess(const PointCloud& model, const PointCloud& scene,
                             const AlignParams& params, ScoredModel& moving, Prepared& prepared,
                             Clock::time_point deadline) {
  const Problem problem =
      prepared.problem(moving, params, window_margin(params.search, params.scene.voxel_size, 0.0),
                       deadline, std::nullopt, true);
  const Clock::time_point started = Clock::now();
  const Pose start = moving.pose_of(params.initial_guess);
  SceneTranslation whole_scene =
      params.local.max_translation > 0.0
          ? SceneTranslation(prepared.scene_map, points_box(moving.move(start)),
                             params.local.max_translation, params.scene.voxel_size,
                             params.scene.occupancy, phase_params(params), params.limits)
          : SceneTranslation(prepared.scene_map, moving.centre(start), moving.reach(),
                             params.scene.voxel_size, params.scene.occupancy, phase_params(params),
                             params.limits);
  WindowCache windows;
  SceneThenWindow source(problem, params.local, whole_scene, windows);
  AlignResult result = algorithm1_with_fitness(problem, params.local, prepared.correlation,
                                               prepared.scene_coefficients, start, source,
                                               params.local.max_iterations);
  prepared.timings.algorithm1 = seconds_since(started);
  if (params.local.icp) {
    const StageTimer timer(&prepared.timings, &AlignTimings::icp);
    refine_with_icp(problem, model, scene, result, /*after_guess=*/true);
  }
  // The servo reads only the fitness; the check (AlignParams::verification.verify) is its to skip.
  const StageTimer timer(&prepared.timings, &AlignTimings::alternatives);
  if (params.verification.verify)
    set_verification(result, prepared.verifier.verify(model, result.T_scene_model));
  return result;
}

// The second stage: hypotheses per part of the scene that could be the object, or over
// the whole scene when it has no parts.
std::vector<Hypothesis> hypotheses_of(const Problem& problem, const AlignParams& params,
                                      Prepared& prepared, double search_voxel,
                                      WindowCache& windows) {
  std::vector<std::vector<Eigen::Index>> parts;
  if (prepared.plane) {
    parts = object_parts(prepared.searched, prepared.plane, problem.model.reach(),
                         params.scene.voxel_size, prepared.band, params.search.max_parts);
    keep_parts_near_guess(problem, params.search, params.initial_guess, prepared.searched, parts);
  } else if (prepared.viewpoint) {
    parts.push_back(whole_view(prepared.searched));
  }
  std::vector<Hypothesis> hypotheses;
  if (parts.empty() && !(prepared.plane && params.search.guess_distance > 0.0)) {
    hypotheses = global_hypotheses(problem, params.search, params.local, prepared.correlation,
                                   prepared.scene_coefficients, search_voxel);
    seed_with_guess(problem, params.search, params.initial_guess, hypotheses, search_voxel);
  } else {
    const int per_part =
        prepared.plane ? std::max(1, params.search.hypotheses / 2) : params.search.hypotheses;
    hypotheses = part_hypotheses(problem, params.local, parts, per_part, prepared.plane.has_value(),
                                 windows);
    seed_with_guess(problem, params.search, params.initial_guess, hypotheses,
                    params.scene.voxel_size);
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
AlignResult refine_best(const Problem& problem, const AlignParams& params, const PointCloud& model,
                        const PointCloud& scene, Prepared& prepared,
                        const std::vector<const Hypothesis*>& refined, WindowCache& windows) {
  AlignResult best;
  bool out_of_time = false;
  int runs = 0;
  for (std::size_t i = 0; i < refined.size() && !out_of_time; ++i) {
    if (i > 0 && !worth_refining(*refined[i], best.fitness, params)) continue;
    ++runs;
    AlignResult result =
        refine_hypothesis(problem, params.refinement, params.local, prepared.correlation,
                          prepared.scene_coefficients, *refined[i], windows);
    // Fitness tells a mug upright from upside down only with its handle in place, and a
    // view's fitness a pose from its near-symmetric flip only at a precise pose: each
    // result is swept and refined before they are compared.
    if (params.refinement.polish && problem.flat_axis)
      sweep_result_about(problem, windows, result, *problem.flat_axis);
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
    polish_result_rotation(problem, windows, best);
  if (params.refinement.icp_refinement) {
    const StageTimer timer(problem.timings, &AlignTimings::icp);
    refine_with_icp(problem, model, scene, best);
  }
  return best;
}

// Beyond the paper: the global search over SO(3) and R^3, its stages in order.
AlignResult align_globally(const PointCloud& model, const PointCloud& scene,
                           const AlignParams& params, ScoredModel& moving, Prepared& prepared,
                           Clock::time_point deadline) {
  AlignTimings& timings = prepared.timings;
  Clock::time_point started = Clock::now();
  const double search_voxel =
      search_voxel_size(scene, moving.reach(), params.search, params.scene.voxel_size);
  const std::optional<Eigen::Vector3d> axis =
      flat_axis(prepared.model_coefficients, params.scene.bandwidth);
  const bool dense = dense_for_polish(model.points(), params.scene.voxel_size);
  const Problem problem = prepared.problem(
      moving, params, window_margin(params.search, params.scene.voxel_size, search_voxel), deadline,
      axis, dense);
  timings.preparation += seconds_since(started);
  started = Clock::now();
  WindowCache windows;
  const std::vector<Hypothesis> hypotheses =
      hypotheses_of(problem, params, prepared, search_voxel, windows);
  timings.placement = seconds_since(started) - timings.rotation_search;
  started = Clock::now();
  AlignResult best = refine_best(problem, params, model, scene, prepared,
                                 refined_hypotheses(hypotheses, params), windows);
  timings.algorithm1 = seconds_since(started) - timings.icp;
  const StageTimer timer(&timings, &AlignTimings::alternatives);
  best.search_voxel_size = search_voxel;
  const Verifier& verifier = prepared.verifier;
  set_verification(best, verifier.verify(model, best.T_scene_model));
  // Made once: the resting rule and the verdict's `rests` ask it, of the same scene cells.
  std::optional<RestingCheck> resting;
  if (prepared.plane) resting.emplace(prepared.searched, *prepared.plane, params.scene.voxel_size);
  const auto check_rest = [&] {
    if (resting) best.rests = resting->rests(model, best.T_scene_model);
  };
  if (best.stop_reason == AlignStopReason::max_seconds ||
      params.verification.max_alternatives == 0) {
    check_rest();
  } else {
    AlternativeSources sources{
        model_symmetries(prepared.model_coefficients, params.scene.bandwidth, params.threads),
        axis,
        {}};
    for (const Hypothesis& h : hypotheses)
      sources.hypotheses.push_back(moving.transform_of(h.pose));
    // The alternatives of the pose `best` holds now (it may change twice below).
    const auto seek_alternatives = [&] {
      best.alternatives =
          find_alternatives(model, verifier, sources, params.verification, params.scene.voxel_size,
                            prepared.viewpoint, best.T_scene_model, best.confidence);
      best.ambiguous = !best.alternatives.empty();
    };
    seek_alternatives();
    // The parts are cut only when there is an alternative to weigh (a few percent of a
    // cluttered alignment's time otherwise).
    std::optional<PartCoverage> coverage;
    if (prepared.plane && !best.alternatives.empty())
      coverage.emplace(prepared.searched, *prepared.plane, prepared.band, params.scene.voxel_size);
    if (reselect(problem, params.verification, prepared, model, coverage, best))
      seek_alternatives();
    check_rest();
    // A pose that does not rest gives way to a resting one, which then rests by its check.
    if (!best.rests && params.verification.expect_resting &&
        rest_on_support(problem, params.verification, params.search, prepared, model, verifier,
                        *resting, best)) {
      seek_alternatives();
      best.rests = true;
    }
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
  const Clock::time_point deadline = deadline_of(given.max_seconds, Clock::now());
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
          typical_size(scene.points()), params.verification.expect_resting);
  } else {
    leave_unjudged(result);
  }
  result.timings = prepared.timings;
  result.timings.verdict = seconds_since(judged);
  result.timings.total = seconds_since(started);
  return result;
}

}  // namespace spectral_vs
