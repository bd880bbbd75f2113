#pragma once
// Internal to the aligner: the plane a scene's objects stand on (a table), found and
// removed before the scene is searched.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <optional>

namespace spectral_vs::detail {

/// The plane that `support_plane` finds and `without_support_plane` removes: unit normal,
/// the mean of its points' normals (which face the sensor, on the side of the objects it
/// carries), and offset, n . x = offset on the plane, metres: the median over the points
/// of the plane's 1.5-voxel band.
struct SupportPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
};

/// The scene's support plane: the largest plane of points with one normal direction, if
/// it is wider than `min_extent` metres and holds more than a fifth of the points (a table
/// under the objects); none otherwise. Found by `spectral_vs::dominant_plane` (voting,
/// deterministic: the most common normal direction, then the most common offset along
/// it, in bins of `voxel_size`).
std::optional<SupportPlane> support_plane(const PointCloud& scene, double voxel_size,
                                          double min_extent);

/// The scene without the points of `plane`: those within `band` metres of it whose
/// normals are within 20 degrees of its normal.
PointCloud without_support_plane(const PointCloud& scene, const SupportPlane& plane,
                                 double voxel_size, double band);

}  // namespace spectral_vs::detail
