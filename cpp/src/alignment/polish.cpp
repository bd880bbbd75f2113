// align()'s own refinement, beyond the paper: the sweep of the turns about a flat axis
// and the polish of the rotation on the voxel overlap, both in a window of the scene.
#include "alignment/polish.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace spectral_vs::detail {

namespace {

// The rotation steps of the final polish, radians: 4 down to 1/4 degree.
constexpr double kPolishFirstStep = 4.0 * M_PI / 180.0;
constexpr double kPolishLastStep = 0.25 * M_PI / 180.0;
constexpr int kPolishFirstStepRounds = 5;  // at most 20 degrees walked at the first step
constexpr double kPolishMinDensity = 2.0;  // model points per occupied voxel

// Re-places `trial`'s translation by phase correlation in the window; its voxel overlap.
double placed_overlap(const Problem& problem, TranslationWindow& window, Pose& trial,
                      int& evaluations) {
  trial.offset += window.estimate(problem.model.move(trial)).shift;
  ++evaluations;
  return window.overlap(problem.model.move(trial));
}

// Beyond the paper: with noisy normals the EGI correlation peaks about a degree from the
// truth, and it cannot see small asymmetric parts (a mug's handle). The 3D voxel
// correlation sees the whole shape: the rotation is polished for the best overlap of the
// model's voxels with the window's, the translation re-placed by phase correlation at
// each trial. Per
// step size (4 down to 1/4 degree), trials at +-step about each model axis give a
// parabola per axis, whose vertex is tried as one combined step; the best trial wins.
Pose polish_pattern(const Problem& problem, TranslationWindow& window, Pose pose,
                    int& evaluations) {
  window.follow(problem.model.centre(pose));
  const auto place = [&](Pose& trial) {
    return placed_overlap(problem, window, trial, evaluations);
  };
  double best = place(pose);
  int rounds_at_first_step = 0;
  for (double step = kPolishFirstStep; step >= kPolishLastStep;) {
    Eigen::Vector3d vertex = Eigen::Vector3d::Zero();
    Pose best_trial = pose;
    double best_trial_peak = best;
    for (int axis = 0; axis < 3; ++axis) {
      double peaks[2];
      for (int side = 0; side < 2; ++side) {
        Pose trial = pose;
        trial.R = pose.R * exp_so3((side ? step : -step) * Eigen::Vector3d::Unit(axis));
        peaks[side] = place(trial);
        if (peaks[side] > best_trial_peak) {
          best_trial_peak = peaks[side];
          best_trial = trial;
        }
      }
      const double curvature = peaks[0] + peaks[1] - 2.0 * best;
      if (curvature < 0.0)
        vertex[axis] = std::clamp(0.5 * step * (peaks[0] - peaks[1]) / curvature, -step, step);
    }
    Pose combined = pose;
    combined.R = pose.R * exp_so3(vertex);
    const double combined_peak = vertex.isZero() ? -1.0 : place(combined);
    if (combined_peak > best_trial_peak) {
      best_trial_peak = combined_peak;
      best_trial = combined;
    }
    const bool improved = best_trial_peak > best;
    if (improved) {
      best = best_trial_peak;
      pose = best_trial;
    }
    // The first step size walks on while it improves (a pose a few steps off, such as a
    // mug turned about its axis); the finer ones refine once each.
    if (!(improved && step == kPolishFirstStep && ++rounds_at_first_step < kPolishFirstStepRounds))
      step *= 0.5;
  }
  return pose;
}

// Points per occupied voxel of the model: below kPolishMinDensity the voxel overlap
// compares two sparse samplings more than two surfaces (a 400-point scan of a bunny at 8
// mm voxels has about one point per voxel), and the polish would only add noise.
double points_per_voxel(const Points& points, double voxel_size) {
  std::vector<std::array<long, 3>> voxels;
  voxels.reserve(std::size_t(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Array3d v = (points.row(i).transpose() / voxel_size).array().floor();
    voxels.push_back({long(v.x()), long(v.y()), long(v.z())});
  }
  std::sort(voxels.begin(), voxels.end());
  const auto distinct = std::unique(voxels.begin(), voxels.end()) - voxels.begin();
  return distinct ? double(points.rows()) / double(distinct) : 0.0;
}

// The turns of the model about its flat axis, every kFlatAxisStep, each placed by phase
// correlation and scored by voxel overlap: the best.
Pose sweep_flat_axis(const Problem& problem, TranslationWindow& window, const Pose& pose,
                     const Eigen::Vector3d& axis, int& evaluations) {
  window.follow(problem.model.centre(pose));
  Pose best = pose;
  double best_overlap = placed_overlap(problem, window, best, evaluations);
  const int turns = static_cast<int>(std::lround(2.0 * M_PI / kFlatAxisStep));
  for (int k = 1; k < turns; ++k) {
    Pose trial = pose;
    trial.R = pose.R * exp_so3(double(k) * kFlatAxisStep * axis);
    const double overlap = placed_overlap(problem, window, trial, evaluations);
    if (overlap > best_overlap) {
      best_overlap = overlap;
      best = trial;
    }
  }
  return best;
}

// The pose of `result` moved by `step` (the flat-axis sweep or the pattern search) in a
// window placed around it; left as it is for a model too sparse for the voxel overlap.
template <typename Step>
void polish_result(const Problem& problem, WindowCache& windows, AlignResult& result, Step step) {
  const Pose start = problem.model.pose_of(result.T_scene_model);
  if (points_per_voxel(problem.model.move(start), problem.scale.voxel_size) < kPolishMinDensity)
    return;
  const Pose polished =
      step(windows.at(problem, problem.model.centre(start)), start, result.polish_evaluations);
  result.T_scene_model = problem.model.transform_of(polished);
  result.fitness = problem.model.fitness(problem.verifier, polished, problem.scale.voxel_size);
}

}  // namespace

bool dense_for_polish(const Points& model_points, double voxel_size) {
  return points_per_voxel(model_points, voxel_size) >= kPolishMinDensity;
}

void sweep_result_about(const Problem& problem, WindowCache& windows, AlignResult& result,
                        const Eigen::Vector3d& axis) {
  polish_result(problem, windows, result, [&](TranslationWindow& w, const Pose& p, int& n) {
    return sweep_flat_axis(problem, w, p, axis, n);
  });
}

void polish_result_rotation(const Problem& problem, WindowCache& windows, AlignResult& result) {
  polish_result(problem, windows, result, [&](TranslationWindow& w, const Pose& p, int& n) {
    return polish_pattern(problem, w, p, n);
  });
}

}  // namespace spectral_vs::detail
