#include "alignment/verifier.hpp"
#include "alignment/normal_directions.hpp"

#include <spectral_vs/alignment/verdict.hpp>

#include "common/checks.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

Eigen::AlignedBox3d grown_box(const PointCloud& scene, double margin) {
  Eigen::AlignedBox3d box = bounding_box(scene);
  box.min().array() -= margin;
  box.max().array() += margin;
  return box;
}

}  // namespace

// Pixels of the verification's range image, in voxels: coarser than the screen's
// half-voxel ones, so that a sparse real scan (about one point per voxel) leaves no holes
// that a model point would be seen through.
constexpr double kPixelVoxels = 1.0;
// Pixels of the screen's range image, in voxels: a model point a voxel in front of or
// behind the scan is resolved.
constexpr double kScreenPixelVoxels = 0.5;

Verifier::Verifier(const PointCloud& scene, double voxel_size,
                   const std::optional<Eigen::Vector3d>& viewpoint,
                   const std::optional<GridSpec>& screen, FitnessMap::Coverage coverage)
    : scene_(&scene),
      voxel_size_(voxel_size),
      viewpoint_(viewpoint),
      screen_spec_(screen),
      coverage_(coverage) {}

double Verifier::fitness(const Points& points, const Points& normals, double tolerance) const {
  if (viewpoint_) return check(points, normals, tolerance).fitness();
  if (!screen_spec_) fail("Verifier: a voxel screen needs its grid (screen)");
  if (!map_) {
    map_.emplace();
    map_->set_scene(*scene_, *screen_spec_, coverage_);
  }
  return map_->fitness(points, normals);
}

ViewCheck Verifier::check(const Points& points, const Points& normals, double tolerance,
                          RangeImage::Distance distance) const {
  return screen_image().check(points, normals, tolerance, distance);
}

const RangeImage& Verifier::screen_image() const {
  if (!viewpoint_) fail("Verifier: a pixel check needs the scene's viewpoint");
  if (!screen_image_) screen_image_.emplace(*scene_, *viewpoint_, kScreenPixelVoxels * voxel_size_);
  return *screen_image_;
}

const RangeImage& Verifier::verify_image() const {
  if (!verify_image_) verify_image_.emplace(*scene_, *viewpoint_, kPixelVoxels * voxel_size_);
  return *verify_image_;
}

const IcpScene& Verifier::grid() const {
  if (!grid_)
    grid_.emplace(*scene_, grown_box(*scene_, kVisibilityVoxels * voxel_size_),
                  kVisibilityVoxels * voxel_size_);
  return *grid_;
}

const IcpScene& Verifier::fine_grid() const {
  if (!fine_grid_)
    fine_grid_.emplace(*scene_, grown_box(*scene_, kVisibilityVoxels * voxel_size_),
                       kInlierVoxels * voxel_size_);
  return *fine_grid_;
}

PoseVerification Verifier::verify(const PointCloud& model, const Transform& T) const {
  PoseVerification v;
  v.inlier_distance = kInlierVoxels * voxel_size_;
  const double tight = kTightVoxels * voxel_size_;
  const double margin = kVisibilityVoxels * voxel_size_;
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  const IcpScene& grid = this->grid();
  const IcpScene& fine_grid = this->fine_grid();
  const RangeImage* view = viewpoint_ ? &verify_image() : nullptr;
  const Points& scene_points = grid.cloud().points();
  const Points& scene_normals = grid.cloud().normals();
  double squared_sum = 0.0;
  const Eigen::Index n = model.points().rows();
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
    const Eigen::Vector3d normal = R * model.normals().row(i).transpose();
    const Eigen::Index nearest = fine_grid.nearest(p, normal, v.inlier_distance, -2.0);
    double distance = INFINITY;
    if (nearest >= 0) {
      distance = (scene_points.row(nearest).transpose() - p).norm();
      ++v.inliers;
      squared_sum += distance * distance;
    }
    bool visible = true;
    double gap = 0.0;
    if (view) {
      gap = view->depth_gap(p);
      const bool facing = normal.dot(*viewpoint_ - p) > 0.0 && !std::isnan(gap);
      visible = facing && gap >= -margin;
      if (facing && !visible) ++v.hidden;
    }
    if (!visible) continue;
    ++v.visible;
    if (gap > margin && distance > v.inlier_distance) ++v.seen_through;
    // Point to plane: two samplings of one surface are half a sample spacing apart along
    // it, not across it.
    const Eigen::Index agreeing = grid.nearest(p, normal, margin, kAgreeingCosine);
    if (agreeing >= 0 && std::abs(scene_normals.row(agreeing).dot(
                             p - scene_points.row(agreeing).transpose())) <= tight)
      ++v.tight;
  }
  v.inlier_rmse = v.inliers ? std::sqrt(squared_sum / double(v.inliers)) : 0.0;
  v.inlier_fraction = n ? double(v.inliers) / double(n) : 0.0;
  v.confidence = confidence_of(v);
  return v;
}

