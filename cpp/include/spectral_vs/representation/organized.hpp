#pragma once
/// @file organized.hpp
/// Points and normals from an organized depth image (a depth camera's planar depth map):
/// the fast way from a sensor frame to the input of the representation, without a
/// neighbour search. `cloud_from_depth` (depth_image.hpp) is the entry point for sensor
/// images (raw units, depth range, organized output); this is its core on metres.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <cstddef>

namespace spectral_vs {

/// A planar depth image, metres along the optical axis, row-major (height x width);
/// NaN (or any non-finite value) where the sensor saw nothing.
using DepthImage = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The pinhole model of the camera that took a depth image: pixel (row v, column u) at
/// depth d is the point (d (u - cx) / fx, d (v - cy) / fy, d) in the camera frame
/// (X right, Y down, Z forward).
struct PinholeIntrinsics {
  double fx = 1.0;  ///< Focal length along the columns, pixels.
  double fy = 1.0;  ///< Focal length along the rows, pixels.
  double cx = 0.0;  ///< Column of the principal point, pixels.
  double cy = 0.0;  ///< Row of the principal point, pixels.
};

/// How `organized_cloud` computes normals and which pixels it keeps.
///
/// The normal of a pixel is the cross product of the central differences of the
/// back-projected points `normal_step` pixels away along the row and the column, summed
/// over a `window` x `window` neighbourhood (an area-weighted average that tames depth
/// noise), normalised and oriented toward the camera. A pixel whose four stencil
/// neighbours are not all within `max_depth_jump` times its depth of it (missing, or
/// across a silhouette edge) has no reliable normal and adds nothing to the sums.
/// Largest depth image the clouds are made of, pixels (8192 x 8192): checked before any
/// buffer is allocated.
inline constexpr long long kMaxDepthPixels = 1LL << 26;

/// Scratch buffers over this many bytes are released after each call; smaller ones (a
/// 640 x 480 frame's, about 25 MB) are kept per thread for the next frame of a servo.
inline constexpr std::size_t kKeptScratchBytes = std::size_t(64) << 20;

struct OrganizedNormalParams {
  int normal_step = 2;           ///< Half-baseline of the differences, pixels (>= 1, at most the
                                 ///< image's larger side).
  int window = 5;                ///< Side of the averaging window, pixels (odd, >= 1, at most twice
                                 ///< the image's larger side plus one).
  double max_depth_jump = 0.05;  ///< Largest relative depth change to a stencil neighbour (> 0).
  int stride = 1;  ///< Keep every stride-th pixel along rows and columns (>= 1, at most the
                   ///< image's larger side).
};

/// The point cloud with unit normals, oriented toward the camera, of a depth image, in
/// the camera frame. Pixels (v, u) with v and u multiples of `params.stride` are kept,
/// in row-major order, when they have a point and a reliable normal (which excludes a
/// border of `normal_step` pixels). The normals of the kept pixels use every pixel
/// around them, whatever the stride.
/// The same as `cloud_from_depth` on a metric image without a depth range, except that a
/// depth of 0 or below is not refused and an image without valid pixels gives an empty
/// cloud.
/// @throws std::invalid_argument for non-finite or non-positive focal lengths,
///         a non-finite principal point, or invalid params.
PointCloud organized_cloud(const Eigen::Ref<const DepthImage>& depth,
                           const PinholeIntrinsics& intrinsics,
                           const OrganizedNormalParams& params = {});

}  // namespace spectral_vs
