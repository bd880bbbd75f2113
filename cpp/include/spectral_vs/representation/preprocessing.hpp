#pragma once
/// @file preprocessing.hpp
/// Downsampling and normal estimation (PCL's plane fits), the steps that turn a raw scan into
/// the input of the representation.

#include <spectral_vs/representation/point_cloud.hpp>

namespace spectral_vs {

/// Replaces the points of each `voxel_size` cube by their centroid. The cubes are those
/// of a lattice through the origin; the output lists the occupied ones ordered by z, then
/// y, then x index (deterministic). Normals, when present, are averaged and renormalised;
/// a voxel whose normals cancel out is dropped.
/// Double precision throughout, with sums relative to the cloud's box: precision does not
/// depend on the distance from the origin. Linear in the number of points (a hash of the
/// occupied voxels).
/// @param voxel_size edge of the cube in metres, finite, > 0 and <= 1e6.
/// @throws std::invalid_argument for an empty cloud or a voxel size that is not
///         finite, not positive, over 1e6 m, or so small that voxel indices would overflow.
PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size);

/// How `estimate_normals` resolves the sign ambiguity of a fitted plane.
enum class NormalOrientation {
  toward_viewpoint,  ///< n . (viewpoint - p) >= 0: for scans, viewpoint = sensor origin.
  outward,           ///< n . (p - centroid) >= 0: for closed, roughly star-shaped models.
};

/// Settings of `estimate_normals`.
struct NormalEstimationParams {
  double radius = 0.015;  ///< Neighbourhood radius in metres (used when k_neighbors == 0).
  int k_neighbors = 0;    ///< If > 0, use this many nearest neighbours instead of a radius.
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();  ///< Sensor origin, metres.
  NormalOrientation orientation = NormalOrientation::toward_viewpoint;
  int threads = 1;  ///< OpenMP threads in [1, 256]; results do not depend on it.
};

/// Fits a plane to each point's neighbourhood (PCL NormalEstimationOMP) and orients it.
/// Points whose neighbourhood has fewer than 3 points, or no plane (all coincident), get
/// no normal and are dropped. (A neighbourhood of collinear points gets an arbitrary
/// normal perpendicular to its line.)
/// @throws std::invalid_argument for an empty cloud, non-finite or non-positive
///         radius, negative k, threads outside [1, 256], or when no point gets a normal.
PointCloud estimate_normals(const PointCloud& cloud, const NormalEstimationParams& params = {});

}  // namespace spectral_vs
