// The scale of a scene-to-scene registration, from the views themselves.

#include <spectral_vs/alignment/view_aligner.hpp>

#include "common/checks.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace spectral_vs {

namespace {

// Twice the median distance of the points from their per-axis median: the size of where
// most of a view's points are. A depth camera sees its near surfaces densely and the far
// background (a floor behind the table, a window) sparsely; the bounding box of a view
// tilted toward the horizon is several times the scene it registers on.
double typical_size(const Points& points) {
  const auto median = [](std::vector<double>& values) {
    const auto k = std::ptrdiff_t(values.size() / 2);
    std::nth_element(values.begin(), values.begin() + k, values.end());
    return values[std::size_t(k)];
  };
  std::vector<double> values(std::size_t(points.rows()));
  Eigen::Vector3d centre;
  for (int axis = 0; axis < 3; ++axis) {
    for (Eigen::Index i = 0; i < points.rows(); ++i) values[std::size_t(i)] = points(i, axis);
    centre[axis] = median(values);
  }
  for (Eigen::Index i = 0; i < points.rows(); ++i)
    values[std::size_t(i)] = (points.row(i).transpose() - centre).norm();
  return 2.0 * median(values);
}

}  // namespace

ViewScale view_scale(const PointCloud& reference, const PointCloud& current, double voxels_across) {
  require_non_empty(reference, "reference");
  require_non_empty(current, "current");
  if (!(voxels_across >= 4.0 && std::isfinite(voxels_across)))
    detail::fail("voxels_across must be finite and >= 4, got ", voxels_across);
  ViewScale scale;
  scale.extent = std::max(typical_size(reference.points()), typical_size(current.points()));
  if (!(scale.extent > 0.0))
    detail::fail("reference, current: the views span no volume (all points at one place)");
  const double points = double(std::min(reference.size(), current.size()));
  scale.voxel_size = std::max(scale.extent / voxels_across, 3.0 * scale.extent / std::sqrt(points));
  scale.search_voxel_size = 2.0 * scale.voxel_size;
  return scale;
}

}  // namespace spectral_vs
