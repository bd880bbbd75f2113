#pragma once
// Internal to align(): its first stage, what both modes start from (aligner.cpp), and
// what the reselection reads of it (reselection.cpp).

#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/fitness_map.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/scene_preparation.hpp"
#include "alignment/stages.hpp"
#include "alignment/support_plane.hpp"
#include "alignment/verifier.hpp"

#include <optional>

namespace spectral_vs::detail {

// The first stage, what both modes start from: the scene as searched (without its
// support plane), its map and EGI, the model's EGI and their correlation, and the
// scene's sensor. Built in place: the scene map points into `searched`.
struct Prepared {
  Prepared(const PointCloud& model, const PointCloud& scene, const AlignParams& params,
           const ScoredModel& moving)
      // Beyond the paper: a table under the objects dominates both the scene's EGI and its
      // voxel grid; searched without it, the object stands out. Fitness still sees it.
      : band(support_band(model.points(), params.scene.voxel_size)),
        plane(params.search.global_search && params.scene.suppress_support_plane
                  ? support_plane(scene, params.scene.voxel_size, 4.0 * moving.reach())
                  : std::nullopt),
        searched(plane ? without_support_plane(scene, *plane, params.scene.voxel_size, band)
                       : scene),
        scene_map(searched),
        model_coefficients(
            egi_coefficients(model, params.scene.bandwidth, params.scene.egi_method)),
        scene_coefficients(
            egi_coefficients(searched, params.scene.bandwidth, params.scene.egi_method)),
        correlation(scene_coefficients, model_coefficients, params.scene.bandwidth, true),
        viewpoint(single_view_origin(scene, params)),
        // The whole scene, its support plane included: a pose that sinks the model into
        // the table is no fit.
        verifier(scene, params.scene.voxel_size, viewpoint,
                 FitnessMap::spec_of(scene, params.scene.voxel_size, params.limits)) {}
  Prepared(const Prepared&) = delete;
  Prepared& operator=(const Prepared&) = delete;

  // What Algorithm 1 and the stages work with, on this scene.
  Problem problem(ScoredModel& moving, const AlignParams& params, double margin,
                  Clock::time_point deadline, std::optional<Eigen::Vector3d> flat_axis,
                  bool dense_model) const {
    return Problem{
        scene_map,      verifier, moving,   model_coefficients, params.scene, phase_params(params),
        params.threads, margin,   deadline, flat_axis,          dense_model,  viewpoint,
        &timings};
  }

  const double band;  // of the support plane, metres
  const std::optional<SupportPlane> plane;
  const PointCloud searched;
  const SceneMap scene_map;
  const ShCoefficients model_coefficients;
  const ShCoefficients scene_coefficients;
  So3Correlation correlation;
  const std::optional<Eigen::Vector3d> viewpoint;  // the sensor of a single view
  const Verifier verifier;
  mutable AlignTimings timings;  // added to by the stages through Problem::timings
};

}  // namespace spectral_vs::detail
