#pragma once
// Internal to the aligner: the one loop of Algorithm 1 (paper, section II-D, eq. 16-17),
// which align(), align_views() and ModelAligner all run. What varies between them is
// where each iteration's translation comes from: a grid over the whole scene, a window
// of it that follows the model, or a grid bounded around the model's start.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "alignment/moving_model.hpp"

#include <Eigen/Core>
#include <chrono>
#include <optional>

namespace spectral_vs::detail {

/// The translation step of Algorithm 1: the phase correlation of the moved model with
/// the scene on some grid (eq. 5-9).
class TranslationSource {
 public:
  virtual ~TranslationSource() = default;
  /// The shift (metres) that moves `moved` (model points in the scene) onto the scene.
  virtual TranslationEstimate estimate(const Points& moved) = 0;
  /// J_t of eq. (9) of the last estimate, voxel units.
  virtual double translation_cost() const = 0;
  /// Told after an iteration that did not stop the loop: the model's centre now, the
  /// translation step just taken (metres) and whether another iteration may follow. A
  /// window re-centres itself here; the paper's whole-scene grid hands over to a window.
  virtual void follow(const Eigen::Vector3d& centre, const Eigen::Vector3d& step, bool more) {}
  /// The voxels of the grid the loop ended on when it is a window of the scene.
  virtual std::optional<Eigen::Vector3i> window_dims() const { return std::nullopt; }
};

/// Where the time of the loop went, seconds (added to, not reset).
struct Algorithm1Timings {
  double rotation = 0.0;     ///< Evaluations of the EGI correlation and the rotation steps.
  double translation = 0.0;  ///< Moving the model and the phase correlation.
  double records = 0.0;      ///< J_t and J_r of the iteration records.
};

/// What one run of the loop ascends: the EGI correlation of scene and model, with their
/// coefficients for J_r, and the model that it moves.
struct Algorithm1Problem {
  So3Correlation& correlation;
  const ShCoefficients& scene_coefficients;
  const ShCoefficients& model_coefficients;
  MovingModel& model;
  const LocalParams& local;  // the gains, the step law, the tolerance
  double voxel_size;         // metres: the unit of the translation step's record
  int bandwidth;             // of the EGIs, for J_r
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
  bool costs = true;  ///< J_t and J_r in the history's records; false: left 0 (not read)
};

/// The rotation of one iteration from the correlation at the current rotation: the
/// Newton step (where the Hessian is negative definite) or the gradient law, times
/// rotation_gain, capped at max_rotation_step; a rotation vector, radians.
Eigen::Vector3d rotation_step(const CorrelationValue& c, const LocalParams& params);

/// `step` (radians) cut to +-max_rotation_step; `capped` tells whether it was.
double capped_step(double step, const LocalParams& params, bool* capped);

/// Algorithm 1 from `pose` until the stop rule of eq. (17), `max_iterations` or the
/// deadline; `pose` is left where it ended. Returns that pose, the history, converged, stop_reason,
/// the final correlation and translation peak, and the window's dims when it ended on one; the
/// fitness is the caller's to score.
AlignResult run_algorithm1(const Algorithm1Problem& problem, Pose& pose, TranslationSource& source,
                           int max_iterations, Algorithm1Timings* timings = nullptr);

/// The one rule of both modes' refinement from a hypothesis: where Algorithm 1 ended,
/// scored `end_score`, replaces its start, scored `start_score`, unless the start scores
/// strictly higher. Algorithm 1 can walk off a right start: in clutter the window's EGI
/// holds other objects' normals, and the EGI correlation of two partial views peaks 10-20
/// degrees off the truth. The score is the caller's (align: the screen's fitness;
/// align_views: the support's score).
inline bool keeps_algorithm1(double end_score, double start_score) {
  return !(start_score > end_score);
}

}  // namespace spectral_vs::detail
