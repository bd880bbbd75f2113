#pragma once
/// @file view_aligner.hpp
/// Scene-to-scene registration: two views of one scene (a reference view and the current
/// view of a moving depth camera), registered globally over SO(3) and R^3. This is what
/// direct visual servoing needs (the reference view registered onto every new view) and
/// what a relocalization after a large motion runs. Beyond the paper, whose Algorithm 1
/// is local: the same EGI correlation and phase correlation, searched globally.

#include <spectral_vs/alignment/aligner.hpp>

#include <optional>
#include <vector>

namespace spectral_vs {

/// The scale of a registration: every length that the voxel grids, the search and the
/// checks work at, metres.
struct ViewScale {
  double voxel_size = 0.0;         ///< Voxel of Algorithm 1's grid and of the support check.
  double search_voxel_size = 0.0;  ///< Voxel of the hypotheses' placement grid and ICP.
  double extent = 0.0;  ///< The larger view's typical size: twice the median distance of its
                        ///< points from their per-axis median.
};

/// The scale of two views: `voxel_size = max(extent / voxels_across, 3 extent / sqrt(N))`
/// where `extent` is the larger view's typical size (twice the median distance of its
/// points from their median: where most of a depth camera's points are, not the box of
/// its few far returns) and N the smaller view's points (a surface of N points spans
/// about extent / sqrt(N) between neighbours: a sparse view gets voxels that hold
/// several points). The search voxel is twice the voxel (docs/views.md: the rule and
/// the measurement behind the default of 24 voxels across).
/// @throws std::invalid_argument for an empty view, views of one point, or
///         voxels_across < 4.
ViewScale view_scale(const PointCloud& reference, const PointCloud& current,
                     double voxels_across = 32.0);

/// Settings of `align_views`. Every length defaults to 0: derived from the views by
/// `view_scale` (docs/views.md gives the rule and what it was measured on).
struct ViewAlignParams {
  double voxel_size = 0.0;         ///< Voxel of Algorithm 1 and of the fitness, metres; 0: derived.
  double search_voxel_size = 0.0;  ///< Voxel of the hypotheses' placement, metres; 0: 2 voxels.
  double voxels_across = 32.0;     ///< With voxel_size = 0: voxels across the views' typical size.
  bool downsample = true;          ///< Downsample both views to half a voxel first (PCL VoxelGrid).
  int bandwidth = 16;              ///< B of the EGIs and of the SO(3) search, in [2, 64].
  int hypotheses = 16;             ///< Rotations of the SO(3) search placed and checked, >= 1.
  int refinements = 1;             ///< Best-checked hypotheses refined by Algorithm 1 and the
                                   ///< ICP, in [1, hypotheses]; the best-scored one is kept.
                                   ///< 1: on 120 scan and rendered pairs 3 won none more
                                   ///< (docs/views.md) at 1.5-2 times the time.
  int refinement_iterations = 3;   ///< Iterations of Algorithm 1 per refinement, in [1, 10^4].
  bool icp_refinement = true;      ///< Point-to-plane ICP after Algorithm 1 (pairs within a
                                   ///< voxel, then 0.4 voxel; Gauss-Newton), kept if it does not
                                   ///< lower the score.
  /// The window search runs when the kept pose's score is under this, in [0, 1] (0: never):
  /// the rotation searched again on windows of the current view as large as the reference.
  /// 0.03: on the tuning pairs right poses scored 0.074 or more, the missed ones 0.002-0.003
  /// (docs/views.md, "The window search").
  double window_search_below = 0.03;
  /// The current view's sensor origin in its coordinates: the origin for a depth
  /// camera's cloud in its own frame. The fitness renders the reference from it.
  /// (Named current_viewpoint before 0.2.)
  Eigen::Vector3d sensor_origin = Eigen::Vector3d::Zero();
  double max_seconds = 0.0;  ///< Time budget, seconds (0: none); past it, the best so far,
                             ///< converged = false.
  int threads = 1;           ///< Threads for FFTW and the SO(3) search, in [1, 256].
  Occupancy occupancy = Occupancy::trilinear;
  EgiMethod egi_method = EgiMethod::projection;
  GridLimits limits = {};  ///< Grids over limits.max_voxels are refused before allocation.
};

/// How well the current view supports a pose of the reference: the reference, moved by
/// the pose, rendered from the current view's sensor (its nearest points facing it, in
/// pixels of half a voxel) and each pixel compared with the current view's depth there.
struct ViewSupport {
  int confirmed = 0;         ///< Pixels where the current view has the surface (within one
                             ///< voxel, normals within 45 degrees).
  int contradicted = 0;      ///< Pixels where it saw through the reference's surface, or a
                             ///< surface turned another way.
  int hidden = 0;            ///< Pixels where it saw something nearer.
  int reference_pixels = 0;  ///< Pixels of the reference's own image from its own sensor
                             ///< that the comparison could see (in the current's field).
  /// confirmed / (confirmed + contradicted + hidden / 2), in [0, 1].
  double fitness = 0.0;
  /// confirmed / reference points checked, in [0, 1]: the share of the reference that the
  /// current view shows again (about the views' overlap for a right pose).
  double overlap = 0.0;
  /// fitness x overlap, in [0, 1]: what ranks the hypotheses and the refined poses.
  double score = 0.0;
};

/// Another pose of the reference that the current view supports about as well as the
/// returned one (ViewAlignResult::alternatives).
struct ViewAlternative {
  Transform T_current_reference = Transform::Identity();
  double confidence = 0.0;         ///< As ViewAlignResult::confidence (calibrated), for this pose.
  double score = 0.0;              ///< As ViewAlignResult::score, for this pose.
  double rotation_apart = 0.0;     ///< Rotation from the returned pose, radians.
  double translation_apart = 0.0;  ///< Reference centroid from the returned pose's, metres.
  bool symmetric = false;          ///< The reference maps onto itself by the turn between the two
                                   ///< poses (as AlignAlternative::symmetric): the same answer.
};

/// Where the time of one `align_views` went, by stage, seconds of the wall clock (with
/// threads = 1, its CPU time).
struct ViewAlignTimings {
  /// The scale, both views downsampled, their dominant planes balanced, their EGIs and
  /// correlation, the verification's depth image, the ICP's neighbour grids.
  double preparation = 0.0;
  /// The SO(3) search, its rotations refined, placed by phase correlation, through a short
  /// ICP and checked.
  double hypotheses = 0.0;
  double refinement = 0.0;     ///< Algorithm 1 and the ICP from the prior and the best.
  double window_search = 0.0;  ///< The window search and its refinements (0: it did not run).
  /// The verification of the pose, its alternatives, its covariance and the verdict.
  double verdict = 0.0;
  double total = 0.0;  ///< The whole call.
};

/// Outcome of `align_views`.
struct ViewAlignResult {
  Transform T_current_reference = Transform::Identity();  ///< Maps reference points into the
                                                          ///< current view's coordinates.
  /// The verdict: true when status is Verdict::reliable (confidence at least
  /// kReliableConfidence, no alternative as good, the search finished in time, the voxel
  /// in range). The one field to check before acting on T_current_reference.
  bool reliable = false;
  /// The verdict in one word: reliable, ambiguous, doubtful, no_support (no pose the
  /// search tried is supported: the views share nothing, or too little to find it),
  /// max_seconds (ViewAlignParams::max_seconds ran out: the best pose found in time),
  /// bad_scale (a voxel out of range of the reference's size).
  Verdict status = Verdict::no_support;
  /// The current view pins the pose down: pose_determined of the covariance at the
  /// reference's centroid.
  bool determined = false;
  /// The probability that the pose is right (within 5 degrees and 10 mm; for a room-scale
  /// view, docs/trust.md gives the tolerance), in [0, 1]: `score` calibrated.
  double confidence = 0.0;
  /// The verification's score, uncalibrated, in [0, 1]: confirmed / sqrt(visible x
  /// checked) x support.fitness. `checked` reference points (the prepared reference, at
  /// most 8000 of it) are moved by the pose, `visible` of them face the current's sensor,
  /// lie in its view and not behind what it saw, and `confirmed` of those lie within half
  /// a voxel of the tangent plane of a current point turned the same way: the geometric
  /// mean of the share of what the current view could see that it confirms and of the
  /// share of the reference it confirms. The support's fitness checks the reference's
  /// structure (off its dominant plane) against the current's depth image: a pose that
  /// only lays a table on a table fails it.
  double score = 0.0;
  /// Covariance of the pose error (rotation vector in radians, then translation in metres,
  /// T_true = exp(delta) T_current_reference, current frame); see pose_covariance.
  PoseCovariance covariance = PoseCovariance::Zero();
  /// Other poses (over 5 degrees or a voxel apart) whose score is within 0.05 of this one's,
  /// each refined by the ICP; best first, at most 3.
  std::vector<ViewAlternative> alternatives;
  bool ambiguous = false;  ///< There is an alternative that is not `symmetric`.
  /// Checked reference points within inlier_distance (one voxel) of their nearest current
  /// point; inlier_fraction = inliers / checked points; inlier_rmse their RMS distance.
  int inliers = 0;
  double inlier_fraction = 0.0;
  double inlier_rmse = 0.0;      ///< Metres.
  double inlier_distance = 0.0;  ///< Metres.
  /// The search ran to its end (every hypothesis and refinement within max_seconds). Says
  /// nothing of whether the pose is right: `reliable` does.
  bool converged = false;
  ViewSupport support;       ///< The depth-image support of the returned pose (what ranks
                             ///< the hypotheses).
  double correlation = 0.0;  ///< Normalised EGI correlation at the returned rotation.
  ViewScale scale;           ///< The scale it worked at.
  int hypothesis = 0;        ///< Index of the kept hypothesis (the search's, best correlated
                             ///< first, then the window search's); -1: the prior pose given
                             ///< to align_views.
  int icp_iterations = 0;    ///< ICP steps of the kept pose (0 without, or not kept).
  int windows = 0;           ///< Windows the window search checked (0: it did not run).
  /// The checked hypotheses, best score first: T_current_reference and support.
  std::vector<std::pair<Transform, ViewSupport>> hypotheses;
  ViewAlignTimings timings;  ///< Where the time went, by stage.
};

/// The support of a given pose, as `align_views` scores its refined poses: the views
/// prepared (downsampled, balanced) at the scale of `params`, depths within a quarter of
/// a voxel. For the confidence of a pose found otherwise (the servo's tracking).
/// @throws std::invalid_argument as `align_views`, or for a pose that is not rigid.
ViewSupport view_support(const PointCloud& reference, const PointCloud& current,
                         const Transform& T_current_reference, const ViewAlignParams& params = {});

/// Registers `reference` onto `current`, two views of one scene, both with normals
/// (toward their sensors): the returned T_current_reference moves the reference's points
/// onto the same surfaces in the current view. Global over rotation (the SO(3) search of
/// the views' EGIs) and translation (phase correlation over both views), each of the
/// best-supported hypotheses refined by Algorithm 1 on the views and a point-to-plane ICP.
/// When the kept pose's score is under `window_search_below` (the search missed: the
/// current view's EGI is mostly surfaces the reference never saw), the rotation is
/// searched again on windows of the current view as large as the reference, each placed
/// on a small grid around its window, and the 3 best of those refined too.
/// Views that share no surface are not an error: status says no_support.
/// A `prior` (a pose known from elsewhere, e.g. a tracker's estimate) is refined and
/// scored beside the search's best hypotheses, as one more of them: the result is the
/// prior's refinement (`hypothesis` -1) unless a searched pose is better supported. A
/// relocalization thus never replaces a right estimate by a worse-supported one.
/// @throws std::invalid_argument for an empty view, missing normals, non-finite or
///         out-of-range settings, a grid over params.limits, a current view with no
///         point in front of sensor_origin, or a prior that is not rigid.
ViewAlignResult align_views(const PointCloud& reference, const PointCloud& current,
                            const ViewAlignParams& params = {},
                            const std::optional<Transform>& prior = std::nullopt);

}  // namespace spectral_vs
