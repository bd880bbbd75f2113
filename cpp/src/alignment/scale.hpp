#pragma once
// Internal: the one rule that derives a registration's voxel from its clouds.

#include <spectral_vs/representation/point_cloud.hpp>

namespace spectral_vs::detail {

/// Twice the median distance of the points from their per-axis median, metres: the size
/// of where most of a cloud's points are (not the box of a depth camera's few far returns).
double typical_size(const Points& points);

/// max(extent / voxels_across, spacings * extent / sqrt(points)): a voxel that divides the
/// typical size, and holds at least `spacings` point spacings of a surface of `points`
/// points spanning `extent` (about extent / sqrt(points) between neighbours).
double scale_rule(double extent, double points, double voxels_across, double spacings);

}  // namespace spectral_vs::detail
