#pragma once
/// @file so3_search.hpp
/// Global rotation search (beyond the paper, whose gradient ascent from the identity
/// has a basin of a few tens of degrees) and the local refinement of its candidates.

#include <spectral_vs/rotation/so3_correlation.hpp>

#include <Eigen/Core>
#include <vector>

namespace spectral_vs {

/// A local maximum of C over the Euler grid.
struct RotationCandidate {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< R_target_model at the grid node
  double correlation = 0.0;                         ///< C(R), same normalisation as the search
};

/// Settings of so3_search.
struct So3SearchParams {
  int candidates = 8;  ///< k: at most this many local maxima are returned, >= 1
  int threads = 1;     ///< worker threads over the beta planes of the grid, in [1, 256]; at most
                       ///< 2B run, and no more than 256 MB of their Wigner matrices allow
                       ///< (11 at B = 128); results do not depend on it
  bool normalised = true;         ///< correlate as So3Correlation(..., normalised)
  double separation_cells = 1.5;  ///< a maximum within this many grid steps (pi / B rad each)
                                  ///< of a better one is dropped (duplicates near beta = 0, pi)
};

/// C over all of SO(3) on the (2B)^3 ZYZ Euler grid alpha_i = pi i / B,
/// beta_j = pi (2j+1) / (4B), gamma_k = pi k / B, by one 2D inverse FFT over
/// (alpha, gamma) per beta (FFTW, double precision), then the k best local maxima
/// (26-neighbourhood, periodic in alpha and gamma), best first. Cost O(B^4) with a small
/// constant; the grid spacing pi / B (11 degrees at B = 16) bounds the error of a
/// candidate before refinement.
///
/// FFTW's planner is not thread-safe: plans of the double-precision library are made
/// once per bandwidth under a mutex private to this library (the single-precision
/// library used by the translation has its own). An application that plans with FFTW
/// double itself, concurrently, must serialise with its own calls.
/// @throws std::invalid_argument for bad coefficients (as So3Correlation) or params.
std::vector<RotationCandidate> so3_search(const ShCoefficients& target, const ShCoefficients& model,
                                          int bandwidth, const So3SearchParams& params = {});

/// Settings of refine_rotation.
struct RotationRefineParams {
  double gain = 0.05;                ///< initial gradient step: R <- R exp(gain hat(gradient)),
                                     ///< rad per unit of gradient (C per rad); halved whenever a
                                     ///< step lowers C or reverses the gradient (an overshoot)
  int max_iterations = 100;          ///< iterations (evaluations with accepted steps), <= 10^4
  double gradient_tolerance = 1e-6;  ///< converged when |gradient| < this times
                                     ///< So3Correlation::scale(), per rad
  bool newton = true;                ///< step -H^-1 gradient when the Hessian is negative definite
  double max_step = 0.25;            ///< largest rotation of one step, rad
};

/// The outcome of refine_rotation.
struct RotationRefineResult {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< the refined rotation
  double correlation = 0.0;                         ///< C(R)
  int iterations = 0;                               ///< iterations run
  bool converged = false;                           ///< |gradient| < gradient_tolerance
};

/// Local ascent of C from R0: Newton steps where C is locally concave, else gradient
/// steps of the paper's update rule (eq. 17) with an adaptive gain; a step that does not
/// increase C is halved until it does. Never decreases C. Converges to the local maximum
/// whose basin holds R0: from the identity, that is the paper's controller (basins in
/// docs/rotation.md); from the candidates of so3_search, the global maximum.
/// @throws std::invalid_argument if R0 is not a rotation or params are invalid.
RotationRefineResult refine_rotation(So3Correlation& correlation, const Eigen::Matrix3d& R0,
                                     const RotationRefineParams& params = {});

}  // namespace spectral_vs
