#pragma once
// Internal to align(): how an object rests on the scene's support plane. An object on a
// table rests on it, or on another object, with a flat face of its hull down. In clutter
// a flat model fits as well on a face of a larger object, its other faces hidden inside
// that object and nothing under them; and a thin box standing on its edge shows the
// sensor little more than that edge, whose normals the depth edges blur, so that its EGI
// does not tell its rotation, where its resting face and the table do, up to a turn about
// the table's normal.

#include <spectral_vs/representation/point_cloud.hpp>

#include "alignment/icp_refinement.hpp"
#include "alignment/stages.hpp"
#include "alignment/support_plane.hpp"

#include <Eigen/Core>
#include <optional>
#include <vector>

namespace spectral_vs::detail {

/// The outward unit normals (model frame) of the model's flat faces on its hull, largest
/// first: each a set of at least kMinRestingShare of the model's points (of about
/// kFacePoints of them at most, evenly strided) within `tolerance` metres of a
/// supporting plane of the model, their normals within kRestingNormalDeg of the plane's.
std::vector<Eigen::Vector3d> resting_faces(const PointCloud& model, double tolerance);

/// The rotations that rest the model on `face` (model frame) on a plane of upward normal
/// `up` (scene frame): the face's normal turned onto -up, then `turns` turns about `up`.
std::vector<Eigen::Matrix3d> resting_rotations(const Eigen::Vector3d& face,
                                               const Eigen::Vector3d& up, int turns);

/// Whether a pose rests: its lowest point within kRestingGap voxels of the support plane,
/// or at least kSupportedShare of its lowest points (within a voxel of the lowest) on
/// an upward-facing scene surface (within kRestingGap voxels, at most half a voxel above
/// them). A pose sunk into the plane by more than kRestingGap voxels does not rest.
class RestingCheck {
 public:
  /// `scene` must outlive the check.
  RestingCheck(const PointCloud& scene, const SupportPlane& plane, double voxel_size);
  bool rests(const PointCloud& model, const Transform& T_scene_model) const;

 private:
  // The scene's upward-facing points in cells, made at the first pose that is not on the
  // plane (most returned poses are: then nothing is made); none if there are none.
  const IcpScene* upward() const;

  const PointCloud& scene_;
  SupportPlane plane_;
  double voxel_size_;
  mutable bool upward_built_ = false;
  mutable PointCloud upward_points_;        // the scene's points whose normals face up
  mutable std::optional<IcpScene> upward_;  // ... sorted into cells
};

/// Poses resting on `plane` at each part of `scene` (rows of it): per part, the model on
/// each resting face, turned every 360 / kRestingTurns degrees about the plane's normal,
/// placed at the part (its side facing the sensor at the part's centroid) and on the
/// plane; the `per_part` fittest distinct ones, fittest first over all parts.
std::vector<Transform> resting_poses(const Problem& problem, const PointCloud& scene,
                                     const std::vector<std::vector<Eigen::Index>>& parts,
                                     const SupportPlane& plane, int per_part);

}  // namespace spectral_vs::detail
