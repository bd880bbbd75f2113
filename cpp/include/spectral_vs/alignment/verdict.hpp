#pragma once
/// @file verdict.hpp
/// Beyond the paper: the one verdict every registration carries (AlignResult,
/// ViewAlignResult, the servo's steps). The verification's score (verification.hpp) is
/// calibrated into a probability that the answer is right, read against one threshold,
/// and named in one word; the pose's covariance says how far off a right answer may be.
/// docs/trust.md ("Can I trust this answer?") gives the measurements behind each number.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>

namespace spectral_vs {

/// What an answer is worth, in one word: `reliable` is the only one to act on.
enum class Verdict {
  reliable,      ///< Confident (confidence >= kReliableConfidence) and no other pose fits as well.
  ambiguous,     ///< Confident, but another pose (an alternative) fits about as well.
  doubtful,      ///< The scene supports the pose too little to be confident.
  undetermined,  ///< The scene supports the pose but leaves a direction free (a plane on a
                 ///< plane): pose_determined fails.
  floating,      ///< In a scene with a support plane, the pose neither rests on it nor
                 ///< stands on an upward-facing surface: a flat object flush with another
                 ///< object's face, the rest of it inside that object (AlignResult::rests).
  no_support,    ///< No point of the answer is supported by the scene (nothing shared).
  max_seconds,   ///< The time budget ran out: the best pose found in time, not judged.
  bad_scale,     ///< The voxel is outside [kMinVoxelShare, kMaxVoxelShare] of the model's
                 ///< typical size (or the model has none: one point): no answer at that
                 ///< scale can be trusted.
  unverified,    ///< The verification was turned off (AlignParams::verification.verify):
                 ///< nothing was checked, nothing is claimed.
};

/// What was registered: the calibration of the score differs between the two.
enum class RegistrationKind {
  model_to_scene,  ///< align(), ModelAligner: an object model onto a scan or a scene.
  view_to_view,    ///< align_views(): two depth views of one scene.
  servo_step,      ///< One step of the servo whose estimate is the registration's, scored
                   ///< by its fitness (Python: ServoRecord.score). No covariance.
  servo_carried,   ///< One step of the servo whose estimate is the last one carried along
                   ///< the camera's measured motion (ServoRecord.carried): the score is the
                   ///< registration's, which the estimate did not take. No covariance.
};

/// Covariance of a pose's error, 6 x 6: the rotation vector (radians) then the translation
/// (metres) of a left perturbation, T_true = exp(delta) T_estimated, in the scene's (the
/// current view's) frame.
using PoseCovariance = Eigen::Matrix<double, 6, 6>;

/// A calibrated confidence at or above this, with no alternative as good, is `reliable`:
/// chosen on the calibration set so that at most 1% of reliable answers are wrong there
/// (docs/trust.md, "The threshold").
inline constexpr double kReliableConfidence = 0.9;

/// A voxel over this share of the model's (the reference's) typical size leaves too few
/// voxels across it to tell its turns apart (a 10 cm object at 0.3 m voxels).
inline constexpr double kMaxVoxelShare = 0.5;
/// A voxel under this share of it is a unit slip (millimetres taken as metres the other
/// way): the grids would hold millions of voxels per object.
inline constexpr double kMinVoxelShare = 1e-3;

/// An alternative whose turn from the returned pose maps the model onto itself with a
/// score of at least this (verify_pose of the model against itself, seen from all
/// sides) is the same answer up to the object's symmetry (a box turned half a turn).
/// docs/trust.md gives the measurement.
inline constexpr double kSymmetricSelfFit = 0.95;

/// The probability that an answer of verification score `score` (in [0, 1]) is right:
/// a monotone, piecewise-linear map fitted on the calibration set (isotonic regression of
/// right against score, benchmarks/verdict_benchmark.py), one per kind. In [0, 1].
double calibrated_confidence(double score, RegistrationKind kind);

/// Whether `voxel_size` is within [kMinVoxelShare, kMaxVoxelShare] of `extent` (metres).
/// An extent of 0 (a model of one place: one point, coincident points) is in range of no
/// voxel: its turns cannot be told apart at any scale.
bool voxel_in_range(double voxel_size, double extent);

/// What "right" means: an answer within these of the truth (rotation, and translation of
/// the model's centroid) is right; the calibration counts it so.
inline constexpr double kRightDegrees = 5.0;
inline constexpr double kRightMetres = 0.010;

/// Whether the scene pins the pose down: two standard deviations of the covariance, along
/// its worst rotation axis and for the model's centroid (`centre`, scene frame, metres)
/// along its worst direction, within kRightDegrees and kRightMetres. A plane laid on a
/// plane, or a cylinder on a cylinder, is not: the prior alone bounds its free directions.
bool pose_determined(const PoseCovariance& covariance, const Eigen::Vector3d& centre);

/// The facts a verdict is read from.
struct VerdictInputs {
  double confidence = 0.0;  ///< Calibrated, in [0, 1].
  bool ambiguous = false;   ///< Another pose fits about as well.
  bool determined = true;   ///< pose_determined: the scene constrains every direction.
  bool supported = false;   ///< Some point of the answer is supported by the scene.
  bool timed_out = false;   ///< The time budget ran out before the search ended.
  bool scale_ok = true;     ///< voxel_in_range.
  bool rests = true;        ///< Not floating: AlignResult::rests, or resting not expected.
};

/// The verdict of an answer: max_seconds, bad_scale, no_support, then doubtful below
/// kReliableConfidence, floating, undetermined, ambiguous with an alternative, reliable
/// otherwise.
Verdict verdict_of(const VerdictInputs& inputs);

/// The name of a verdict, as Python and the command line print it ("reliable", ...).
const char* verdict_name(Verdict verdict);

/// The covariance of the pose error at T_scene_model from the point-to-plane fit of the
/// model onto the scene: each model point paired with its nearest scene point within
/// `voxel_size` whose normal agrees within 45 degrees, J_i = (p_i x n_i, n_i) for the left
/// perturbation and H = sum J_i J_i^T. Neighbouring residuals share their normal's error
/// and the sensor's: they are grouped in cells of 4 voxels and the covariance is the
/// cluster-robust (sandwich) one, H^-1 (sum over cells of g g^T) H^-1 with g the cell's
/// sum of J_i r_i, times k = covariance_inflation; a weak prior (a standard deviation of pi
/// radians and of the scene's typical size) keeps the directions that no surface
/// constrains (along a plane, about a cylinder's axis) finite. With fewer than 7 pairs,
/// the prior alone.
/// @throws std::invalid_argument for empty clouds, clouds without normals, a transform
///         that is not rigid, or a voxel_size not in (0, 1e6] metres.
PoseCovariance pose_covariance(const PointCloud& model, const PointCloud& scene,
                               const Transform& T_scene_model, double voxel_size);

/// The inflation k of the covariance, per kind: with it the mean normalised estimation
/// error squared (NEES) of the right answers of the calibration set is 6 (docs/trust.md,
/// "Covariance"). pose_covariance uses the model-to-scene one. Throws std::invalid_argument
/// for the servo's kinds (servo_step, servo_carried), which have no covariance.
double covariance_inflation(RegistrationKind kind);

}  // namespace spectral_vs
