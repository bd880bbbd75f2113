#pragma once
/// @file phase_correlation.hpp
/// Translation by 3D phase correlation of voxel grids (paper, section II-B, eq. 5-9).

#include <spectral_vs/representation/voxel_grid.hpp>

#include <Eigen/Core>
#include <memory>

namespace spectral_vs {

/// Settings of the phase correlation.
struct PhaseCorrelationParams {
  /// Refine the integer peak by a least-squares fit of the cross-power spectrum's
  /// phase plane over low frequencies (|f| < subvoxel_band cycles per voxel).
  bool subvoxel = true;
  double subvoxel_band = 0.25;  ///< Frequency band of the fit, cycles per voxel, in (0, 0.5].
  int threads = 1;              ///< FFTW threads, in [1, 256].
  /// Grids over limits.max_voxels are refused before any buffer is allocated. The
  /// transforms take about 20 bytes per voxel (kPhaseCorrelationBytesPerVoxel).
  GridLimits limits = {};
};

/// Memory of a PhaseCorrelation per voxel of its grid, bytes (about): the float input and
/// output and three complex half spectra.
inline constexpr double kPhaseCorrelationBytesPerVoxel = 20.0;

/// Translation that moves the moving grid onto the target: target(x) ~ moving(x - shift).
struct TranslationEstimate {
  Eigen::Vector3d shift_voxels = Eigen::Vector3d::Zero();  ///< Refined shift, voxels.
  Eigen::Vector3i peak_voxels = Eigen::Vector3i::Zero();   ///< Integer argmax, voxels (unfolded).
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();         ///< shift_voxels * resolution, metres.
  /// Height of the normalised correlation at the integer peak, in [0, 1]: 1 for two
  /// grids that are exact shifts of each other, near 0 when nothing matches.
  double peak = 0.0;
};

/// Phase correlation against a fixed target on a fixed grid. Owns the FFTW plans
/// (real-to-complex and back, made once) and the target's spectrum, so each
/// `estimate` costs one forward and one inverse FFT. Not safe to call from two
/// threads at once; distinct objects are independent.
class PhaseCorrelation {
 public:
  /// @throws std::invalid_argument for an invalid spec or params, or a grid over
  ///         params.limits (before allocating).
  explicit PhaseCorrelation(const GridSpec& spec, const PhaseCorrelationParams& params = {});
  ~PhaseCorrelation();
  PhaseCorrelation(PhaseCorrelation&&) noexcept;
  PhaseCorrelation& operator=(PhaseCorrelation&&) noexcept;

  /// Caches the spectrum of `target`. @throws if its spec differs or it is empty.
  void set_target(const VoxelGrid& target);
  bool has_target() const;

  /// The shift of `moving` onto the cached target. Only shifts for which the two
  /// grids' occupied boxes overlap are considered, so the wrap-around of the
  /// circular correlation is unfolded without ambiguity.
  /// @throws std::invalid_argument if no target is set, the spec differs, or
  ///         `moving` is empty.
  TranslationEstimate estimate(const VoxelGrid& moving);

  /// The same with the shift also bounded by |shift| <= max_shift_voxels (per axis).
  /// A local search in a window needs a grid only as large as the window plus the
  /// bound, not the window plus the moving cloud, to be free of wrap-around.
  TranslationEstimate estimate(const VoxelGrid& moving, const Eigen::Vector3i& max_shift_voxels);

  const GridSpec& spec() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// One-shot phase correlation of two grids on the same spec (plans made per call).
TranslationEstimate phase_correlation(const VoxelGrid& moving, const VoxelGrid& target,
                                      const PhaseCorrelationParams& params = {});

/// Translation cost J_t of eq. (9): 0.5 * sum_x (target(x) - moving(x - shift))^2 for
/// an integer `shift` in voxels; voxels shifted out of the grid count as empty.
double translation_cost(const VoxelGrid& moving, const VoxelGrid& target,
                        const Eigen::Vector3i& shift);

/// The same J_t with the target's energy sum_x target(x)^2 given, for a caller that
/// scores many moving grids against one target: the sum then runs over the moving
/// grid's occupied box only.
double translation_cost(const VoxelGrid& moving, const VoxelGrid& target,
                        const Eigen::Vector3i& shift, double target_energy);

/// sum_x grid(x)^2.
double grid_energy(const VoxelGrid& grid);

}  // namespace spectral_vs
