#pragma once
// Internal to the aligner: a single-view scene as its sensor saw it, to check a model
// pose against what the sensor would then have seen.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Geometry>
#include <vector>

namespace spectral_vs::detail {

/// What one view of the model at a pose says, per pixel of the model's own depth image
/// (its nearest points facing the sensor): the scan has a surface there, turned the same
/// way within 45 degrees (`confirmed`); the scan saw through it, farther or nowhere, or
/// saw a surface there turned another way (`contradicted`); or the scan saw something
/// nearer that hides it (`hidden`).
struct ViewCheck {
  int confirmed = 0;
  int contradicted = 0;
  int hidden = 0;
  /// Model points, each (not only the nearest of its pixel), within the tolerance of the
  /// scan's depth at their pixel and turned its way within 45 degrees.
  int supported_points = 0;
  /// Model points, each, on the scanned surface of their pixel (as above, whatever their
  /// normal).
  int surface_points = 0;

  /// confirmed / (confirmed + contradicted + hidden / 2), in [0, 1]: a hidden pixel
  /// neither confirms nor refutes a pose, but a pose tucked behind other surfaces should
  /// not score as well as one the scan shows (measured: half weight ranked the poses of
  /// single views and clutter best among 0, 1/4, 1/2 and 1).
  double fitness() const;
};

/// The scene's depth image from the sensor origin: one pixel per `pixel` radians, the
/// nearest scene point per pixel, empty pixels filled from their nearest neighbours
/// (missing returns, sparser scans).
class RangeImage {
 public:
  /// `pixel_size`: metres per pixel at the median distance of the scene.
  /// @throws std::invalid_argument if no scene point is in front of `viewpoint`.
  RangeImage(const PointCloud& scene, const Eigen::Vector3d& viewpoint, double pixel_size);

  /// How `check` decides that a model point is on the scanned surface of its pixel.
  enum class Distance {
    depth,         ///< Its depth is within the tolerance of the pixel's.
    along_normal,  ///< Its distance to the plane of the pixel's scan point and normal is:
                   ///< on a surface seen at a slant the depth changes by more than the
                   ///< tolerance across one pixel.
  };

  /// The check of model points with their normals, in scene coordinates; `tolerance`:
  /// distance, metres, within which a model point is on the scanned surface.
  ViewCheck check(const Points& points, const Points& normals, double tolerance,
                  Distance distance = Distance::depth) const;

  /// The scan's depth at p's pixel minus p's own depth from the viewpoint, metres:
  /// negative where the scan saw something nearer (p hidden), +inf where the scan saw
  /// nothing there, NaN outside the image or behind the viewpoint.
  double depth_gap(const Eigen::Vector3d& p) const;

 private:
  struct Pixel {
    int u, v;
    float depth;
    Eigen::Index row;
  };
  bool project(const Eigen::Vector3d& p, Pixel& pixel) const;
  std::size_t index(int u, int v) const {
    return std::size_t(v - v0_) * std::size_t(width_) + std::size_t(u - u0_);
  }

  Eigen::Vector3d viewpoint_;
  Eigen::Matrix3d R_camera_scene_;  // rows: image x, image y, viewing axis
  double angle_ = 0.0;              // radians per pixel
  int u0_ = 0, v0_ = 0, width_ = 0, height_ = 0;
  std::vector<float> depth_;             // +inf where the scan saw nothing
  std::vector<Eigen::Vector3f> normal_;  // of the nearest scan point
  std::vector<Eigen::Vector3f> point_;   // the nearest scan point
  mutable std::vector<Pixel> model_;     // scratch of check()
};

}  // namespace spectral_vs::detail
