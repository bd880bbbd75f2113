#pragma once
/// @file preprocessing.hpp
/// Downsampling and normal estimation (PCL's plane fits), the steps that turn a raw scan into
/// the input of the representation.

#include <spectral_vs/representation/point_cloud.hpp>

#include <string>

namespace spectral_vs {

/// Replaces the points of each `voxel_size` cube by their centroid. The cubes are those
/// of a lattice through the origin; the output lists the occupied ones ordered by z, then
/// y, then x index (deterministic). Normals, when present, are averaged and renormalised;
/// a voxel whose normals cancel out is dropped.
/// Double precision throughout, with sums relative to each voxel's first point: precision
/// depends neither on the distance from the origin nor on the cloud's extent (a far
/// outlier is one more voxel and changes no other). Linear in the number of points (a hash
/// of the occupied voxels, keyed by their three indices).
/// @param voxel_size edge of the cube in metres, finite, > 0 and <= 1e6.
/// @throws std::invalid_argument for an empty cloud or a voxel size that is not
///         finite, not positive, over 1e6 m, or so small that a point's voxel index would
///         reach 2^62 (|coordinate| >= 2^62 voxel_size; the message counts those points).
PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size);

/// How `estimate_normals` resolves the sign ambiguity of a fitted plane.
enum class NormalOrientation {
  toward_viewpoint,  ///< n . (viewpoint - p) >= 0: for scans, viewpoint = sensor origin.
  outward,           ///< n . (p - c) >= 0, c the centroid of the points that get a normal: for
                     ///< closed, roughly star-shaped models.
};

/// Settings of `estimate_normals`.
struct NormalEstimationParams {
  double radius = 0.015;  ///< Neighbourhood radius in metres (used when k_neighbors == 0).
  int k_neighbors = 0;    ///< If > 0, use this many nearest neighbours instead of a radius
                          ///< (at most 1024; more than the cloud's points means all of them).
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();  ///< Sensor origin, metres.
  NormalOrientation orientation = NormalOrientation::toward_viewpoint;
  int threads = 1;  ///< OpenMP threads in [1, 256]; results do not depend on it.
};

/// Fits a plane to each point's neighbourhood (PCL NormalEstimationOMP) and orients it.
/// Points whose neighbourhood has fewer than 3 points, or no plane (all coincident), get
/// no normal and are dropped. (A neighbourhood of collinear points gets an arbitrary
/// normal perpendicular to its line.)
/// PCL searches in float: the cloud goes in as it is when its per-axis median is within
/// 100 m of the origin, else relative to that median, so that far outliers (one point at
/// 1e12 m) change no other point's neighbours or normal; points 1e18 m or more from that
/// reference on an axis are not searched and get no normal.
/// @throws std::invalid_argument for an empty cloud, non-finite or non-positive
///         radius, k outside [0, 1024], threads outside [1, 256], or when no point gets a normal
///         (the message counts the points too far to be searched).
PointCloud estimate_normals(const PointCloud& cloud, const NormalEstimationParams& params = {});

/// A cloud as the registrations take it, the one preparation of align(), align_views() and
/// the servo: downsampled to half of `voxel_size` (the EGI and the grids see no finer
/// detail; `downsample` false keeps every point), with normals where it has none, fitted
/// over a radius of twice `voxel_size` and turned toward `viewpoint` (the sensor's origin),
/// or outward from the cloud's centroid when `viewpoint` lies strictly inside the cloud's
/// bounding box: toward a point inside a closed model (one centred at the origin) they
/// would point into it (a model aligned onto single views of itself so came back 147
/// degrees off at the median, 0 of 12 right; 12 of 12 right outward).
/// @param argument the cloud's name in the caller's API, which every message names.
/// @throws std::invalid_argument for an empty cloud, a voxel_size that is not finite and
///         > 0, a non-finite viewpoint, and as voxel_downsample and estimate_normals (a
///         voxel too fine for the cloud's extent, a cloud in which no normal can be fitted),
///         saying which step of the preparation failed.
PointCloud prepare_cloud(const PointCloud& cloud, double voxel_size, bool downsample,
                         const Eigen::Vector3d& viewpoint, const std::string& argument = "cloud");

}  // namespace spectral_vs
