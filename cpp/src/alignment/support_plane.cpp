#include "alignment/support_plane.hpp"

#include <spectral_vs/representation/dominant_plane.hpp>

#include <algorithm>
#include <vector>

namespace spectral_vs::detail {

namespace {

// The support plane's detection: the most common normal direction to within 10 degrees,
// the plane's normals within 20 degrees of it, its offset voted in voxel bins, its points
// within 1.5 voxels of it and more than a fifth of the scene's.
PlaneDetectionParams support_plane_params(double voxel_size) {
  PlaneDetectionParams params;
  params.direction_cone = 10.0 * M_PI / 180.0;
  params.member_cone = 20.0 * M_PI / 180.0;
  params.offset_bin = voxel_size;
  params.band = 1.5 * voxel_size;
  params.min_share = 0.2;
  return params;
}

}  // namespace

std::optional<SupportPlane> support_plane(const PointCloud& scene, double voxel_size,
                                          double min_extent) {
  const std::optional<DominantPlane> plane =
      dominant_plane(scene, support_plane_params(voxel_size));
  if (!plane || plane->count == scene.size() || plane->extent < min_extent) return std::nullopt;
  // The vote's offset is a bin's edge, up to half a voxel off: the median of its points'
  // offsets is the plane's, so that a band under a thin object's height (support_band)
  // still holds the plane.
  const std::vector<char> on = plane_members(scene, *plane, support_plane_params(voxel_size));
  std::vector<double> offsets;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i)
    if (on[std::size_t(i)]) offsets.push_back(scene.points().row(i).dot(plane->normal));
  const auto middle = offsets.begin() + std::ptrdiff_t(offsets.size() / 2);
  std::nth_element(offsets.begin(), middle, offsets.end());
  return SupportPlane{plane->normal, *middle};
}

PointCloud without_support_plane(const PointCloud& scene, const SupportPlane& plane,
                                 double voxel_size, double band) {
  DominantPlane found;
  found.normal = plane.normal;
  found.offset = plane.offset;
  PlaneDetectionParams members = support_plane_params(voxel_size);
  members.band = band;
  const std::vector<char> on = plane_members(scene, found, members);
  const auto kept = Eigen::Index(std::count(on.begin(), on.end(), 0));
  Points kept_points(kept, 3), kept_normals(kept, 3);
  Eigen::Index row = 0;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
    if (on[std::size_t(i)]) continue;
    kept_points.row(row) = scene.points().row(i);
    kept_normals.row(row++) = scene.normals().row(i);
  }
  return PointCloud(kept_points, kept_normals);
}

}  // namespace spectral_vs::detail
