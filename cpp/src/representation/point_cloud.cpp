#include <spectral_vs/representation/point_cloud.hpp>

#include "common/checks.hpp"

#include <Eigen/LU>

namespace spectral_vs {

using detail::fail;

namespace {

bool row_finite(const Points& m, Eigen::Index row) { return m.row(row).allFinite(); }

}  // namespace

PointCloud::PointCloud(Points points, Points normals)
    : points_(std::move(points)), normals_(std::move(normals)) {
  for (Eigen::Index i = 0; i < points_.rows(); ++i) {
    if (!row_finite(points_, i)) {
      fail("points: row ", i,
           " is not finite; drop such rows first (Python: PointCloud(..., drop_non_finite=True);"
           " C++: remove_non_finite)");
    }
  }
  if (normals_.rows() == 0) {
    return;
  }
  if (normals_.rows() != points_.rows()) {
    fail("normals: expected ", points_.rows(), " rows (one per point), got ", normals_.rows());
  }
  for (Eigen::Index i = 0; i < normals_.rows(); ++i) {
    const double norm = normals_.row(i).norm();
    if (!std::isfinite(norm) || norm == 0.0) {
      fail("normals: row ", i, " is not finite or has zero length");
    }
    normals_.row(i) /= norm;
  }
}

Eigen::Vector3d PointCloud::centroid() const {
  require_non_empty(*this, "cloud");
  return points_.colwise().mean().transpose();
}

PointCloud PointCloud::transformed(const Transform& T_target_source) const {
  // The invariant: a cloud holds finite points only.
  if (!T_target_source.allFinite()) fail("T_target_source has non-finite entries");
  const Eigen::Matrix3d R = T_target_source.topLeftCorner<3, 3>();
  const Eigen::RowVector3d t = T_target_source.topRightCorner<3, 1>().transpose();
  PointCloud out;
  out.points_ = (points_ * R.transpose()).rowwise() + t;
  if (has_normals()) {
    out.normals_ = normals_ * R.transpose();
  }
  return out;
}

PointCloud PointCloud::selected(const std::vector<char>& keep) const {
  if (keep.size() != size()) {
    fail("keep: expected ", size(), " entries (one per point), got ", keep.size());
  }
  Eigen::Index count = 0;
  for (const char k : keep) count += k != 0;
  PointCloud out;
  out.points_.resize(count, 3);
  if (has_normals()) out.normals_.resize(count, 3);
  Eigen::Index row = 0;
  for (Eigen::Index i = 0; i < points_.rows(); ++i) {
    if (!keep[std::size_t(i)]) continue;
    out.points_.row(row) = points_.row(i);
    if (has_normals()) out.normals_.row(row) = normals_.row(i);
    ++row;
  }
  return out;
}

std::size_t remove_non_finite(Points& points, Points* normals) {
  const bool with_normals = normals != nullptr && normals->rows() != 0;
  if (with_normals && normals->rows() != points.rows()) {
    fail("normals: expected ", points.rows(), " rows (one per point), got ", normals->rows());
  }
  Eigen::Index kept = 0;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    bool ok = row_finite(points, i);
    if (ok && with_normals) {
      const double norm = normals->row(i).norm();
      ok = std::isfinite(norm) && norm > 0.0;
    }
    if (!ok) {
      continue;
    }
    points.row(kept) = points.row(i);
    if (with_normals) {
      normals->row(kept) = normals->row(i);
    }
    ++kept;
  }
  const auto dropped = static_cast<std::size_t>(points.rows() - kept);
  points.conservativeResize(kept, Eigen::NoChange);
  if (with_normals) {
    normals->conservativeResize(kept, Eigen::NoChange);
  }
  return dropped;
}

void require_non_empty(const PointCloud& cloud, const std::string& argument) {
  if (cloud.empty()) {
    fail(argument, " is empty: at least 1 finite point is needed");
  }
}

void require_normals(const PointCloud& cloud, const std::string& argument) {
  if (!cloud.has_normals()) {
    fail(argument, " has no normals: estimate them first (estimate_normals)");
  }
}

void require_rigid_transform(const Transform& T, const std::string& argument, double tolerance) {
  if (!T.allFinite()) {
    fail(argument, " has non-finite entries");
  }
  if ((T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > tolerance) {
    fail(argument, " must have last row [0 0 0 1]");
  }
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (orthogonality > tolerance || R.determinant() < 0.0) {
    fail(argument, " is not a rigid transform: |R^T R - I| = ", orthogonality, " (limit ",
         tolerance, "), det R = ", R.determinant());
  }
}

}  // namespace spectral_vs
