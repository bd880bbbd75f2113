#pragma once
/// @file model_aligner.hpp
/// One model aligned onto many scenes: the model's side of Algorithm 1 prepared once
/// (for visual servoing, where the reference view is registered onto every new view).

#include <spectral_vs/alignment/aligner.hpp>

#include <memory>

namespace spectral_vs {

/// Where the time of the last `ModelAligner::align` went, seconds (wall clock).
struct ModelAlignerTimings {
  double scene_coefficients = 0.0;  ///< The scene's EGI coefficients and the correlation's set-up.
  double scene_map = 0.0;           ///< The verification's set-up: the extent of its voxel
                                    ///< screen (built with the fitness, around the model).
  double translation_grid = 0.0;    ///< The translation grid: its spec, FFT plans when its size
                                    ///< changed, the scene's voxels and spectrum.
  double rotation = 0.0;            ///< Evaluations of the EGI correlation and the rotation steps.
  double translation = 0.0;         ///< The model's voxels and the phase correlation.
  double records = 0.0;             ///< J_t and J_r of the iteration records.
  double fitness = 0.0;             ///< The verification's fitness of the result (its screen
                                    ///< around the model) and check (params.verification).
  double icp = 0.0;                 ///< The ICP after Algorithm 1 (LocalParams::icp).
  double total = 0.0;               ///< The whole call.
};

/// Aligns one model onto many scenes with the same settings: `align(scene)` returns what
/// `spectral_vs::align(model, scene, params)` returns, the same pose to rounding.
///
/// In the local mode (`global_search = false` with `max_translation > 0`: the servo's
/// bounded search) the model's side is prepared once: its centred points, normals, reach
/// and EGI coefficients; and the FFT plans and buffers of the translation grid are kept
/// for the next scene whose grid has the same size (views of one scene from nearby poses
/// mostly do). Per scene only the scene's work remains: its EGI coefficients, its voxels
/// and spectrum, the iterations, and the fitness at the final pose (the same value as
/// align()'s, from a map of the scene only around the model there). In the other modes
/// (global search, or the unbounded translation of the paper) each call runs `align`.
/// Two settings are resolved once, at construction (params() returns them resolved): a
/// voxel_size of 0 is derived from the model (`alignment_voxel_size`), and scene_view
/// 'automatic' becomes 'all_sides' (a tracker checks a view only when it is declared, so
/// that its steps do not switch between the two fitness measures from scene to scene).
///
/// Threads: `align` may be called on one object from several threads; the calls share
/// the object's buffers and so run one after the other (each waits for the running one),
/// each giving what it gives alone. For alignments that run in parallel, use one
/// ModelAligner per thread. Moving or destroying the object while a call runs is not
/// allowed, as for any C++ object.
class ModelAligner {
 public:
  /// @throws std::invalid_argument for an empty model, missing normals or invalid
  ///         params (as `align`).
  explicit ModelAligner(const PointCloud& model, const AlignParams& params = {});
  ~ModelAligner();
  ModelAligner(ModelAligner&&) noexcept;
  ModelAligner& operator=(ModelAligner&&) noexcept;

  /// `align(model, scene, params)` with params.initial_guess.
  /// @throws std::invalid_argument as `align` does for the scene.
  AlignResult align(const PointCloud& scene);
  /// The same from `initial_guess` (T_scene_model) instead of params.initial_guess.
  /// @throws std::invalid_argument also for an initial guess that is not rigid.
  AlignResult align(const PointCloud& scene, const Transform& initial_guess);

  const AlignParams& params() const;
  const PointCloud& model() const;
  /// The model's EGI coefficients (size bandwidth^2), as `egi_coefficients` gives them.
  const ShCoefficients& model_coefficients() const;
  /// Stage times of the last `align` to finish (zero but `total` when it ran plain
  /// `align`); a copy, so that reading it while another thread aligns is safe.
  ModelAlignerTimings last_timings() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace spectral_vs
