#pragma once
/// @file depth_image.hpp
/// A depth camera's frame as the input of the method: the depth image (in the sensor's
/// integer units or in metres) and the 3x3 camera matrix K give the cloud, organized or
/// not, with normals toward the camera.

#include <spectral_vs/representation/organized.hpp>
#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace spectral_vs {

/// A depth image in the sensor's integer units (uint16, as Kinect, RealSense and the TUM
/// RGB-D files store it), row-major (height x width); 0 where the sensor saw nothing.
using RawDepthImage = Eigen::Matrix<std::uint16_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// A planar depth image in metres in single precision (OpenCV's CV_32F), row-major.
using DepthImageF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// Sensor units per metre of a raw depth image when none is given: millimetres, the unit
/// of the Kinect, RealSense and Azure Kinect SDKs (TUM RGB-D files use 5000).
inline constexpr double kDefaultDepthScale = 1000.0;

/// How `cloud_from_depth` reads a depth image and which pixels it keeps. The normal
/// settings and the stride are those of `OrganizedNormalParams` (the normals are the
/// same: cross products of central differences of neighbouring pixels' points, averaged
/// over a window, toward the camera).
///
/// A pixel is valid when its depth, in metres, is finite, > 0 and within
/// [min_depth, max_depth]. Invalid pixels count as missing for the normals of their
/// neighbours too (a truncated background does not bend the normals of the edge before it).
struct DepthCloudParams : OrganizedNormalParams {
  /// Sensor units per metre: depth in metres = value / depth_scale (> 0). Unset: 1000 for
  /// raw (uint16) images, 1 for floating images (metres).
  std::optional<double> depth_scale;
  double min_depth = 0.0;  ///< Nearer pixels are invalid, metres (>= 0).
  double max_depth = std::numeric_limits<double>::infinity();  ///< Farther invalid, m.
  bool normals = true;  ///< Compute normals; false: points only, every valid pixel kept.
};

/// An organized cloud: one entry per pixel of the depth image's lattice (the pixels whose
/// row and column are multiples of the stride), row-major, camera frame.
struct OrganizedCloud {
  int height = 0;  ///< Rows of the lattice: ceil(image rows / stride).
  int width = 0;   ///< Columns of the lattice: ceil(image columns / stride).
  /// height * width rows: the point of pixel (i stride, j stride) at row i width + j,
  /// metres; NaN where the pixel is invalid.
  Points points;
  /// Unit normals toward the camera, one row per point, NaN where the pixel has no
  /// reliable normal; no rows when the normals were not computed.
  Points normals;

  bool has_normals() const { return normals.rows() != 0; }
  /// Whether pixel row i width + j has a point and, with normals, a normal.
  bool valid(Eigen::Index row) const;
  /// The valid pixels' points (and normals) in row-major order: what `cloud_from_depth`
  /// returns.
  PointCloud valid_cloud() const;
};

/// The pinhole intrinsics of a 3x3 camera matrix K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
/// @throws std::invalid_argument, naming `argument`, unless K has finite entries, fx > 0,
///         fy > 0, no skew (K(0, 1) = K(1, 0) = 0) and the bottom row (0, 0, 1) (within 1e-9).
PinholeIntrinsics intrinsics_from_matrix(const Eigen::Matrix3d& K,
                                         const std::string& argument = "K");

/// The cloud of a depth image: the valid pixels of the lattice, in row-major order, with
/// unit normals toward the camera (pixels without a reliable normal are dropped: the
/// border of normal_step pixels, silhouette edges, the neighbours of holes), camera frame
/// (X right, Y down, Z forward: pixel (v, u) at depth d is d ((u - cx) / fx, (v - cy) /
/// fy, 1)). With params.normals off, every valid pixel and no normals. It may be empty
/// when valid pixels exist but none has a reliable normal (isolated pixels).
/// @throws std::invalid_argument naming the argument: an empty image, a K that is not a
///         camera matrix, invalid params, or no valid pixel at all.
PointCloud cloud_from_depth(const Eigen::Ref<const RawDepthImage>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params = {});
PointCloud cloud_from_depth(const Eigen::Ref<const DepthImageF>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params = {});
PointCloud cloud_from_depth(const Eigen::Ref<const DepthImage>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params = {});

/// The depths a depth camera measures, metres: a scale that puts most of an image's
/// pixels outside [kPlausibleMinDepth, kPlausibleMaxDepth] is likely wrong (a float image
/// in millimetres read as metres puts a table at 800 m; a metres image divided by 1000, at
/// 0.8 mm). Structured light, stereo and time-of-flight cameras range over 0.1-20 m.
inline constexpr double kPlausibleMinDepth = 0.05;
inline constexpr double kPlausibleMaxDepth = 50.0;

/// How the depths of an image fall at a depth scale: whether the scale is plausible.
struct DepthScaleCheck {
  double depth_scale = 0.0;  ///< The scale used (the default of the image's type if unset).
  std::size_t valid = 0;     ///< Pixels whose depth is finite and > 0 (min/max_depth ignored).
  /// Of them, those within [kPlausibleMinDepth, kPlausibleMaxDepth] metres.
  std::size_t plausible = 0;
  /// True unless there are valid pixels and at most half of them are plausible.
  bool ok() const { return 2 * plausible > valid || valid == 0; }
};

/// Counts the valid and the plausible depths of an image at `depth_scale` (unset: 1000 for
/// raw images, 1 for floating ones), in one pass over the pixels (about 0.1 ms for 640 x
/// 480): what the Python `cloud_from_depth` checks before it warns.
/// @throws std::invalid_argument for a depth_scale that is not finite and > 0.
DepthScaleCheck check_depth_scale(const Eigen::Ref<const RawDepthImage>& depth,
                                  std::optional<double> depth_scale = std::nullopt);
DepthScaleCheck check_depth_scale(const Eigen::Ref<const DepthImageF>& depth,
                                  std::optional<double> depth_scale = std::nullopt);
DepthScaleCheck check_depth_scale(const Eigen::Ref<const DepthImage>& depth,
                                  std::optional<double> depth_scale = std::nullopt);

/// The median of an image's valid depths (finite and > 0) at `depth_scale`, metres; NaN
/// when there are none. A selection over a copy of the pixels (a few ms for 640 x 480).
/// @throws std::invalid_argument for a depth_scale that is not finite and > 0.
double median_depth(const Eigen::Ref<const RawDepthImage>& depth,
                    std::optional<double> depth_scale = std::nullopt);
double median_depth(const Eigen::Ref<const DepthImageF>& depth,
                    std::optional<double> depth_scale = std::nullopt);
double median_depth(const Eigen::Ref<const DepthImage>& depth,
                    std::optional<double> depth_scale = std::nullopt);

/// The organized cloud of a depth image: every pixel of the lattice, NaN where invalid
/// (see `OrganizedCloud`); `valid_cloud()` of it equals `cloud_from_depth`.
/// @throws std::invalid_argument as `cloud_from_depth`.
OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const RawDepthImage>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params = {});
OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const DepthImageF>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params = {});
OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const DepthImage>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params = {});

}  // namespace spectral_vs
