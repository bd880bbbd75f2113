#include "alignment/range_image.hpp"

#include "alignment/normal_directions.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace spectral_vs::detail {

namespace {

constexpr double kMaxPixels = 4194304.0;  // 2^22: a 2048 x 2048 image at most
constexpr double kMaxSlope = 3.0;         // rays up to about 72 degrees off the axis
constexpr float kNothing = std::numeric_limits<float>::infinity();  // a pixel seen empty
// With Distance::along_normal, the largest depth difference of a point on the surface, in
// tolerances: a surface at 75 degrees to the ray changes its depth by about 4 tolerances
// across a pixel of 2 (the support check's half-voxel pixels at a quarter-voxel tolerance).
constexpr double kSlantDepth = 4.0;

// The camera's rows: x and y of the image, then the viewing axis toward `target`.
Eigen::Matrix3d look_at(const Eigen::Vector3d& viewpoint, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - viewpoint).normalized();
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-6) x = z.cross(Eigen::Vector3d::UnitX());
  x.normalize();
  Eigen::Matrix3d R;
  R.row(0) = x;
  R.row(1) = z.cross(x);
  R.row(2) = z;
  return R;
}

}  // namespace

double ViewCheck::fitness() const {
  const double weighed = double(confirmed) + double(contradicted) + 0.5 * double(hidden);
  return weighed > 0.0 ? double(confirmed) / weighed : 0.0;
}

RangeImage::RangeImage(const PointCloud& cloud, const Eigen::Vector3d& viewpoint, double pixel_size)
    : viewpoint_(viewpoint) {
  const Points& scene = cloud.points();
  const Eigen::Vector3d centroid = scene.colwise().mean().transpose();
  if ((centroid - viewpoint).norm() < 1e-9)
    fail("sensor_origin: the sensor is at the scene's centroid");
  R_camera_scene_ = look_at(viewpoint, centroid);
  std::vector<double> depths;
  double lo[2] = {kMaxSlope, kMaxSlope}, hi[2] = {-kMaxSlope, -kMaxSlope};
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    const Eigen::Vector3d c = R_camera_scene_ * (scene.row(i).transpose() - viewpoint);
    if (c.z() <= 1e-6 || std::abs(c.x()) > kMaxSlope * c.z() || std::abs(c.y()) > kMaxSlope * c.z())
      continue;
    depths.push_back(c.z());
    for (int a = 0; a < 2; ++a) {
      lo[a] = std::min(lo[a], c[a] / c.z());
      hi[a] = std::max(hi[a], c[a] / c.z());
    }
  }
  if (depths.empty()) fail("sensor_origin: no scene point is in front of the sensor");
  std::nth_element(depths.begin(), depths.begin() + std::ptrdiff_t(depths.size() / 2),
                   depths.end());
  angle_ = pixel_size / depths[depths.size() / 2];
  angle_ = std::max(angle_, std::sqrt((hi[0] - lo[0]) * (hi[1] - lo[1]) / kMaxPixels));
  u0_ = int(std::floor(lo[0] / angle_)) - 1;
  v0_ = int(std::floor(lo[1] / angle_)) - 1;
  width_ = int(std::floor(hi[0] / angle_)) + 2 - u0_;
  height_ = int(std::floor(hi[1] / angle_)) + 2 - v0_;

  std::vector<float> nearest(std::size_t(width_) * std::size_t(height_), kNothing);
  std::vector<Eigen::Index> row_of(nearest.size(), -1);
  Pixel pixel;
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    if (!project(scene.row(i).transpose(), pixel)) continue;
    const std::size_t k = index(pixel.u, pixel.v);
    if (pixel.depth < nearest[k]) {
      nearest[k] = pixel.depth;
      row_of[k] = i;
    }
  }
  // A pixel the scan left empty takes its nearest neighbour's: at half a voxel per pixel,
  // a scan sparser than the pixels, or a missing return, is not a look through.
  depth_ = nearest;
  std::vector<Eigen::Index> filled = row_of;
  for (int v = v0_ + 1; v + 1 < v0_ + height_; ++v) {
    for (int u = u0_ + 1; u + 1 < u0_ + width_; ++u) {
      const std::size_t k = index(u, v);
      if (row_of[k] >= 0) continue;
      for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du) {
          const std::size_t n = index(u + du, v + dv);
          if (nearest[n] < depth_[k]) {
            depth_[k] = nearest[n];
            filled[k] = row_of[n];
          }
        }
    }
  }
  normal_.assign(depth_.size(), Eigen::Vector3f::Zero());
  point_.assign(depth_.size(), Eigen::Vector3f::Zero());
  for (std::size_t k = 0; k < depth_.size(); ++k) {
    if (filled[k] < 0) continue;
    normal_[k] = cloud.normals().row(filled[k]).transpose().cast<float>();
    point_[k] = scene.row(filled[k]).transpose().cast<float>();
  }
}

bool RangeImage::project(const Eigen::Vector3d& p, Pixel& pixel) const {
  const Eigen::Vector3d c = R_camera_scene_ * (p - viewpoint_);
  if (!(c.z() > 1e-6)) return false;
  const double x = std::floor(c.x() / c.z() / angle_), y = std::floor(c.y() / c.z() / angle_);
  if (!(x >= u0_ && x < u0_ + width_ && y >= v0_ && y < v0_ + height_)) return false;
  pixel = {int(x), int(y), float(c.z()), -1};
  return true;
}

double RangeImage::depth_gap(const Eigen::Vector3d& p) const {
  Pixel pixel;
  if (!project(p, pixel)) return std::numeric_limits<double>::quiet_NaN();
  return double(depth_[index(pixel.u, pixel.v)]) - double(pixel.depth);
}

ViewCheck RangeImage::check(const Points& points, const Points& normals, double tolerance,
                            Distance distance) const {
  model_.clear();
  Pixel pixel;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = points.row(i).transpose();
    if (normals.row(i).dot(viewpoint_ - p) <= 0.0) continue;  // facing away: not seen
    if (!project(p, pixel)) continue;
    pixel.row = i;
    model_.push_back(pixel);
  }
  // The model's own depth image: its nearest point per pixel.
  std::sort(model_.begin(), model_.end(), [](const Pixel& a, const Pixel& b) {
    return a.v != b.v ? a.v < b.v : a.u != b.u ? a.u < b.u : a.depth < b.depth;
  });
  const float turned = float(kAgreeingCosine);
  ViewCheck result;
  for (std::size_t i = 0; i < model_.size(); ++i) {
    const std::size_t k = index(model_[i].u, model_[i].v);
    const double scanned = depth_[k], depth = model_[i].depth;
    const bool on_surface =
        distance == Distance::depth
            ? std::abs(scanned - depth) <= tolerance
            : std::abs(scanned - depth) <= kSlantDepth * tolerance &&
                  std::abs(normal_[k].dot(points.row(model_[i].row).transpose().cast<float>() -
                                          point_[k])) <= tolerance;
    const bool same_way =
        on_surface && normal_[k].dot(normals.row(model_[i].row).transpose().cast<float>()) > turned;
    if (on_surface) ++result.surface_points;
    if (same_way) ++result.supported_points;
    if (i > 0 && model_[i].u == model_[i - 1].u && model_[i].v == model_[i - 1].v) continue;
    if (on_surface) {
      ++(same_way ? result.confirmed : result.contradicted);
    } else if (scanned > depth) {
      ++result.contradicted;
    } else {
      ++result.hidden;
    }
  }
  return result;
}

}  // namespace spectral_vs::detail
