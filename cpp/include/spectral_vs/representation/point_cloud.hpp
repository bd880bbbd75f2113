#pragma once
/// @file point_cloud.hpp
/// The point cloud with surface normals that every part of the method consumes
/// (paper, section II-A).

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

namespace spectral_vs {

/// N x 3 row-major matrix: the memory layout of a C-contiguous (N, 3) numpy array.
using Points = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

/// 4 x 4 homogeneous rigid transform.
using Transform = Eigen::Matrix4d;

/// Points in metres with optional unit surface normals, both in one frame.
///
/// Invariants (checked on construction): every coordinate is finite; normals are
/// either absent (0 rows) or one per point, finite, non-zero and stored unit length.
class PointCloud {
 public:
  PointCloud() = default;

  /// @param points  (N, 3) coordinates in metres.
  /// @param normals (N, 3) normals or an empty matrix; rescaled to unit length.
  /// @throws std::invalid_argument naming the first offending row.
  explicit PointCloud(Points points, Points normals = Points());

  std::size_t size() const { return static_cast<std::size_t>(points_.rows()); }
  bool empty() const { return points_.rows() == 0; }
  bool has_normals() const { return normals_.rows() != 0; }

  const Points& points() const { return points_; }
  const Points& normals() const { return normals_; }

  /// Centroid of the points, metres. @throws std::invalid_argument if empty.
  Eigen::Vector3d centroid() const;

  /// The cloud moved by `T_target_source` (points rotated and translated, normals rotated).
  /// @throws std::invalid_argument if the transform has non-finite entries.
  PointCloud transformed(const Transform& T_target_source) const;

  /// The rows i with keep[i] != 0, in order, with their normals (no re-check: the rows
  /// are this cloud's). @throws std::invalid_argument unless keep has one entry per point.
  PointCloud selected(const std::vector<char>& keep) const;

 private:
  Points points_;
  Points normals_;
};

/// Rows of `points` (and `normals`, when given) whose entries are all finite.
/// Normals of zero length count as non-finite. Returns the number of rows dropped.
std::size_t remove_non_finite(Points& points, Points* normals = nullptr);

/// Throws std::invalid_argument("<argument> is empty ...") when `cloud` has no points.
void require_non_empty(const PointCloud& cloud, const std::string& argument);

/// Throws std::invalid_argument unless `cloud` carries normals.
void require_normals(const PointCloud& cloud, const std::string& argument);

/// Throws std::invalid_argument unless `T` is a finite rigid transform (orthonormal
/// rotation with determinant +1 to `tolerance`, last row 0 0 0 1).
void require_rigid_transform(const Transform& T, const std::string& argument,
                             double tolerance = 1e-6);

}  // namespace spectral_vs
