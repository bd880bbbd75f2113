#include "alignment/part_coverage.hpp"

#include "alignment/align_detail.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/scene_preparation.hpp"
#include "alignment/support_plane.hpp"

#include <algorithm>

namespace spectral_vs::detail {

PartCoverage::PartCoverage(const PointCloud& searched, const SupportPlane& plane, double band,
                           double voxel_size)
    : searched_(searched), voxel_size_(voxel_size), above_(rows_above(searched, plane, band)) {
  part_of_.assign(above_.size(), -1);
  const auto parts =
      connected_parts(rows_of(searched.points(), above_), kPartTolerance * voxel_size);
  for (std::size_t p = 0; p < parts.size(); ++p) {
    for (const Eigen::Index i : parts[p]) part_of_[std::size_t(i)] = int(p);
    part_size_.push_back(parts[p].size());
  }
}

double PartCoverage::explained_share(const PointCloud& model, const Transform& T) const {
  const PointCloud moved = model.transformed(T);
  Eigen::AlignedBox3d box = bounding_box(moved);
  box.min().array() -= voxel_size_;
  box.max().array() += voxel_size_;
  const IcpScene near_model(moved, box, voxel_size_);
  std::vector<std::size_t> explained(part_size_.size(), 0);
  for (std::size_t k = 0; k < above_.size(); ++k) {
    const Eigen::Vector3d p = searched_.points().row(above_[k]).transpose();
    if (box.contains(p) && near_model.nearest(p, Eigen::Vector3d::UnitZ(), voxel_size_, -2.0) >= 0)
      ++explained[std::size_t(part_of_[k])];
  }
  const auto most = std::max_element(explained.begin(), explained.end());
  if (most == explained.end() || *most == 0) return 0.0;
  return double(*most) / double(part_size_[std::size_t(most - explained.begin())]);
}

}  // namespace spectral_vs::detail
