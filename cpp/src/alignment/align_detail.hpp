#pragma once
// Internal to the aligner: the pieces of align() that ModelAligner shares with it.

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include <Eigen/Core>
#include <chrono>
#include <optional>

namespace spectral_vs::detail {

/// The argument checks of align(). @throws std::invalid_argument as align() does.
void check_align_params(const AlignParams& params);

/// The time limit of `max_seconds` from `start` (none for 0).
std::chrono::steady_clock::time_point deadline_of(double max_seconds,
                                                  std::chrono::steady_clock::time_point start);

/// The sensor origin of a scene declared a single view (scene_view = single_view); none
/// otherwise.
std::optional<Eigen::Vector3d> declared_viewpoint(const AlignParams& params);

/// Wall-clock seconds from `start` to now.
inline double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// The phase-correlation settings of the alignment's grids: local.subvoxel, threads, limits.
PhaseCorrelationParams phase_params(const LocalParams& local, int threads,
                                    const GridLimits& limits);
inline PhaseCorrelationParams phase_params(const AlignParams& params) {
  return phase_params(params.local, params.threads, params.limits);
}

}  // namespace spectral_vs::detail
