#include "alignment/verifier.hpp"

#include "common/checks.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

// Pairs for `tight` agree in normal within 45 degrees: a surface turned another way (the
// other side of a thin part, a flip onto a parallel face) is no support.
constexpr double kTightCosine = 0.7071;

Eigen::AlignedBox3d grown_box(const PointCloud& scene, double margin) {
  Eigen::AlignedBox3d box = bounding_box(scene);
  box.min().array() -= margin;
  box.max().array() += margin;
  return box;
}

}  // namespace

// Pixels of the verifier's range image, in voxels: coarser than the aligner's half-voxel
// ones, so that a sparse real scan (about one point per voxel) leaves no holes that a
// model point would be seen through.
constexpr double kPixelVoxels = 1.0;

Verifier::Verifier(const PointCloud& scene, double voxel_size,
                   const std::optional<Eigen::Vector3d>& viewpoint)
    : voxel_size_(voxel_size),
      grid_(scene, grown_box(scene, kVisibilityVoxels * voxel_size),
            kVisibilityVoxels * voxel_size),
      fine_grid_(scene, grown_box(scene, kVisibilityVoxels * voxel_size),
                 kInlierVoxels * voxel_size) {
  if (viewpoint) view_.emplace(scene, *viewpoint, kPixelVoxels * voxel_size);
}

PoseVerification Verifier::verify(const PointCloud& model, const Transform& T) const {
  PoseVerification v;
  v.inlier_distance = kInlierVoxels * voxel_size_;
  const double tight = kTightVoxels * voxel_size_;
  const double margin = kVisibilityVoxels * voxel_size_;
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  const Points& scene_points = grid_.cloud().points();
  const Points& scene_normals = grid_.cloud().normals();
  double squared_sum = 0.0;
  const Eigen::Index n = model.points().rows();
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
    const Eigen::Vector3d normal = R * model.normals().row(i).transpose();
    const Eigen::Index nearest = fine_grid_.nearest(p, normal, v.inlier_distance, -2.0);
    double distance = INFINITY;
    if (nearest >= 0) {
      distance = (scene_points.row(nearest).transpose() - p).norm();
      ++v.inliers;
      squared_sum += distance * distance;
    }
    bool visible = true;
    double gap = 0.0;
    if (view_) {
      gap = view_->depth_gap(p);
      const bool facing = normal.dot(view_->viewpoint() - p) > 0.0 && !std::isnan(gap);
      visible = facing && gap >= -margin;
      if (facing && !visible) ++v.hidden;
    }
    if (!visible) continue;
    ++v.visible;
    if (gap > margin && distance > v.inlier_distance) ++v.seen_through;
    // Point to plane: two samplings of one surface are half a sample spacing apart along
    // it, not across it.
    const Eigen::Index agreeing = grid_.nearest(p, normal, margin, kTightCosine);
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
