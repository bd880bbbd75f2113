#pragma once
// Internal to align(), its first stage: what of the scene is searched. The support
// plane under the objects is taken out (support_plane.hpp), the rest cut into connected
// parts that could be the object, and a scene seen from one sensor is found out.

#include <spectral_vs/alignment/aligner.hpp>

#include "alignment/stages.hpp"
#include "alignment/support_plane.hpp"

#include <optional>
#include <vector>

namespace spectral_vs::detail {

/// How far above the support plane the plane's band reaches, metres: what lies within it
/// is taken for the plane (without_support_plane) and kept out of the parts. 1.5 voxels
/// (the tilted normals at the objects' feet), but under the thickness of a thin model.
double support_band(const Points& model_points, double voxel_size);

/// Points this many voxels apart are in one part: the scene comes downsampled to half a
/// voxel, and objects a few millimetres apart stay apart.
inline constexpr double kPartTolerance = 0.75;

/// The rows of `searched` more than `band` above the support plane (all without one).
std::vector<Eigen::Index> rows_above(const PointCloud& searched,
                                     const std::optional<SupportPlane>& plane, double band);

/// The connected parts of `searched` (more than `band` above the support plane, when there
/// is one) that could be the object: sizes between a quarter of the model's reach and two
/// of its diameters, at most `max_parts` (GlobalSearchParams::max_parts), largest first; a
/// view cut in parts also as a whole.
std::vector<std::vector<Eigen::Index>> object_parts(const PointCloud& searched,
                                                    const std::optional<SupportPlane>& plane,
                                                    double reach, double voxel_size, double band,
                                                    int max_parts);

/// The whole of a single view as the one part (no support plane to cut it).
std::vector<Eigen::Index> whole_view(const PointCloud& searched);

/// With search.guess_distance: keeps the parts that the model could reach from
/// `initial_guess`.
void keep_parts_near_guess(const Problem& problem, const GlobalSearchParams& search,
                           const Transform& initial_guess, const PointCloud& searched,
                           std::vector<std::vector<Eigen::Index>>& parts);

/// The sensor origin of a single view, or none (a scene seen from all sides, declared or
/// detected).
std::optional<Eigen::Vector3d> single_view_origin(const PointCloud& scene,
                                                  const AlignParams& params);

/// The sensor origin of the scene as the settings give it (sensor_origin).
Eigen::Vector3d scene_sensor_origin(const AlignParams& params);

}  // namespace spectral_vs::detail
