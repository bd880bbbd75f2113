#pragma once
// Internal to the aligner: sets of points, by row, by voxel and by connection.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

namespace spectral_vs::detail {

/// The rows `rows` of `matrix`, in that order.
Points rows_of(const Points& matrix, const std::vector<Eigen::Index>& rows);

/// Every stride-th point (and normal) of `cloud`, at least its first.
PointCloud every_nth(const PointCloud& cloud, Eigen::Index stride);

// The sparse model that candidate poses are screened on (a part's rotations in clutter,
// the alternatives): every this-many-th model point, an eighth of the nearest-point
// queries. Screening a part's rotations on every 8th point, 263 of 280 tuning clutter
// scenes come out right, as on every 4th; on every 2nd, 261; at 0.95 and 0.86 times
// their CPU time.
constexpr Eigen::Index kSparseStride = 8;

/// A voxel (or cell) index as one sortable key, 21 bits per axis, each index clamped to
/// [-2^20, 2^20 - 1]: the sparse sets of voxels of the fitness and of connected_parts.
std::uint64_t voxel_key(const Eigen::Array3i& voxel);

/// The rows of `scene` within max_translation of `model_box` on every axis: the only
/// points that a shift of at most max_translation can bring the model's points onto, so
/// the only ones a bounded phase correlation needs (the others enter its spectrum only as
/// clutter). All of `scene` when every point is in reach, or when none is.
Points points_in_reach(const Points& scene, const Eigen::AlignedBox3d& model_box,
                       double max_translation);

/// The box of a non-empty set of points.
Eigen::AlignedBox3d points_box(const Points& points);

/// The scene's points grouped into connected parts: two points within `tolerance` metres
/// are in one part (single linkage, on a hash grid of `tolerance` cells). Parts in
/// decreasing size, each as rows of `points` in increasing order; deterministic.
std::vector<std::vector<Eigen::Index>> connected_parts(const Points& points, double tolerance);

}  // namespace spectral_vs::detail
