#pragma once

#include "spectral_vs/representation/point_cloud.hpp"

#include <cmath>
#include <cstddef>
#include <optional>
#include <vector>

namespace spectral_vs {

/// Settings of the dominant-plane detection (a table top under objects, a floor).
struct PlaneDetectionParams {
  /// Half-angle of the vote for the direction, rad: the normal with the most others within
  /// it wins (over a subsample of at most 400 candidates), and the direction is the mean of
  /// the normals within it of the winner.
  double direction_cone = 10.0 * M_PI / 180.0;
  /// Half-angle about the direction whose normals are the plane's, rad (0, pi/2).
  double member_cone = 20.0 * M_PI / 180.0;
  /// Bin of the vote for the plane's offset along its normal, m (> 0): the offset is the
  /// middle of the two neighbouring bins that hold the most in-cone points.
  double offset_bin = 0.01;
  /// The plane's points lie within this of its offset, m (> 0; infinity: any distance).
  double band = 0.015;
  /// Least share of the points on the plane, in [0, 1]; fewer: no plane.
  double min_share = 0.2;
};

/// The most common direction of unit normals and the share of the normals within
/// `member_cone` of it (n . axis > cos member_cone).
struct DominantDirection {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< unit; +z for no normals
  double share = 0.0;                               ///< in [0, 1]
};

/// A dominant plane: n . x = offset on it.
struct DominantPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, the mean of its normals' side
  double offset = 0.0;                                ///< m
  std::size_t count = 0;  ///< points on the plane (in the band, normal within the cone)
  double share = 0.0;     ///< count over the cloud's points, in [0, 1]
  double extent = 0.0;    ///< diagonal of the bounding box of its points, m
};

/// The dominant direction of `normals` (unit, N x 3), by voting; deterministic.
DominantDirection dominant_direction(const Points& normals,
                                     const PlaneDetectionParams& params = {});

/// The dominant plane of a cloud with normals: the dominant direction, then the most common
/// offset along it; none when fewer than `min_share` of the points lie on it.
/// Throws std::invalid_argument for a cloud without normals or settings out of range.
std::optional<DominantPlane> dominant_plane(const PointCloud& cloud,
                                            const PlaneDetectionParams& params = {});

/// Which points of `cloud` lie on `plane` (1) under `params`: |n . normal| above
/// cos(member_cone) and |p . normal - offset| below band.
std::vector<char> plane_members(const PointCloud& cloud, const DominantPlane& plane,
                                const PlaneDetectionParams& params);

}  // namespace spectral_vs