void set_verification(AlignResult& result, const PoseVerification& v) {
  result.confidence = v.confidence;
  result.inliers = v.inliers;
  result.inlier_rmse = v.inlier_rmse;
  result.inlier_distance = v.inlier_distance;
}

}  // namespace spectral_vs::detail

namespace spectral_vs {

double confidence_of(const PoseVerification& v) {
  if (v.visible == 0) return 0.0;
  const double visible = double(v.visible);
  return std::clamp(double(v.tight) / visible * (1.0 - double(v.seen_through) / visible), 0.0, 1.0);
}

double field_share(const Points& reference_points, const Transform& T_current_reference,
                   const Points& current_points, double max_depth) {
  if (!reference_points.allFinite()) detail::fail("reference_points must be finite");
  if (!current_points.allFinite()) detail::fail("current_points must be finite");
  require_rigid_transform(T_current_reference, "T_current_reference");
  if (!(max_depth > 0.0)) detail::fail("max_depth must be > 0, got ", max_depth);
  // The current view's field: the bounds of its returns' x/z and y/z, from an even
  // stride of them.
  constexpr Eigen::Index kFieldPoints = 4000;
  constexpr double kNear = 1e-3;  // metres: the least depth of a point in front
  if (reference_points.rows() == 0 || current_points.rows() == 0) return 0.0;
  const Eigen::Index stride = std::max<Eigen::Index>(1, current_points.rows() / kFieldPoints);
  double u_low = INFINITY, u_high = -INFINITY, v_low = INFINITY, v_high = -INFINITY;
  bool any = false;
  for (Eigen::Index i = 0; i < current_points.rows(); i += stride) {
    const double z = current_points(i, 2);
    if (!(z > kNear)) continue;
    const double u = current_points(i, 0) / z, v = current_points(i, 1) / z;
    u_low = std::min(u_low, u);
    u_high = std::max(u_high, u);
    v_low = std::min(v_low, v);
    v_high = std::max(v_high, v);
    any = true;
  }
  if (!any) return 0.0;
  const Eigen::Matrix3d R = T_current_reference.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T_current_reference.topRightCorner<3, 1>();
  Eigen::Index inside = 0;
  for (Eigen::Index i = 0; i < reference_points.rows(); ++i) {
    const Eigen::Vector3d p = R * reference_points.row(i).transpose() + t;
    if (!(p.z() > kNear && p.z() <= max_depth)) continue;
    const double u = p.x() / p.z(), v = p.y() / p.z();
    inside += u >= u_low && u <= u_high && v >= v_low && v <= v_high;
  }
  return double(inside) / double(reference_points.rows());
}

StepScore step_score(double visible_fitness, bool carried, const Points& reference_points,
                     const Transform& T_current_reference, const Points& current_points,
                     const StepScoreParams& params) {
  // A NaN fitness would pass for a perfect one (min(1, NaN) is 1).
  if (!(visible_fitness >= 0.0 && visible_fitness <= 1.0))
    detail::fail("visible_fitness must be in [0, 1], got ", visible_fitness);
  if (!(params.relocalize_fitness >= 0.0 && params.relocalize_fitness <= 1.0))
    detail::fail("relocalize_fitness must be in [0, 1], got ", params.relocalize_fitness);
  if (!(params.min_field_share > 0.0 && params.min_field_share <= 1.0))
    detail::fail("min_field_share must be in (0, 1], got ", params.min_field_share);
  StepScore out;
  out.score = visible_fitness;
  if (step_score_needs_field(visible_fitness, params)) {
    const double share =
        field_share(reference_points, T_current_reference, current_points, params.max_depth);
    out.score = std::min(1.0, visible_fitness / std::max(share, params.min_field_share));
  }
  out.confidence = calibrated_confidence(
      out.score, carried ? RegistrationKind::servo_carried : RegistrationKind::servo_step);
  return out;
}

PoseVerification verify_pose(const PointCloud& model, const PointCloud& scene,
                             const Transform& T_scene_model, const VerifyParams& params) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  detail::require_positive_finite(params.voxel_size, "voxel_size");
  require_rigid_transform(T_scene_model, "T_scene_model");
  if (params.viewpoint && !params.viewpoint->allFinite()) detail::fail("viewpoint must be finite");
  const detail::Verifier verifier(scene, params.voxel_size, params.viewpoint);
  return verifier.verify(model, T_scene_model);
}

}  // namespace spectral_vs
