#include "spectral_vs/representation/dominant_plane.hpp"

#include "common/checks.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace spectral_vs {

namespace {

/// Direction votes are cast by at most this many candidates against as many voters (a
/// strided subsample): about 0.2 ms, and the winner is within the cone of the true mode.
constexpr Eigen::Index kDirectionCandidates = 400;

void check(const PlaneDetectionParams& p) {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  if (!(p.direction_cone > 0.0 && p.direction_cone < M_PI / 2))
    fail("direction_cone must be in (0, pi/2) rad, got " + std::to_string(p.direction_cone));
  if (!(p.member_cone > 0.0 && p.member_cone < M_PI / 2))
    fail("member_cone must be in (0, pi/2) rad, got " + std::to_string(p.member_cone));
  if (!(p.offset_bin > 0.0 && std::isfinite(p.offset_bin)))
    fail("offset_bin must be finite and > 0 m, got " + std::to_string(p.offset_bin));
  if (!(p.band > 0.0)) fail("band must be > 0 m, got " + std::to_string(p.band));
  if (!(p.min_share >= 0.0 && p.min_share <= 1.0))
    fail("min_share must be in [0, 1], got " + std::to_string(p.min_share));
}

/// The direction most normals share: the normal with the most others within `cone`, over
/// a subsample, then the mean of the normals within `cone` of it.
Eigen::Vector3d common_direction(const Points& normals, double cone) {
  const Eigen::Index n = normals.rows();
  const Eigen::Index stride = std::max<Eigen::Index>(1, n / kDirectionCandidates);
  const double near = std::cos(cone);
  Eigen::Index best = 0, best_votes = -1;
  for (Eigen::Index i = 0; i < n; i += stride) {
    Eigen::Index votes = 0;
    for (Eigen::Index j = 0; j < n; j += stride) votes += normals.row(i).dot(normals.row(j)) > near;
    if (votes > best_votes) {
      best_votes = votes;
      best = i;
    }
  }
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (Eigen::Index j = 0; j < n; ++j) {
    if (normals.row(best).dot(normals.row(j)) > near) sum += normals.row(j).transpose();
  }
  return sum.normalized();
}

/// The middle of the two neighbouring offset bins with the most in-cone points.
std::optional<double> common_offset(const PointCloud& cloud, const Eigen::Vector3d& axis,
                                    const PlaneDetectionParams& params) {
  const Points& p = cloud.points();
  const Points& n = cloud.normals();
  const double parallel = std::cos(params.member_cone);
  std::vector<std::pair<long, Eigen::Index>> offsets;
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    if (n.row(i).dot(axis) > parallel)
      offsets.emplace_back(std::lround(p.row(i).dot(axis) / params.offset_bin), i);
  }
  if (offsets.empty()) return std::nullopt;
  std::sort(offsets.begin(), offsets.end());
  long best_bin = 0;
  std::size_t best_votes = 0;
  for (std::size_t i = 0; i < offsets.size();) {
    std::size_t j = i;
    while (j < offsets.size() && offsets[j].first == offsets[i].first) ++j;
    // A bin and its neighbours: a plane's offsets straddle bin edges.
    std::size_t votes = j - i;
    for (std::size_t k = j; k < offsets.size() && offsets[k].first == offsets[i].first + 1; ++k)
      ++votes;
    if (votes > best_votes) {
      best_votes = votes;
      best_bin = offsets[i].first;
    }
    i = j;
  }
  return (double(best_bin) + 0.5) * params.offset_bin;
}

}  // namespace

DominantDirection dominant_direction(const Points& normals, const PlaneDetectionParams& params) {
  check(params);
  DominantDirection out;
  if (normals.rows() == 0) return out;
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    const double length = normals.row(i).norm();
    if (!(std::abs(length - 1.0) <= 1e-3)) {
      detail::fail("normals: row ", i, " is not a unit vector (length ", length, ")");
    }
  }
  const Eigen::Vector3d axis = common_direction(normals, params.direction_cone);
  if (!(axis.norm() > 0.5)) return out;  // no normal within the cone of another
  const double parallel = std::cos(params.member_cone);
  Eigen::Index inside = 0;
  for (Eigen::Index i = 0; i < normals.rows(); ++i) inside += normals.row(i).dot(axis) > parallel;
  out.axis = axis;
  out.share = double(inside) / double(normals.rows());
  return out;
}

std::vector<char> plane_members(const PointCloud& cloud, const DominantPlane& plane,
                                const PlaneDetectionParams& params) {
  const double parallel = std::cos(params.member_cone);
  std::vector<char> on(std::size_t(cloud.size()), 0);
  for (Eigen::Index i = 0; i < cloud.points().rows(); ++i) {
    on[std::size_t(i)] =
        std::abs(cloud.normals().row(i).dot(plane.normal)) > parallel &&
        std::abs(cloud.points().row(i).dot(plane.normal) - plane.offset) < params.band;
  }
  return on;
}

std::optional<DominantPlane> dominant_plane(const PointCloud& cloud,
                                            const PlaneDetectionParams& params) {
  check(params);
  if (!cloud.has_normals()) throw std::invalid_argument("cloud must have normals");
  if (cloud.size() == 0) return std::nullopt;
  const Eigen::Vector3d axis = common_direction(cloud.normals(), params.direction_cone);
  if (!(axis.norm() > 0.5)) return std::nullopt;
  const std::optional<double> offset = common_offset(cloud, axis, params);
  if (!offset) return std::nullopt;
  DominantPlane plane;
  plane.normal = axis;
  plane.offset = *offset;
  const std::vector<char> on = plane_members(cloud, plane, params);
  Eigen::AlignedBox3d box;
  for (Eigen::Index i = 0; i < cloud.points().rows(); ++i) {
    if (!on[std::size_t(i)]) continue;
    box.extend(cloud.points().row(i).transpose());
    ++plane.count;
  }
  plane.share = double(plane.count) / double(cloud.size());
  plane.extent = plane.count ? box.sizes().norm() : 0.0;
  if (plane.share < params.min_share) return std::nullopt;
  return plane;
}

}  // namespace spectral_vs
