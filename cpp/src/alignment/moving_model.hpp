#pragma once
// Internal to the aligner: the model as Algorithm 1 moves it, shared by align() and
// ModelAligner.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>

namespace spectral_vs::detail {

/// The model's pose as a rotation about its centroid c and a translation of it:
/// x_scene = R (x_model - c) + c + offset.
struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
};

/// The model as Algorithm 1 moves it, rotating about its centroid. Its points and
/// normals at a pose are written into buffers kept between calls.
class MovingModel {
 public:
  explicit MovingModel(const PointCloud& model)
      : centroid_(model.centroid()),
        centred_(model.points().rowwise() - centroid_.transpose()),
        normals_(model.normals()) {
    reach_ = centred_.rowwise().norm().maxCoeff();
  }

  /// The largest distance of a model point from the centroid, metres.
  double reach() const { return reach_; }
  const Eigen::Vector3d& centroid() const { return centroid_; }
  Eigen::Vector3d centre(const Pose& pose) const { return centroid_ + pose.offset; }

  /// Where the centroid of the model's side facing `direction` (a viewing ray) is, from
  /// the model's centroid, with the model turned by R: a single view shows that side.
  Eigen::Vector3d facing_side(const Eigen::Matrix3d& R, const Eigen::Vector3d& direction) const {
    const Eigen::Vector3d local = R.transpose() * direction;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    for (Eigen::Index i = 0; i < centred_.rows(); ++i) {
      if (normals_.row(i).dot(local) < 0.0) {
        sum += centred_.row(i).transpose();
        ++count;
      }
    }
    return count ? Eigen::Vector3d(R * sum / double(count)) : Eigen::Vector3d::Zero();
  }

  Pose pose_of(const Transform& T_scene_model) const {
    Pose pose;
    pose.R = T_scene_model.topLeftCorner<3, 3>();
    pose.offset = T_scene_model.topRightCorner<3, 1>() + pose.R * centroid_ - centroid_;
    return pose;
  }

  Transform transform_of(const Pose& pose) const {
    Transform T = Transform::Identity();
    T.topLeftCorner<3, 3>() = pose.R;
    T.topRightCorner<3, 1>() = centroid_ + pose.offset - pose.R * centroid_;
    return T;
  }

  /// The model as it was given (points and normals).
  PointCloud cloud() const {
    return PointCloud(Points(centred_.rowwise() + centroid_.transpose()), normals_);
  }

  /// The model's points at `pose`, in the scene (valid until the next call).
  const Points& move(const Pose& pose) {
    moved_.noalias() = centred_ * pose.R.transpose();
    moved_.rowwise() += centre(pose).transpose();
    return moved_;
  }

  /// The model's normals at `pose` (valid until the next call).
  const Points& turned_normals(const Pose& pose) {
    moved_normals_.noalias() = normals_ * pose.R.transpose();
    return moved_normals_;
  }

 private:
  Eigen::Vector3d centroid_;
  Points centred_;
  Points normals_;
  Points moved_, moved_normals_;
  double reach_ = 0.0;
};

}  // namespace spectral_vs::detail
