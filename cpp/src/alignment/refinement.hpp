#pragma once
// The refinement stage of both modes (docs/architecture.md): from a hypothesis, Algorithm
// 1 (the paper's loop, algorithm1.hpp), its end kept by keeps_algorithm1, then the
// two-stage point-to-plane ICP, its pose kept by keeps_icp. The modes differ in data only:
// the EGI correlation and the translation source the loop runs on, the score a pose is
// kept by (align: the screen's fitness; align_views: the support's score), and what the
// ICP pairs with. align() configures it here (refine_hypothesis, SceneThenWindow,
// refine_with_icp) and, beyond the paper, sweeps and polishes between the two steps
// (polish.hpp); align_views() configures it in view_aligner.cpp.

#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/algorithm1.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/stages.hpp"

#include <functional>
#include <optional>

namespace spectral_vs::detail {

/// A mode's score of a pose of its moving model, which Algorithm 1's step keeps by.
using PoseScore = std::function<double(const Pose&)>;
/// The same score of a pose given as T_scene_model, which the ICP's step keeps by.
using TransformScore = std::function<double(const Transform&)>;

/// The refinement's first step, both modes': Algorithm 1 from `start`, which scores
/// `start_score`, for at most `max_iterations`. The loop's result (run_algorithm1) with its
/// end's `score` as fitness, unless keeps_algorithm1 keeps the start: then the start, which
/// claims no iterations (stop_reason kept_start, not converged, the correlation at the
/// start, no translation peak).
AlignResult algorithm1_step(const Algorithm1Problem& loop, TranslationSource& source,
                            int max_iterations, const Pose& start, double start_score,
                            const PoseScore& score);

/// The ICP's outcome, scored by `score`, replaces result's pose (T_scene_model, fitness,
/// icp_iterations) when it took a step and keeps_icp keeps it.
void take_icp(const IcpOutcome& icp, const TransformScore& score, AlignResult& result);

/// The refinement's last step, both modes': the two-stage ICP (refine_in_two_stages;
/// `fine`: its tighter second stage too) from result.T_scene_model against `scene` (a
/// PointCloud: neighbour grids made per stage around the model; an IcpScene: made once),
/// kept by take_icp.
template <class Scene>
void icp_step(const PointCloud& model, const Scene& scene, double voxel_size,
              const IcpSettings& settings, bool fine, const TransformScore& score,
              AlignResult& result) {
  take_icp(refine_in_two_stages(model, scene, result.T_scene_model, voxel_size, settings, fine),
           score, result);
}

// --- align()'s configuration --------------------------------------------------------------

// The paper's translation source: the grid over the whole scene until a step fits in a
// window (the model is near), then a window that follows the model. A bounded grid
// (max_translation) is kept throughout.
class SceneThenWindow : public TranslationSource {
 public:
  SceneThenWindow(const Problem& problem, const LocalParams& local, SceneTranslation& scene,
                  WindowCache& windows)
      : problem_(problem),
        bounded_(local.max_translation != 0.0),
        scene_(scene),
        windows_(windows) {}

  TranslationEstimate estimate(const Points& moved) override {
    return window_ ? window_->estimate(moved) : scene_.estimate(moved);
  }
  double translation_cost() const override {
    return window_ ? window_->translation_cost() : scene_.translation_cost();
  }
  void follow(const Eigen::Vector3d& centre, const Eigen::Vector3d& step, bool more) override {
    if (window_) {
      window_->follow(centre);
    } else if (!bounded_ && more && step.norm() < 0.5 * problem_.margin) {
      window_ = &windows_.at(problem_, centre);  // near: go local
    }
  }
  std::optional<Eigen::Vector3i> window_dims() const override {
    return window_ ? std::optional<Eigen::Vector3i>(window_->dims()) : std::nullopt;
  }

 private:
  const Problem& problem_;
  const bool bounded_;  // local.max_translation: the grid bounded around the start throughout
  SceneTranslation& scene_;
  WindowCache& windows_;
  TranslationWindow* window_ = nullptr;  // once the model is near
};

/// Algorithm 1 (eq. 16-17) from `pose` with the translation from `source`, and the
/// fitness of where it ends.
AlignResult algorithm1_with_fitness(const Problem& problem, const LocalParams& local,
                                    So3Correlation& correlation,
                                    const ShCoefficients& scene_coefficients, Pose pose,
                                    TranslationSource& source, int max_iterations);

/// Algorithm 1 (`local`) from a hypothesis for refinement.refinement_iterations, in a
/// window of the scene around it, on the EGI of the scene inside that window; the
/// hypothesis itself when it is fitter.
AlignResult refine_hypothesis(const Problem& problem, const RefinementParams& refinement,
                              const LocalParams& local, So3Correlation& scene_correlation,
                              const ShCoefficients& scene_coefficients,
                              const Hypothesis& hypothesis, WindowCache& windows);

/// align()'s ICP step (AlignParams::refinement.icp_refinement, or LocalParams::icp after
/// the paper's mode, `after_guess`: local_icp_settings) against the whole scene, kept by
/// the screen's fitness.
void refine_with_icp(const Problem& problem, const PointCloud& model, const PointCloud& scene,
                     AlignResult& result, bool after_guess = false);

/// `a` is a better result than `b`: fitter, or as fit and better correlated.
bool better(const AlignResult& a, const AlignResult& b);

}  // namespace spectral_vs::detail
