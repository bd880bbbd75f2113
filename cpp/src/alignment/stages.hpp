#pragma once
// Internal to align(): what its stages pass between them. The stages, in the order
// align() runs them (docs/architecture.md):
//   scene_preparation  the support plane, the connected parts, the single-view check;
//   hypotheses         the SO(3) search (global or per part), placement, ranking;
//   refinement         Algorithm 1 from each hypothesis and the ICP, each kept by its rule
//                      (refinement.hpp, both modes'); between them the flat-axis sweep
//                      and the polish (polish.hpp);
//   verifier           the one verification: the screen that ranks poses (fitness)
//                      and the check behind the verdict (confidence, inliers);
//   alternatives       the other poses the scene supports about as well;
//   reselect           an alternative replaces the pose: one far more confident, one
//                      that explains its object's part whole (part_coverage), or one
//                      as confident with more inliers; in clutter, a resting pose;
//   verdict            the one of both modes (judge_pose, verdict_detail.hpp).

#include <spectral_vs/alignment/aligner.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/hypothesis.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verifier.hpp"

#include <spectral_vs/translation/phase_correlation.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <vector>

namespace spectral_vs::detail {

using Clock = std::chrono::steady_clock;

// A model EGI whose smallest curvature is under this share of its largest has a flat
// axis (measured at B = 16: mug 0.015, duck 0.08; bunny 0.44, box 0.31, others 0.57-0.8).
constexpr double kFlatAxisRatio = 0.1;
constexpr double kFlatAxisStep = 15.0 * M_PI / 180.0;  // turns tried about the flat axis

// The moving model scored by the verification's screen: against what its sensor saw,
// with depths within `tolerance` metres, when the scene is one view.
class ScoredModel : public MovingModel {
 public:
  using MovingModel::MovingModel;

  double fitness(const Verifier& verifier, const Pose& pose, double tolerance) {
    const Points& normals = turned_normals(pose);
    return verifier.fitness(move(pose), normals, tolerance);
  }
};

// What every stage works on: the scene, the model, its EGI, the scale they are measured
// in and the translation grids' settings. A stage's own settings group is not here: each
// stage takes the group it reads as an argument (docs/architecture.md, the stage table).
struct Problem {
  const SceneMap& scene;
  const Verifier& verifier;  // scores poses against the whole scene (its sensor's view)
  ScoredModel& model;
  const ShCoefficients& model_coefficients;
  const SceneParams& scale;      // the unit of every stage: voxel, bandwidth, EGI, occupancy
  PhaseCorrelationParams phase;  // of the translation grids: local.subvoxel, threads, limits
  int threads;                   // of the SO(3) searches
  double margin;                 // of a window around the model, metres
  Clock::time_point deadline = Clock::time_point::max();    // of AlignParams::max_seconds
  std::optional<Eigen::Vector3d> flat_axis = std::nullopt;  // of the model's EGI, if it has one
  bool dense_model = true;  // at least kPolishMinDensity points per occupied voxel
  std::optional<Eigen::Vector3d> viewpoint = std::nullopt;  // the sensor of a single view
  AlignTimings* timings = nullptr;                          // where the stages add their time
};

// Adds the wall-clock seconds of its scope to one field of `timings` (none: nothing).
class StageTimer {
 public:
  StageTimer(AlignTimings* timings, double AlignTimings::*field)
      : into_(timings ? &(timings->*field) : nullptr), start_(Clock::now()) {}
  ~StageTimer() {
    if (into_) *into_ += seconds_since(start_);
  }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  double* into_;
  Clock::time_point start_;
};

/// `result` now holds a pose that no run of Algorithm 1 ended at (its start kept, an
/// alternative reselected): it claims no iterations, no history, no translation peak, is
/// not converged, stops for `reason`, and reports the EGI `correlation` at that pose.
inline void claim_no_run(AlignResult& result, double correlation, AlignStopReason reason) {
  result.correlation = correlation;
  result.translation_peak = 0.0;
  result.converged = false;
  result.stop_reason = reason;
  result.iterations = 0;
  result.history.clear();
}

/// The time limit of AlignParams::max_seconds has passed.
inline bool expired(const Problem& problem) { return Clock::now() > problem.deadline; }

/// A guess's neighbourhood (GlobalSearchParams::guess_angle_deg, guess_distance) is set.
bool has_neighbourhood(const GlobalSearchParams& search);

/// The window's margin around the model (search.window_margin, or from the voxels: the
/// alignment's `voxel_size` and the search's `search_voxel`), metres.
double window_margin(const GlobalSearchParams& search, double voxel_size, double search_voxel);

/// The translation window of one alignment, made at its first use and moved to each place
/// a stage works at (a part's placement, Algorithm 1 from a hypothesis, the sweep, the
/// polish), so that its FFT plans are made once: the cache the stages share.
class WindowCache {
 public:
  /// The window, placed at `centre`.
  TranslationWindow& at(const Problem& problem, const Eigen::Vector3d& centre);

 private:
  std::optional<TranslationWindow> window_;
};

}  // namespace spectral_vs::detail
