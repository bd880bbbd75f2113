#pragma once
// Internal to align() and align_views(): a pose to refine, and the one way both make them
// from an SO(3) search (docs/architecture.md): each rotation refined on the EGI
// correlation, placed by phase correlation from where it starts, then scored by the
// caller's verification.

#include <spectral_vs/alignment/view_aligner.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/moving_model.hpp"
#include "alignment/scene_map.hpp"

#include <algorithm>
#include <chrono>
#include <vector>

namespace spectral_vs::detail {

/// A pose to refine: where the search found it (its rank in the SO(3) search, -1 for a
/// given pose: the initial guess, the prior), and how the verification scored it.
struct Hypothesis {
  int index = 0;
  Pose pose;
  /// What ranks it, in [0, 1]: align()'s fitness screen, align_views()' support score.
  double fitness = 0.0;
  /// align_views(): the check against the current view's depth image (fitness is its
  /// score); unset in align().
  ViewSupport support;
};

/// Fittest first; equals keep their order.
inline void rank(std::vector<Hypothesis>& hypotheses) {
  std::stable_sort(hypotheses.begin(), hypotheses.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.fitness > b.fitness; });
}

/// The rotations of an SO(3) search, in its order, each refined on `correlation` and
/// placed from `start_offset` (the model's offset before the shift) by the shift
/// `place(points)` returns for the model's points there (metres: a phase correlation,
/// SceneTranslation::estimate), then scored by `score(Hypothesis&)`. The best-correlated
/// come first: past `deadline` the rest are left out (never the first).
template <typename Place, typename Score>
std::vector<Hypothesis> placed_rotations(const std::vector<RotationCandidate>& candidates,
                                         So3Correlation& correlation,
                                         const RotationRefineParams& refine, MovingModel& model,
                                         const Eigen::Vector3d& start_offset,
                                         std::chrono::steady_clock::time_point deadline,
                                         Place&& place, Score&& score) {
  std::vector<Hypothesis> placed;
  for (std::size_t h = 0; h < candidates.size(); ++h) {
    if (h > 0 && std::chrono::steady_clock::now() > deadline) break;
    Hypothesis hypothesis;
    hypothesis.index = int(h);
    hypothesis.pose.R = refine_rotation(correlation, candidates[h].R, refine).R;
    hypothesis.pose.offset = start_offset;
    hypothesis.pose.offset += place(model.move(hypothesis.pose));
    score(hypothesis);
    placed.push_back(hypothesis);
  }
  return placed;
}

}  // namespace spectral_vs::detail
