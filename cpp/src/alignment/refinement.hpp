#pragma once
// Internal to align(), its third stage: from each hypothesis, Algorithm 1 (the paper's
// loop, algorithm1.hpp) on the scene around it; then, beyond the paper, the sweep of
// the turns about a flat axis, the polish of the rotation on the voxel overlap, and the
// point-to-plane ICP.

#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/algorithm1.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/stages.hpp"

#include <functional>
#include <optional>

namespace spectral_vs::detail {

// The paper's translation source: the grid over the whole scene until a step fits in a
// window (the model is near), then a window that follows the model. A bounded grid
// (max_translation) is kept throughout.
class SceneThenWindow : public TranslationSource {
 public:
  SceneThenWindow(const Problem& problem, SceneTranslation& scene, WindowCache& windows)
      : problem_(problem), scene_(scene), windows_(windows) {}

  TranslationEstimate estimate(const Points& moved) override {
    return window_ ? window_->estimate(moved) : scene_.estimate(moved);
  }
  double translation_cost() const override {
    return window_ ? window_->translation_cost() : scene_.translation_cost();
  }
  void follow(const Eigen::Vector3d& centre, const Eigen::Vector3d& step, bool more) override {
    if (window_) {
      window_->follow(centre);
    } else if (problem_.params.local.max_translation == 0.0 && more &&
               step.norm() < 0.5 * problem_.margin) {
      window_ = &windows_.at(problem_, centre);  // near: go local
    }
  }
  std::optional<Eigen::Vector3i> window_dims() const override {
    return window_ ? std::optional<Eigen::Vector3i>(window_->dims()) : std::nullopt;
  }

 private:
  const Problem& problem_;
  SceneTranslation& scene_;
  WindowCache& windows_;
  TranslationWindow* window_ = nullptr;  // once the model is near
};

/// Algorithm 1 (eq. 16-17) from `pose` with the translation from `source`, and the
/// fitness of where it ends.
AlignResult algorithm1_with_fitness(const Problem& problem, So3Correlation& correlation,
                                    const ShCoefficients& scene_coefficients, Pose pose,
                                    TranslationSource& source, int max_iterations);

/// Algorithm 1 from a hypothesis, in a window of the scene around it, on the EGI of the
/// scene inside that window; the hypothesis itself when it is fitter.
AlignResult refine_hypothesis(const Problem& problem, So3Correlation& scene_correlation,
                              const ShCoefficients& scene_coefficients,
                              const Hypothesis& hypothesis, WindowCache& windows);

/// The model is dense enough for the voxel overlap of the sweep and the polish.
bool dense_for_polish(const Points& model_points, double voxel_size);

/// The result turned to the best of its turns about the model's flat axis `axis`.
void sweep_result_about(const Problem& problem, WindowCache& windows, AlignResult& result,
                        const Eigen::Vector3d& axis);

/// The result's rotation polished on the voxel overlap (a pattern search).
void polish_result_rotation(const Problem& problem, WindowCache& windows, AlignResult& result);

/// The ICP refinement of a result (AlignParams::refinement.icp_refinement, or
/// LocalParams::icp when `local`: local_icp_settings), against the whole scene; kept
/// unless it loses fitness.
void refine_with_icp(const Problem& problem, const PointCloud& model, const PointCloud& scene,
                     AlignResult& result, bool local = false);

/// The two-stage point-to-plane ICP of `result`'s pose (`fine`: the second, tighter stage
/// too), kept unless its fitness (`fitness_of` a pose) is more than a slide off the object
/// below the result's: the one rule of both modes' ICP.
void refine_with_icp(const PointCloud& model, const PointCloud& scene, double voxel_size,
                     const IcpSettings& settings, bool fine,
                     const std::function<double(const Transform&)>& fitness_of,
                     AlignResult& result);

/// `a` is a better result than `b`: fitter, or as fit and better correlated.
bool better(const AlignResult& a, const AlignResult& b);

}  // namespace spectral_vs::detail
