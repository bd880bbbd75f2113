// The scale of a registration from the clouds themselves: one rule for scene-to-scene
// registration (view_scale) and for model-to-scene alignment (alignment_voxel_size).

#include <spectral_vs/alignment/view_aligner.hpp>

#include "alignment/scale.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace spectral_vs {

namespace detail {

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
    values[std::size_t(i)] = (points.row(i).transpose() - centre).stableNorm();  // no overflow
  return 2.0 * median(values);
}

double scale_rule(double extent, double points, double voxels_across, double spacings) {
  return std::max(extent / voxels_across, spacings * extent / std::sqrt(points));
}

}  // namespace detail

namespace {

// The model's typical size in voxels of the alignment: 12 gives 6.9-12 mm (8.3 mm at the
// median) on the objects of docs/experiments.md, whose tuned default was 8 mm.
constexpr double kModelVoxelsAcross = 12.0;
// One point spacing per voxel at least: a sparse model (the 198-point half of bun0.pcd,
// 8.6 mm apart) keeps about the 8 mm it was measured at; views take 3 (view_scale).
constexpr double kModelSpacings = 1.0;

}  // namespace

ViewScale view_scale(const PointCloud& reference, const PointCloud& current, double voxels_across) {
  require_non_empty(reference, "reference");
  require_non_empty(current, "current");
  if (!(voxels_across >= 4.0 && std::isfinite(voxels_across)))
    detail::fail("voxels_across must be finite and >= 4, got ", voxels_across);
  ViewScale scale;
  scale.extent =
      std::max(detail::typical_size(reference.points()), detail::typical_size(current.points()));
  if (!(scale.extent > 0.0))
    detail::fail("reference, current: the views span no volume (all points at one place)");
  const double points = double(std::min(reference.size(), current.size()));
  scale.voxel_size = detail::scale_rule(scale.extent, points, voxels_across, 3.0);
  scale.search_voxel_size = 2.0 * scale.voxel_size;
  return scale;
}

double alignment_voxel_size(const PointCloud& model, const PointCloud& scene) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  // A model of one point, or of coincident points, has no size: the scene's then.
  const PointCloud& sized = detail::typical_size(model.points()) > 0.0 ? model : scene;
  const double extent = detail::typical_size(sized.points());
  if (!(extent > 0.0))
    detail::fail("model, scene: their points span no volume (each at one place): give voxel_size");
  return detail::scale_rule(extent, double(sized.size()), kModelVoxelsAcross, kModelSpacings);
}

}  // namespace spectral_vs
