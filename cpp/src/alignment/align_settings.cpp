// The checks and derived values of AlignParams that every stage of align() reads: each
// group checked on its own.
#include "alignment/align_detail.hpp"
#include "alignment/stages.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

void check(const SceneParams& p) {
  if (!(p.voxel_size >= 0.0 && std::isfinite(p.voxel_size))) {
    fail("voxel_size must be >= 0 metres (0: derived from the model), got ", p.voxel_size);
  }
  if (p.bandwidth < 2 || p.bandwidth > kMaxAlignBandwidth) {
    fail("bandwidth must be in [2, ", kMaxAlignBandwidth, "], got ", p.bandwidth);
  }
  if (!p.sensor_origin.allFinite()) fail("sensor_origin must be finite");
}

void check(const LocalParams& p) {
  if (!(p.translation_gain > 0.0 && p.translation_gain <= 1.0)) {
    fail("translation_gain must be in (0, 1], got ", p.translation_gain);
  }
  detail::require_positive_finite(p.rotation_gain, "rotation_gain");
  if (p.rotation_step == RotationStep::newton && p.rotation_gain > 1.0) {
    fail("rotation_gain must be in (0, 1] with Newton steps, got ", p.rotation_gain);
  }
  detail::require_positive_finite(p.max_rotation_step, "max_rotation_step");
  detail::require_positive_finite(p.tolerance, "tolerance");
  if (p.max_iterations < 1 || p.max_iterations > kMaxAlignIterations) {
    fail("max_iterations must be in [1, ", kMaxAlignIterations, "], got ", p.max_iterations);
  }
  if (!(p.max_translation >= 0.0 && std::isfinite(p.max_translation))) {
    fail("max_translation must be >= 0 metres (0: unbounded), got ", p.max_translation);
  }
}

void check(const GlobalSearchParams& p) {
  if (p.hypotheses < 1) fail("hypotheses must be >= 1, got ", p.hypotheses);
  if (p.refinements < 1 || p.refinements > p.hypotheses) {
    fail("refinements must be in [1, hypotheses = ", p.hypotheses, "], got ", p.refinements);
  }
  if (!(p.search_voxel_size >= 0.0 && std::isfinite(p.search_voxel_size))) {
    fail("search_voxel_size must be >= 0 metres (0: automatic), got ", p.search_voxel_size);
  }
  if (!(p.window_margin >= 0.0 && std::isfinite(p.window_margin))) {
    fail("window_margin must be >= 0 metres (0: automatic), got ", p.window_margin);
  }
  if (!(p.guess_angle_deg >= 0.0 && p.guess_angle_deg <= 180.0)) {
    fail("guess_angle_deg must be in [0, 180] degrees (0: no limit), got ", p.guess_angle_deg);
  }
  if (p.max_parts < 1) fail("max_parts must be >= 1, got ", p.max_parts);
  if (!(p.guess_distance >= 0.0 && std::isfinite(p.guess_distance))) {
    fail("guess_distance must be >= 0 metres (0: no limit), got ", p.guess_distance);
  }
}

void check(const RefinementParams& p) {
  if (p.refinement_iterations < 1 || p.refinement_iterations > kMaxAlignIterations) {
    fail("refinement_iterations must be in [1, ", kMaxAlignIterations, "], got ",
         p.refinement_iterations);
  }
}

void check(const VerificationParams& p) {
  if (p.max_alternatives < 0 || p.max_alternatives > 64) {
    fail("max_alternatives must be in [0, 64], got ", p.max_alternatives);
  }
  if (!(p.reselect_margin >= 0.0 && p.reselect_margin <= 1.0)) {
    fail("reselect_margin must be in [0, 1] (1: never reselect), got ", p.reselect_margin);
  }
}

}  // namespace

void check_align_params(const AlignParams& p) {
  check(p.scene);
  check(p.local);
  check(p.search);
  check(p.refinement);
  check(p.verification);
  check_grid_limits(p.limits);
  if (p.threads < 1 || p.threads > 256) fail("threads must be in [1, 256], got ", p.threads);
  if (!(p.max_seconds >= 0.0 && std::isfinite(p.max_seconds))) {
    fail("max_seconds must be >= 0 seconds (0: no limit), got ", p.max_seconds);
  }
  require_rigid_transform(p.initial_guess, "initial_guess");
}

bool has_neighbourhood(const GlobalSearchParams& search) {
  return search.guess_angle_deg > 0.0 || search.guess_distance > 0.0;
}

double window_margin(const GlobalSearchParams& search, double voxel_size, double search_voxel) {
  if (search.window_margin > 0.0) return search.window_margin;
  return std::max(5.0 * voxel_size, 2.5 * search_voxel);
}

std::chrono::steady_clock::time_point deadline_of(double max_seconds,
                                                  std::chrono::steady_clock::time_point start) {
  using Clock = std::chrono::steady_clock;
  if (max_seconds == 0.0) return Clock::time_point::max();
  const std::chrono::duration<double> budget(std::min(max_seconds, 1e9));  // no overflow
  return start + std::chrono::duration_cast<Clock::duration>(budget);
}

PhaseCorrelationParams phase_params(const LocalParams& local, int threads,
                                    const GridLimits& limits) {
  PhaseCorrelationParams p;
  p.subvoxel = local.subvoxel;
  p.threads = threads;
  p.limits = limits;
  return p;
}

}  // namespace spectral_vs::detail
