// Stage of align_views(): refinement. Algorithm 1 from a hypothesis on a grid bounded
// around it, then the point-to-plane ICP; each kept only where it does not lower the
// support.

#include "alignment/algorithm1.hpp"
#include "alignment/align_detail.hpp"
#include "alignment/view_stages.hpp"

namespace spectral_vs::detail::views {

namespace {

// Translation room of Algorithm 1 around each hypothesis, in search voxels: the
// placement is within half a search voxel, the rotation within a few degrees.
constexpr double kRefinementRoom = 2.0;

// The point-to-plane ICP of a refined pose: pairs within a voxel, then within
// kIcpFineDistance of one; kept where it does not lower the support.
void refine_with_icp(const Views& views, ViewAlignResult& result) {
  detail::IcpSettings icp;
  icp.viewpoint = views.params.sensor_origin;
  const detail::IcpOutcome outcome = detail::refine_in_two_stages(
      views.reference, views.fine_scene, result.T_current_reference, views.scale.voxel_size, icp);
  const Transform& T = outcome.T_scene_model;
  const int iterations = outcome.iterations;
  if (iterations == 0) return;
  const ViewSupport icp_support = views.support.of(T, kCoarseTolerance);
  if (keeps_icp(icp_support.score, result.support.score)) {
    result.T_current_reference = T;
    result.support = icp_support;
    result.icp_iterations = iterations;
  }
}

}  // namespace

// Stage: refinement. Algorithm 1 from a hypothesis on a grid bounded around it, then
// the point-to-plane ICP; each kept only where it does not lower the support.
ViewAlignResult refine(const Views& views, const Hypothesis& hypothesis) {
  ViewAlignResult result;
  result.hypothesis = hypothesis.index;
  result.T_current_reference = views.model.transform_of(hypothesis.pose);
  result.support = hypothesis.support;
  Pose pose = hypothesis.pose;
  const Eigen::AlignedBox3d box = points_box(views.model.move(pose));
  // A hypothesis that moved the reference off the current view has nothing to refine on
  // (and its grid, spanning both, could be of any size).
  if (!box.intersects(bounding_box(views.map.cloud()))) return result;
  SceneTranslation grid(views.map, box, kRefinementRoom * views.scale.search_voxel_size,
                        views.scale.voxel_size, views.params.occupancy, views.phase,
                        views.params.limits);
  const detail::Algorithm1Problem loop{views.correlation,
                                       views.current_coefficients,
                                       views.reference_coefficients,
                                       views.model,
                                       views.local,
                                       views.scale.voxel_size,
                                       views.params.bandwidth,
                                       views.deadline,
                                       false};  // its history is not read
  detail::run_algorithm1(loop, pose, grid, views.params.refinement_iterations);
  const Transform refined = views.model.transform_of(pose);
  const ViewSupport refined_support = views.support.of(refined, kCoarseTolerance);
  if (keeps_algorithm1(refined_support.score, result.support.score)) {
    result.T_current_reference = refined;
    result.support = refined_support;
  }
  if (views.params.icp_refinement) refine_with_icp(views, result);
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

}  // namespace spectral_vs::detail::views
