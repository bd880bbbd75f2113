#pragma once
// Internal to align(): how much of the scene's object it lies on a pose explains. In
// clutter a flat model fits on a face of a larger object as well as on its own, its
// other faces hidden inside that object; the scene then holds the rest of that object,
// unexplained, where the model's own object is explained whole.

#include <spectral_vs/representation/point_cloud.hpp>

#include "alignment/support_plane.hpp"

#include <vector>

namespace spectral_vs::detail {

class PartCoverage {
 public:
  /// The connected parts of `searched` more than `band` above `plane` (as object_parts
  /// cuts them). `searched` must outlive the coverage.
  PartCoverage(const PointCloud& searched, const SupportPlane& plane, double band,
               double voxel_size);

  /// Of the scene points of the part that most of the model's explained points fall in
  /// (scene points within a voxel of a model point at T_scene_model), the share so
  /// explained, in [0, 1]; 0 when the model explains none.
  double explained_share(const PointCloud& model, const Transform& T_scene_model) const;

 private:
  const PointCloud& searched_;
  double voxel_size_;
  std::vector<Eigen::Index> above_;  // rows of searched_ above the band
  std::vector<int> part_of_;         // per row of above_: its part
  std::vector<std::size_t> part_size_;
};

}  // namespace spectral_vs::detail
