#pragma once
/// @file verification.hpp
/// Beyond the paper: how far a scene supports a model pose, in quantities with a stated
/// meaning (inliers, their RMSE, the share of what the sensor would see that it saw), and
/// the confidence that the pose is right, chosen to separate right from wrong poses
/// (docs/experiments.md, "Confidence").

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <limits>
#include <optional>

namespace spectral_vs {

/// Settings of `verify_pose`.
struct VerifyParams {
  /// The alignment's voxel edge, metres (AlignParams::scene.voxel_size): the inlier distance is
  /// kInlierVoxels of it, the tight distance kTightVoxels.
  double voxel_size = 0.008;
  /// The sensor origin of a single-view scene, scene coordinates, metres: the model
  /// points the sensor would see from there are the ones checked. Unset for a scene seen
  /// from all sides: every model point is.
  std::optional<Eigen::Vector3d> viewpoint;
};

/// Inlier distance, in voxels: a model point within this of its nearest scene point.
inline constexpr double kInlierVoxels = 1.0;
/// Tight distance, in voxels: what a right pose reaches, refined, on a real scan's noise
/// (at a quarter voxel, right poses of the real bunny scan kept a confidence of 0.6).
inline constexpr double kTightVoxels = 0.5;
/// Visibility margin, in voxels: a model point more than this behind the scanned
/// surface is hidden, more than this in front of it seen through; and the radius in
/// which its scene neighbour for `tight` is sought.
inline constexpr double kVisibilityVoxels = 2.0;

/// The scene's support of one pose, every count over model points moved by the pose.
struct PoseVerification {
  double inlier_distance = 0.0;  ///< d = kInlierVoxels * voxel_size, metres.
  /// Model points whose nearest scene point is within d (Euclidean, normals ignored).
  int inliers = 0;
  /// Root mean square of those nearest distances over the inliers, metres (0 with none).
  double inlier_rmse = 0.0;
  /// inliers / model points, in [0, 1]: Open3D's `fitness` with max distance d.
  double inlier_fraction = 0.0;
  /// Model points the sensor would see: with a viewpoint, the ones facing it, in its view
  /// and not more than kVisibilityVoxels voxels behind the scanned surface (a range image
  /// of one-voxel pixels); without, all of them.
  int visible = 0;
  /// Of the visible points: within kTightVoxels * voxel_size of the tangent plane of
  /// their nearest scene point within kVisibilityVoxels voxels whose normal is within 45
  /// degrees of theirs.
  int tight = 0;
  /// Of the visible points: more than kVisibilityVoxels voxels in front of the scanned
  /// surface and no inlier, where the sensor saw through them (0 without a viewpoint).
  int seen_through = 0;
  /// Model points facing the viewpoint, in its view, more than kVisibilityVoxels voxels
  /// behind the scanned surface (0 without a viewpoint): neither confirmed nor refuted.
  int hidden = 0;
  /// The confidence that the pose is right, in [0, 1] (see `confidence_of`).
  double confidence = 0.0;
};

/// The confidence of a verified pose, in [0, 1]: tight / visible, times one minus the
/// share of visible points the sensor saw through: the share of what the sensor would
/// see of the model that it saw, where the model is, turned the same way.
double confidence_of(const PoseVerification& verification);

/// The share of `reference_points` that `T_current_reference` puts inside the field of the
/// current view, seen from its own origin (`current_points`, its frame: z forward): in
/// front of the sensor (z over 1 mm), no deeper than `max_depth`, and within the bounds of
/// the current points in x/z and y/z (a pinhole camera's image as far as it has returns; at
/// most 4000 of them, evenly strided, bound it). Occlusion is ignored. In [0, 1]; 0 for no
/// reference point or no current point in front. The servo divides its tracking fitness
/// by it: a fit of what little of the reference is left in view is no sign of a right pose.
/// @throws std::invalid_argument for non-finite points, a T that is not rigid or a
///         max_depth that is not > 0.
double field_share(const Points& reference_points, const Transform& T_current_reference,
                   const Points& current_points, double max_depth);

/// How the servo judges one step's estimate (ServoRecord's score and confidence).
struct StepScoreParams {
  /// From this visible fitness up the score is the fitness itself; under it, the fitness
  /// over the share of the reference in the field (ServoParams.relocalize_fitness).
  double relocalize_fitness = 0.8;
  /// That share counts as at least this: the extreme starts keep 30% of the reference in
  /// the field.
  double min_field_share = 0.3;
  /// The field's depth (field_share), metres.
  double max_depth = std::numeric_limits<double>::infinity();
};

/// A servo step's score, in [0, 1], and its calibrated confidence.
struct StepScore {
  double score = 0.0;
  double confidence = 0.0;
};

/// Whether step_score reads the field: a visible fitness under relocalize_fitness.
inline bool step_score_needs_field(double visible_fitness, const StepScoreParams& params) {
  return !(visible_fitness >= params.relocalize_fitness);
}

/// The servo's judgement of a step's estimate T_current_reference from the registration's
/// fitness over the reference's part no occluder hides (`visible_fitness`, in [0, 1]):
/// that fitness from params.relocalize_fitness up; under it, the fitness over the share of
/// `reference_points` that the estimate puts in the field of `current_points` (field_share,
/// at least params.min_field_share), at most 1: a fit of what little of the reference is
/// left in view is no sign of a right pose. The confidence is calibrated_confidence of the
/// score, by the map of a registered estimate, or of one `carried` along the odometry.
/// Reads neither cloud when the fitness needs no field (step_score_needs_field).
/// @throws std::invalid_argument for a visible_fitness or relocalize_fitness outside
///         [0, 1], a min_field_share outside (0, 1], and as field_share when it reads the
///         field.
StepScore step_score(double visible_fitness, bool carried, const Points& reference_points,
                     const Transform& T_current_reference, const Points& current_points,
                     const StepScoreParams& params = {});

/// The scene's support of the model at T_scene_model (see PoseVerification).
/// @throws std::invalid_argument for an empty cloud, missing normals, a voxel_size that
///         is not finite and > 0, a non-finite viewpoint or a T that is not rigid.
PoseVerification verify_pose(const PointCloud& model, const PointCloud& scene,
                             const Transform& T_scene_model, const VerifyParams& params = {});

}  // namespace spectral_vs
