// Scene-to-scene registration as a pipeline of stages (view_stages.hpp): scale,
// preparation, hypotheses (the SO(3) search of the views' EGIs, each rotation placed by
// phase correlation), refinement (align()'s, refinement.hpp, configured here), the verdict.

#include <spectral_vs/alignment/view_aligner.hpp>

#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/refinement.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verifier.hpp"
#include "alignment/view_stages.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

namespace spectral_vs {

using detail::fail;
using namespace detail::views;

namespace {

// Best-supported window hypotheses refined: the views that set the window search off are
// those whose checked scores say least, and on the rendered iiwa pairs of seed 7 (tuning)
// a right window hypothesis came second or third of them; 5 won no more.
constexpr int kWindowRefinements = 3;

void check_params(const ViewAlignParams& p) {
  check_grid_limits(p.limits);
  if (!(p.voxel_size >= 0.0 && std::isfinite(p.voxel_size)))
    fail("voxel_size must be >= 0 metres (0: derived from the views), got ", p.voxel_size);
  if (!(p.search_voxel_size >= 0.0 && std::isfinite(p.search_voxel_size)))
    fail("search_voxel_size must be >= 0 metres (0: twice the voxel), got ", p.search_voxel_size);
  if (!(p.voxels_across >= 4.0 && std::isfinite(p.voxels_across)))
    fail("voxels_across must be finite and >= 4, got ", p.voxels_across);
  if (p.bandwidth < 2 || p.bandwidth > kMaxAlignBandwidth)
    fail("bandwidth must be in [2, ", kMaxAlignBandwidth, "], got ", p.bandwidth);
  if (p.hypotheses < 1) fail("hypotheses must be >= 1, got ", p.hypotheses);
  if (p.refinements < 1 || p.refinements > p.hypotheses)
    fail("refinements must be in [1, hypotheses = ", p.hypotheses, "], got ", p.refinements);
  if (p.refinement_iterations < 1 || p.refinement_iterations > kMaxAlignIterations)
    fail("refinement_iterations must be in [1, ", kMaxAlignIterations, "], got ",
         p.refinement_iterations);
  if (!p.sensor_origin.allFinite()) fail("sensor_origin must be finite");
  if (!(p.window_search_below >= 0.0 && p.window_search_below <= 1.0))
    fail("window_search_below must be in [0, 1] (a support score; 0: never), got ",
         p.window_search_below);
  if (!(p.max_seconds >= 0.0 && std::isfinite(p.max_seconds)))
    fail("max_seconds must be >= 0 seconds (0: no limit), got ", p.max_seconds);
  if (p.threads < 1 || p.threads > 256) fail("threads must be in [1, 256], got ", p.threads);
}

// The scale of view_scale, or the settings' where given.
ViewScale scale_of(const PointCloud& reference, const PointCloud& current,
                   const ViewAlignParams& params) {
  ViewScale scale = view_scale(reference, current, params.voxels_across);
  if (params.voxel_size > 0.0) {
    scale.voxel_size = params.voxel_size;
    scale.search_voxel_size = 2.0 * params.voxel_size;
  }
  if (params.search_voxel_size > 0.0) scale.search_voxel_size = params.search_voxel_size;
  return scale;
}

void check_views(const PointCloud& reference, const PointCloud& current,
                 const ViewAlignParams& params) {
  require_non_empty(reference, "reference");
  require_non_empty(current, "current");
  require_normals(reference, "reference");
  require_normals(current, "current");
  check_params(params);
}

}  // namespace

namespace detail::views {

namespace {

// Translation room of Algorithm 1 around each hypothesis, in search voxels: the
// placement is within half a search voxel, the rotation within a few degrees.
constexpr double kRefinementRoom = 2.0;

}  // namespace

// Stage: refinement, the one of refinement.hpp configured by the views' data: Algorithm 1
// on the views' EGI correlation and a grid bounded around the hypothesis, then the ICP
// against the current view's neighbour grid, each kept by the support's score at a voxel.
ViewAlignResult refine(const Views& views, const Hypothesis& hypothesis) {
  ViewAlignResult result;
  result.hypothesis = hypothesis.index;
  result.T_current_reference = views.model.transform_of(hypothesis.pose);
  result.support = hypothesis.support;
  const Eigen::AlignedBox3d box = points_box(views.model.move(hypothesis.pose));
  // A hypothesis that moved the reference off the current view has nothing to refine on
  // (and its grid, spanning both, could be of any size).
  if (!box.intersects(bounding_box(views.map.cloud()))) return result;
  SceneTranslation grid(views.map, box, kRefinementRoom * views.scale.search_voxel_size,
                        views.scale.voxel_size, views.params.occupancy, views.phase,
                        views.params.limits);
  const Algorithm1Problem loop{views.correlation,
                               views.current_coefficients,
                               views.reference_coefficients,
                               views.model,
                               views.local,
                               views.scale.voxel_size,
                               views.params.bandwidth,
                               views.deadline,
                               false};  // its history is not read
  const TransformScore support_score = [&](const Transform& T) {
    return views.support.of(T, kCoarseTolerance).score;
  };
  AlignResult refined = algorithm1_step(
      loop, grid, views.params.refinement_iterations, hypothesis.pose, hypothesis.support.score,
      [&](const Pose& pose) { return support_score(views.model.transform_of(pose)); });
  if (views.params.icp_refinement) {
    IcpSettings icp;
    icp.viewpoint = views.params.sensor_origin;
    icp_step(views.reference, views.fine_scene, views.scale.voxel_size, icp, true, support_score,
             refined);
  }
  result.T_current_reference = refined.T_scene_model;
  result.icp_iterations = refined.icp_iterations;
  result.support = views.support.of(result.T_current_reference, kFineTolerance);
  return result;
}

bool refine_into(const Views& views, const std::vector<Hypothesis>& ranked, int count,
                 std::optional<ViewAlignResult>& kept) {
  for (std::size_t i = 0; i < std::min(std::size_t(count), ranked.size()); ++i) {
    ViewAlignResult result = refine(views, ranked[i]);
    if (!kept || result.support.score > kept->support.score) kept = std::move(result);
    if (expired(views)) return false;
  }
  return true;
}

}  // namespace detail::views

ViewSupport view_support(const PointCloud& reference_view, const PointCloud& current_view,
                         const Transform& T_current_reference, const ViewAlignParams& params) {
  check_views(reference_view, current_view, params);
  require_rigid_transform(T_current_reference, "T_current_reference");
  const ViewScale scale = scale_of(reference_view, current_view, params);
  const PointCloud current = prepared(current_view, params, scale.voxel_size);
  const PointCloud reference = prepared(reference_view, params, scale.voxel_size);
  const detail::Verifier verifier(current, scale.voxel_size, params.sensor_origin);
  SupportCheck support(verifier, structure(reference, plane_balance(reference.normals())));
  return support.of(T_current_reference, kFineTolerance);
}

ViewAlignResult align_views(const PointCloud& reference_view, const PointCloud& current_view,
                            const ViewAlignParams& params, const std::optional<Transform>& prior) {
  check_views(reference_view, current_view, params);
  if (prior) require_rigid_transform(*prior, "prior");
  const Clock::time_point started = Clock::now();
  ViewAlignTimings timings;
  Clock::time_point stage = started;
  const auto lap = [&stage](double& into) {
    into = detail::seconds_since(stage);
    stage = Clock::now();
  };
  const ViewScale scale = scale_of(reference_view, current_view, params);
  PreparedViews prepared(reference_view, current_view, params, scale, started);
  const Views views = prepared.views();
  detail::MovingModel& model = views.model;
  SupportCheck& support = views.support;
  lap(timings.preparation);

  const std::vector<Hypothesis> ranked = hypotheses(views);
  lap(timings.hypotheses);
  std::optional<ViewAlignResult> kept;
  bool in_time = true;
  if (prior) {
    // The prior first: a searched pose must be better supported to replace it.
    Hypothesis given;
    given.index = -1;
    given.pose = model.pose_of(*prior);
    given.support = support.of(*prior, kCoarseTolerance);
    given.fitness = given.support.score;
    kept = refine(views, given);
    in_time = !expired(views);
  }
  if (in_time) in_time = refine_into(views, ranked, params.refinements, kept);
  lap(timings.refinement);
  std::vector<Hypothesis> checked = ranked;
  int windows_checked = 0;
  if (in_time && kept && kept->support.score < params.window_search_below) {
    std::vector<Hypothesis> windows = window_hypotheses(views, int(ranked.size()), windows_checked);
    rank(windows);
    in_time = !expired(views) && refine_into(views, windows, kWindowRefinements, kept);
    checked.insert(checked.end(), windows.begin(), windows.end());
    rank(checked);
  }
  lap(timings.window_search);
  ViewAlignResult best = kept ? std::move(*kept) : ViewAlignResult();
  // Timed out only when the deadline was hit: a search may find fewer rotations than it
  // asked for (a view of few distinct normals).
  best.converged = in_time;
  best.scale = scale;
  best.windows = windows_checked;
  best.correlation =
      views.correlation.evaluate(Eigen::Matrix3d(best.T_current_reference.topLeftCorner<3, 3>()))
          .value;
  for (const Hypothesis& h : checked) {
    best.hypotheses.emplace_back(model.transform_of(h.pose), h.support);
  }
  detail::views::judge(views, best, checked, !in_time);
  lap(timings.verdict);
  timings.total = detail::seconds_since(started);
  best.timings = timings;
  return best;
}

}  // namespace spectral_vs
