#pragma once
// Internal to the aligner: the optional last step, a point-to-plane ICP from the
// spectral result (AlignParams::icp_refinement).

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Geometry>
#include <optional>

namespace spectral_vs::detail {

/// Settings of `refine_point_to_plane`.
struct IcpSettings {
  double max_distance = 0.008;     ///< Pairs farther apart than this are not matched, metres.
  double min_cosine = 0.7071;      ///< Pairs whose normals are farther apart than 45 degrees
                                   ///< are not matched (the other side of a thin part, the table).
  int max_iterations = 30;         ///< Gauss-Newton steps at most.
  Eigen::Index max_points = 1500;  ///< About this many model points take part (a hashed
                                   ///< selection of one in rows / max_points), or all.
  std::optional<Eigen::Vector3d> viewpoint;  ///< Only the model points facing it take part.
};

/// Outcome of `refine_point_to_plane`.
struct IcpOutcome {
  Transform T_scene_model = Transform::Identity();
  int iterations = 0;  ///< Gauss-Newton steps taken.
  int pairs = 0;       ///< Matched pairs at the last step.
};

/// Point-to-plane ICP from `T_scene_model`: each step pairs every model point with its
/// nearest scene point within settings.max_distance whose normal agrees, and takes the
/// Gauss-Newton step of the summed squared distances to the scene points' tangent planes
/// (rotation linearised about the pairs' centroid). Stops when a step moves less than
/// 1e-4 rad and 0.02 mm (a tenth of the accuracy it reaches: finer steps only follow pairs
/// switching back and forth), or with fewer than 6 pairs (the pose is then returned
/// unchanged).
IcpOutcome refine_point_to_plane(const PointCloud& model, const PointCloud& scene,
                                 const Transform& T_scene_model, const IcpSettings& settings);

}  // namespace spectral_vs::detail
