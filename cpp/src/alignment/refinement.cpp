// The refinement stage: its two steps, both modes', and align()'s configuration of them.
#include "alignment/refinement.hpp"

#include "alignment/align_detail.hpp"
#include "alignment/point_sets.hpp"

#include <stdexcept>
#include <vector>

namespace spectral_vs::detail {

namespace {

// The EGI of the scene points in a window: in clutter, the object's own normals
// rather than the whole scene's.
std::optional<ShCoefficients> window_coefficients(const SceneMap& scene,
                                                  const Eigen::Vector3d& centre, double half_width,
                                                  const SceneParams& scale) {
  const Eigen::AlignedBox3d box(centre - Eigen::Vector3d::Constant(half_width),
                                centre + Eigen::Vector3d::Constant(half_width));
  const std::vector<Eigen::Index> rows = scene.points_in(box);
  if (rows.size() < 3) return std::nullopt;
  return egi_coefficients(detail::rows_of(scene.cloud().normals(), rows), scale.bandwidth,
                          scale.egi_method);
}

}  // namespace

TranslationWindow& WindowCache::at(const Problem& problem, const Eigen::Vector3d& centre) {
  if (window_) {
    window_->place(centre);
  } else {
    window_.emplace(problem.scene, problem.model.reach(), problem.margin, centre,
                    problem.scale.voxel_size, problem.scale.occupancy, problem.phase,
                    problem.phase.limits);
  }
  return *window_;
}

AlignResult algorithm1_with_fitness(const Problem& problem, const LocalParams& local,
                                    So3Correlation& correlation,
                                    const ShCoefficients& scene_coefficients, Pose pose,
                                    TranslationSource& source, int max_iterations) {
  const Algorithm1Problem loop{
      correlation, scene_coefficients,       problem.model_coefficients, problem.model,
      local,       problem.scale.voxel_size, problem.scale.bandwidth,    problem.deadline};
  AlignResult result = run_algorithm1(loop, pose, source, max_iterations);
  result.fitness = problem.model.fitness(problem.verifier, pose, problem.scale.voxel_size);
  return result;
}

AlignResult refine_hypothesis(const Problem& problem, const RefinementParams& refinement,
                              const LocalParams& local, So3Correlation& scene_correlation,
                              const ShCoefficients& scene_coefficients,
                              const Hypothesis& hypothesis, WindowCache& windows) {
  const double half_width = problem.model.reach() + problem.margin;
  const auto window_egi = window_coefficients(problem.scene, problem.model.centre(hypothesis.pose),
                                              half_width, problem.scale);
  std::optional<So3Correlation> local_correlation;
  if (window_egi) {
    try {
      local_correlation.emplace(*window_egi, problem.model_coefficients, problem.scale.bandwidth,
                                true);
    } catch (const std::invalid_argument&) {
      // A window whose normals have no structure (a uniform EGI): keep the scene's.
    }
  }
  const Algorithm1Problem loop{local_correlation ? *local_correlation : scene_correlation,
                               local_correlation ? *window_egi : scene_coefficients,
                               problem.model_coefficients,
                               problem.model,
                               local,
                               problem.scale.voxel_size,
                               problem.scale.bandwidth,
                               problem.deadline};
  const PoseScore fitness = [&](const Pose& pose) {
    return problem.model.fitness(problem.verifier, pose, problem.scale.voxel_size);
  };
  AlignResult result = algorithm1_step(
      loop, windows.at(problem, problem.model.centre(hypothesis.pose)),
      refinement.refinement_iterations, hypothesis.pose, fitness(hypothesis.pose), fitness);
  result.hypothesis = hypothesis.index;
  return result;
}

void refine_with_icp(const Problem& problem, const PointCloud& model, const PointCloud& scene,
                     AlignResult& result, bool after_guess) {
  IcpSettings settings;
  settings.viewpoint = problem.viewpoint;
  if (after_guess) settings = local_icp_settings(problem.viewpoint);
  const double voxel_size = problem.scale.voxel_size;
  // The fine stage only for a densely sampled model (kIcpFineDistance).
  icp_step(
      model, scene, voxel_size, settings, problem.dense_model,
      [&](const Transform& T) {
        return problem.model.fitness(problem.verifier, problem.model.pose_of(T), voxel_size);
      },
      result);
}

AlignResult algorithm1_step(const Algorithm1Problem& loop, TranslationSource& source,
                            int max_iterations, const Pose& start, double start_score,
                            const PoseScore& score) {
  Pose pose = start;
  AlignResult result = run_algorithm1(loop, pose, source, max_iterations);
  result.fitness = score(pose);
  if (keeps_algorithm1(result.fitness, start_score)) return result;
  // The returned pose is then not where this run ended: it claims no iterations.
  result.T_scene_model = loop.model.transform_of(start);
  result.fitness = start_score;
  claim_no_run(result, loop.correlation.evaluate(start.R).value, AlignStopReason::kept_start);
  return result;
}

void take_icp(const IcpOutcome& icp, const TransformScore& score, AlignResult& result) {
  if (icp.iterations == 0) return;
  const double icp_score = score(icp.T_scene_model);
  if (!keeps_icp(icp_score, result.fitness)) return;
  result.T_scene_model = icp.T_scene_model;
  result.fitness = icp_score;
  result.icp_iterations = icp.iterations;
}

bool better(const AlignResult& a, const AlignResult& b) {
  if (a.fitness != b.fitness) return a.fitness > b.fitness;
  return a.correlation > b.correlation;
}

}  // namespace spectral_vs::detail
