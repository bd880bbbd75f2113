#pragma once
/// @file aligner.hpp
/// Model-to-scene alignment: the decoupled controller of Algorithm 1 (paper, section
/// II-D, eq. 16-17) and, beyond the paper, a global rotation search that makes the
/// result independent of the initial rotation.

#include <spectral_vs/alignment/verdict.hpp>
#include <spectral_vs/alignment/verification.hpp>
#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>

#include <cstddef>
#include <optional>
#include <vector>

namespace spectral_vs {

/// How a rotation step follows the correlation C(R) of eq. (12).
enum class RotationStep {
  gradient,  ///< The paper's law: R <- R exp(lambda_r hat(grad C)).
  newton,    ///< R <- R exp(lambda_r hat(-H^-1 grad C)) where the Hessian H is negative
             ///< definite, the gradient law elsewhere: the same fixed point, fewer iterations.
};

/// What the scene is to its sensor (SceneParams::scene_view).
enum class SceneView {
  automatic,    ///< A single view from sensor_origin if `detect_single_view` finds one
                ///< (a depth camera's cloud in its own frame), else seen from all sides.
  single_view,  ///< A single view from sensor_origin (declared).
  all_sides,    ///< Seen from all sides (a full model, a fused map): no view check.
};

/// The scene and its representation (`AlignParams::scene`): the voxel grids, the EGIs and
/// The largest bandwidth of an alignment (align, align_views): at 128 the global search's
/// refinements took 116 s for a 400-point model (64: 0.8 s, 96: 4.2 s).
inline constexpr int kMaxAlignBandwidth = 64;
/// The most iterations of Algorithm 1 an alignment takes (max_iterations,
/// refinement_iterations, whose defaults are 100 and 20): 2^31 - 1 never returned without
/// max_seconds.
inline constexpr int kMaxAlignIterations = 10000;

/// what the scene is to its sensor. Read by every stage (the voxel is the unit of every
/// length), and by the scene preparation alone for the sensor and the support plane.
struct SceneParams {
  /// Voxel edge r of the translation grid, metres; 0: derived from the model by
  /// `alignment_voxel_size` (its typical size / 12, at least its point spacing).
  double voxel_size = 0.0;
  int bandwidth = 16;  ///< B: EGI harmonics of degree l < B are correlated, in [2, 64].
  Occupancy occupancy = Occupancy::trilinear;    ///< Voxel values (the paper: binary).
  EgiMethod egi_method = EgiMethod::projection;  ///< How EGI coefficients are formed.
  /// Where the scene's sensor was, scene coordinates, metres: the origin for a depth
  /// camera's cloud in its own frame. Python orients estimated normals toward it.
  Eigen::Vector3d sensor_origin = Eigen::Vector3d::Zero();
  /// Whether the scene is a single view from sensor_origin. For a single view, fitness
  /// checks a pose against what the view saw (AlignResult::fitness), which tells a pose
  /// from its flip; with global search and no support plane, the whole view is searched
  /// as one part (below). Default: detected (`detect_single_view`).
  SceneView scene_view = SceneView::automatic;
  /// With global search: search the scene without its support plane (a plane of one
  /// normal direction wider than 4 model reaches holding over a fifth of the points, e.g.
  /// a table; fitness still sees it). Where there is one, the objects on it are searched
  /// one by one: the points more than 1.5 voxels above the plane are split into connected
  /// parts (points within 0.75 voxel_size joined), and each part that could be the object
  /// or a view of it (at least 30 points, its box diagonal between a quarter of the
  /// model's reach and 4 reaches; the 8 largest) gets its own SO(3) search on its own EGI,
  /// its rotations placed by phase correlation in a window around it (at twice the voxel,
  /// then at the voxel), from the model's side facing the sensor of a single view.
  bool suppress_support_plane = true;
};

/// The local controller, Algorithm 1 (`AlignParams::local`; paper, eq. 16-17): its gains,
/// its rotation law, its stop rule and its translation grid. Read by every run of
/// Algorithm 1: the paper's mode, the refinements of the global search, ModelAligner.
struct LocalParams {
  double translation_gain = 0.5;  ///< lambda_t in (0, 1]: share of the phase-correlation
                                  ///< shift applied per iteration (eq. 16), dimensionless.
  double rotation_gain = 0.5;     ///< lambda_r > 0. Newton: share of the Newton step, in (0, 1].
                                  ///< Gradient: radians per unit of normalised gradient.
  RotationStep rotation_step = RotationStep::newton;  ///< The rotation law.
  double max_rotation_step = 0.25;  ///< Largest rotation of one iteration, radians.
  double tolerance = 0.02;          ///< eps_g of eq. (17): stop when |translation step| in voxels
                                    ///< plus |grad C| (normalised correlation per radian) < eps_g.
  int max_iterations = 100;  ///< Iterations of Algorithm 1, in [1, 10^4], without global search
                             ///< (the paper's mode; the global search's: refinement_iterations).
  bool subvoxel = true;      ///< Sub-voxel refinement of the phase-correlation peak.
  double max_translation = 0.0;  ///< Without global search: the largest translation from the
                                 ///< initial guess that is sought, metres, per axis. The grid
                                 ///< then holds the scene and the model's start grown by this
                                 ///< (not by the model's reach), all iterations run on it, and
                                 ///< farther phase-correlation peaks are ignored: for two views
                                 ///< of one scene, as in servoing. 0: unbounded (the paper).
  /// Without global search: the ICP of RefinementParams::icp_refinement after Algorithm 1,
  /// with the same rule (kept unless it lowers fitness by more than 0.05), on about 1000
  /// of the model's points (a model within a voxel needs fewer pairs). Beyond the
  /// paper: a tracker's one-iteration estimate is pulled by geometry the model does not
  /// have (a tool left on the table: 15 mm and 8 degrees off at a fitness of 0.97,
  /// docs/servoing.md), which the ICP's pairs within a voxel leave out. Off: the paper's
  /// Algorithm 1 alone.
  bool icp = false;
};

/// The global search (`AlignParams::search`; beyond the paper): the SO(3) search, the
/// placement of its rotations by phase correlation, and the neighbourhood of the initial
/// guess it is kept to. Read by the hypothesis generation and the choice of the
/// hypotheses refined; without global_search, by nothing.
struct GlobalSearchParams {
  bool global_search = true;  ///< Start from the best rotations of the SO(3) search
                              ///< (beyond the paper) instead of the initial guess's.
  int hypotheses = 48;        ///< Rotations of the global search that are placed and verified:
                              ///< enough to hold the true one among the near-equal maxima of
                              ///< an object with symmetric faces. Searched per part of a
                              ///< cluttered scene (see SceneParams::suppress_support_plane):
                              ///< half as many per part, at least 1, each at least 10 degrees
                              ///< from the part's others once refined. >= 1.
  int refinements = 3;        ///< The best-verified hypotheses that Algorithm 1 then runs from,
                              ///< each in a window of the scene around it; the one with the
                              ///< best final fitness is kept. At most: after the first, a
                              ///< hypothesis fitting under 0.65 of the best refined pose's
                              ///< fitness is skipped (with a neighbourhood, never the
                              ///< guess). In [1, hypotheses].
  double search_voxel_size = 0.0;  ///< Voxel of the global search's translation grid, metres.
                                   ///< 0: twice voxel_size, coarser where needed to keep that
                                   ///< grid under 2^19 voxels (large scenes).
  double window_margin = 0.0;      ///< How far the model may move per window placement, metres:
                                   ///< local windows are the model's reach plus this on each side.
                                   ///< 0: the larger of 5 voxels and 2.5 search voxels.
  /// The largest rotation from initial_guess that is searched, degrees, in [0, 180]; 0: no
  /// limit. With this or guess_distance, the guess is always refined and only the
  /// hypotheses inside the neighbourhood are kept.
  double guess_angle_deg = 0.0;
  /// The largest distance of the model's centroid from where initial_guess puts it that
  /// is searched, metres, >= 0; 0: no limit. With a limit, the parts of a cluttered scene
  /// farther than this plus the model's reach are not searched.
  double guess_distance = 0.0;
  /// The connected parts of a cluttered scene (above its support plane) that are searched,
  /// at most, >= 1: the largest plausible ones (by points) first. The search's time grows
  /// about linearly with them. 8 holds every part of every tuning scene (4-6 objects);
  /// on a synthetic table of 13 or more objects (benchmarks/cost_growth.py, "extent")
  /// the object was among the parts left out, and the answer doubtful.
  int max_parts = 8;
};

/// The refinement of the global search's hypotheses (`AlignParams::refinement`): Algorithm
/// 1 from each (with LocalParams' gains), the flat-axis sweep and polish, the ICP. Without
/// global search, by nothing.
struct RefinementParams {
  /// Iterations of Algorithm 1 per refinement, in [1, 10^4]. Each starts at a verified hypothesis
  /// and is then polished and ICP-refined: 20 ended as well as 100 on every experiment
  /// family (docs/experiments.md), where cluttered windows made a third of the runs
  /// chatter to 100 without converging.
  int refinement_iterations = 20;
  bool polish = true;  ///< For a model whose EGI has a flat axis (its smallest
                       ///< autocorrelation curvature under a tenth of the largest: a
                       ///< mug's axis, its handle a few percent of the normals), each pose
                       ///< Algorithm 1 ends at is turned to the best of the turns about
                       ///< that axis every 15 degrees, scored by the overlap of the model's
                       ///< voxels with the scene's, before the poses are compared. Without
                       ///< icp_refinement, then a pattern search on the kept rotation (4 to
                       ///< 1/4 degree steps) for the same overlap, past the EGI's accuracy
                       ///< floor. Skipped for models sampled sparser than 2 points per
                       ///< occupied voxel.
  /// A point-to-plane ICP from the result (each model point paired with its nearest scene
  /// point within voxel_size whose normal agrees within 45 degrees, then, for a model of
  /// at least 2 points per occupied voxel, within 0.4 voxel_size; for a single view, the
  /// model points facing its sensor only; Gauss-Newton, up to 30 steps each), kept unless
  /// it lowers fitness by more than 0.05. For a single view it refines every Algorithm 1
  /// result before they are compared (a view's fitness tells a pose from its
  /// near-symmetric flip only when both are precise), and the kept one after the polish.
  /// Not spectral: the one local step, past the voxel grid's and the EGI's accuracy
  /// (docs/experiments.md measures with and without).
  bool icp_refinement = true;
};

/// What is checked and reported of the result (`AlignParams::verification`): read by the
/// verifier and the search for alternatives, after the last refinement.
struct VerificationParams {
  /// Without global search: verify the final pose (verify_pose: AlignResult::confidence,
  /// inliers, inlier_rmse, inlier_distance). Off, those stay 0 and the pose, fitness and
  /// history are the same bit for bit: a tracker that reads only the fitness skips the
  /// check (about 2 ms of a servo step at 320 x 240, docs/servoing.md). With global search
  /// the poses are always verified: the check ranks the alternatives.
  bool verify = true;
  /// With global search: at most this many alternatives are reported
  /// (AlignResult::alternatives), in [0, 64]; 0 skips their search (and `ambiguous` and
  /// the reselection).
  int max_alternatives = 8;
  /// With global search and alternatives: when the best alternative's confidence exceeds
  /// the refined pose's by more than this, the alternative is returned instead
  /// (stop_reason reselected) and the alternatives are searched again around it. In
  /// [0, 1]; 1 never reselects. The confidence tells right from wrong poses better than
  /// the fitness that ranks the refinements (ROC AUC 0.997 against 0.974 on the tuning
  /// families); 0.1 gained 5 of 280 tuning single views and clutter scenes (258 to 263:
  /// margins 0.03-0.05 gained 4, 0 lost 14, 0.15 gained 4), docs/experiments.md.
  /// Below 1, two more rules return an alternative, for a flat box whose hidden faces sit
  /// inside another object, as confident as the box lying on the table: in clutter, one
  /// within 0.01 of the refined pose's confidence that explains a share of its object's
  /// part of the scene larger by over 0.2 (the box explains its own part whole, not
  /// another object's); else one at least as confident with more inliers (the table
  /// supports the box's underside), the one with the most. Tuning thin objects in
  /// clutter 105 to 123 of 126, 840 other tuning cases 4 gained and none lost
  /// (docs/experiments.md "Thin objects"). Below 1 too, in clutter, a pose that rests
  /// neither on the support plane nor on an upward-facing scene surface gives way to the
  /// most confident pose that does, at most 0.1 less confident (docs/alignment.md).
  double reselect_margin = 0.1;
  /// With global search, in a scene where a support plane is found: objects rest on it or
  /// on each other, so a pose that does neither (AlignResult::rests false) is not reliable
  /// (status floating) and, below a reselect_margin of 1, gives way to a resting one. On
  /// 1,021 tuning-side and calibration problems none of the 921 right answers floated, and
  /// 2 of the 4 wrong answers taken for reliable did; on the validation set both of its
  /// confident wrong answers did (docs/trust.md, "Floating poses"). False for an object
  /// that may hang above the table (held in a gripper): its pose is then judged without it.
  bool expect_resting = true;
};

/// Settings of `align`, grouped by the stage they steer (docs/architecture.md shows which
/// stage reads which group). Defaults are the ones measured best here
/// (docs/experiments.md). Which groups apply depends on the mode: with
/// search.global_search (the default) every group; without it (the paper's mode, the
/// servo's bounded search) scene, local and verification, and not search or refinement.
struct AlignParams {
  SceneParams scene;                ///< The scene and its representation.
  LocalParams local;                ///< Algorithm 1.
  GlobalSearchParams search;        ///< The global search (with search.global_search).
  RefinementParams refinement;      ///< Refinement of its hypotheses (with global search).
  VerificationParams verification;  ///< The check of the result and its alternatives.
  /// T_scene_model to start from. Without global search, Algorithm 1 starts here. With
  /// it, the guess seeds the search: it is verified and ranked with the search's
  /// hypotheses, and with a neighbourhood (search.guess_angle_deg, guess_distance) it is
  /// always refined and only the hypotheses inside the neighbourhood are kept.
  Transform initial_guess = Transform::Identity();
  int threads = 1;  ///< Threads for FFTW and the SO(3) search, in [1, 256].
  /// Time budget of the whole alignment, seconds, >= 0 (0: none). Checked after every
  /// iteration, hypothesis and refinement: past it, the best pose so far is returned with
  /// converged = false and stop_reason = max_seconds (the one setting whose result depends
  /// on the machine's speed).
  double max_seconds = 0.0;
  /// Memory cap: any grid over limits.max_voxels voxels (scene map, translation grids,
  /// windows) is refused with std::invalid_argument before it is allocated. The largest
  /// grids cost about 28 bytes per voxel (values, FFT buffers) and an alignment holds
  /// several: the default 2^24 voxels bounds an alignment at about 1 GB.
  GridLimits limits = {};
};

/// Why `align` stopped.
enum class AlignStopReason {
  converged,       ///< The stop rule (eq. 17) held.
  max_iterations,  ///< AlignParams::local.max_iterations ran out.
  max_seconds,     ///< AlignParams::max_seconds ran out.
  kept_start,      ///< With global search: Algorithm 1 ended less fit than the hypothesis it
                   ///< started from, and the hypothesis's pose was kept (its run is not
                   ///< the returned pose's: iterations 0, history empty).
  reselected,      ///< With global search: an alternative the scene supports clearly better
                   ///< (VerificationParams::reselect_margin) replaced the refined pose; no
                   ///< run of Algorithm 1 ended there (iterations 0, history empty,
                   ///< hypothesis -2).
};

/// One iteration of Algorithm 1, recorded after its update.
struct AlignIteration {
  double translation_cost = 0.0;   ///< J_t of eq. (9) on the voxel grids, voxel units.
  double rotation_cost = 0.0;      ///< J_r of eq. (16) on normalised EGI coefficients.
  double translation_step = 0.0;   ///< |lambda_t * phase-correlation shift|, voxels.
  double rotation_gradient = 0.0;  ///< |grad C| of eq. (15), normalised correlation per radian.
  double correlation = 0.0;        ///< Normalised EGI correlation C(R) in [-1, 1].
  double translation_peak = 0.0;   ///< Phase-correlation peak height in [0, 1].
  Transform T_scene_model = Transform::Identity();  ///< Pose after the update.
  double seconds = 0.0;  ///< Wall time of the iteration (rotation and translation steps), s.
};

/// Another pose that the scene supports about as well as the returned one (a symmetric
/// object's, or one whose distinguishing part the view does not show).
struct AlignAlternative {
  Transform T_scene_model = Transform::Identity();
  double confidence = 0.0;         ///< As AlignResult::confidence (calibrated), for this pose.
  double score = 0.0;              ///< As AlignResult::score (the uncalibrated score).
  int inliers = 0;                 ///< As AlignResult::inliers.
  double inlier_rmse = 0.0;        ///< As AlignResult::inlier_rmse, metres.
  double rotation_apart = 0.0;     ///< Rotation from the returned pose, radians.
  double translation_apart = 0.0;  ///< Model centroid from the returned pose's, metres.
  /// The model maps onto itself by the turn from the returned pose to this one (its own
  /// score against itself at least kSymmetricSelfFit): the same answer up to the object's
  /// symmetry, which does not make the result ambiguous.
  bool symmetric = false;
};

/// Where the time of one `align` went, by stage, seconds of the wall clock (with
/// `threads = 1`, the call's CPU time). The stages sum to `total` but for the settings'
/// checks and the result's copies. `ModelAligner::align` in its local mode fills
/// preparation, algorithm1, verdict (the verification and the verdict) and total
/// (`ModelAligner::last_timings` splits them further).
struct AlignTimings {
  /// The scene as searched (its support plane out), the EGIs of model and scene and their
  /// correlation, the single-view detection, the model's flat axis.
  double preparation = 0.0;
  double rotation_search = 0.0;  ///< The SO(3) searches of the hypotheses (`so3_search`).
  /// The hypotheses' rotations refined, placed by phase correlation and ranked by the
  /// verification's screen; the turns about a flat axis.
  double placement = 0.0;
  /// Algorithm 1 from each refined hypothesis (the paper's mode: from the guess), the
  /// sweeps about a flat axis and the polish.
  double algorithm1 = 0.0;
  double icp = 0.0;  ///< The ICP refinement of the refined hypotheses.
  /// The check of the pose, the alternatives, the reselection and the resting poses.
  double alternatives = 0.0;
  double verdict = 0.0;  ///< The verdict: the covariance, the symmetries, the calibration.
  double total = 0.0;    ///< The whole call.
};

/// Outcome of `align`.
struct AlignResult {
  Transform T_scene_model = Transform::Identity();  ///< Maps model coordinates into the scene.
  /// The optimisation ended normally: stop_reason is converged, kept_start or reselected
  /// (not max_iterations nor max_seconds). It says nothing of whether the pose is right:
  /// `reliable` does. With global search the Algorithm 1 run started at the kept hypothesis
  /// (`hypothesis`); the pose is then turned about a flat axis and ICP-refined
  /// (polish_evaluations, icp_iterations).
  bool converged = false;
  AlignStopReason stop_reason = AlignStopReason::max_iterations;  ///< Why it stopped.
  int iterations = 0;  ///< Iterations of that run: history.size().
  /// How well the scene supports the final pose, in [0, 1]: high for a correct alignment,
  /// low for a wrong one. For a scene seen from all sides: the fraction of the model's occupied
  /// voxels that lie within one voxel of scene points with a normal within about 50
  /// degrees of the model's. For a single view: the model is rendered from sensor_origin (its
  /// nearest points facing it, in pixels of half a voxel) and each pixel compared with the
  /// scan's depth there: confirmed (within one voxel, normals within 45 degrees),
  /// contradicted (the scan saw through it, or a surface turned another way) or hidden
  /// (the scan saw something nearer); fitness = confirmed / (confirmed + contradicted +
  /// hidden / 2).
  double fitness = 0.0;
  double correlation = 0.0;       ///< Final normalised EGI correlation C(R).
  double translation_peak = 0.0;  ///< Final phase-correlation peak height.
  /// Index of the kept global-search hypothesis (0 without; -1: the initial guess; -2: an
  /// alternative of the verification, stop_reason reselected).
  int hypothesis = 0;
  /// The voxel sizes the alignment worked at, metres: the global search's translation
  /// grid (0 without global search) and the windows of Algorithm 1.
  double search_voxel_size = 0.0;
  Eigen::Vector3i window_dims = Eigen::Vector3i::Zero();  ///< Voxels of the local window.
  int polish_evaluations = 0;  ///< Phase correlations of the final polish (0 without).
  int icp_iterations = 0;      ///< Steps of the ICP refinement (0 without, or if not kept).
  /// Global-search hypotheses refined by Algorithm 1: at most search.refinements (those
  /// fitting under 0.65 of the best refined pose are skipped); 0 without global search.
  int refinements_run = 0;
  /// Every iteration of that run; history.back().T_scene_model is where Algorithm 1
  /// ended, T_scene_model that pose after the polish and ICP (equal without them).
  std::vector<AlignIteration> history;
  /// The verdict: true when status is Verdict::reliable (confidence at least
  /// kReliableConfidence, no alternative as good, the search finished in time, the voxel
  /// in range). The one field to check before acting on T_scene_model.
  bool reliable = false;
  Verdict status = Verdict::doubtful;  ///< The verdict in one word (verdict.hpp).
  /// The scene pins the pose down: pose_determined of the covariance at the model's
  /// centroid (false when the verification is off).
  bool determined = false;
  /// The pose rests on the scene's support plane, or on an upward-facing surface of the
  /// scene just under its lowest points (within 1.5 voxels). False only where a support
  /// plane was found (search.global_search and scene.suppress_support_plane on, a plane
  /// wider than 4 model reaches holding over a fifth of the scene's points) and the pose
  /// neither touches it nor stands on anything: a flat object flush with another object's
  /// face, the rest of it inside that object. With verification.expect_resting such a
  /// pose is `floating`. True also where no plane was sought (not known to float).
  bool rests = true;
  /// The probability that the pose is right (within 5 degrees and 10 mm), in [0, 1]: `score`
  /// through the calibration map fitted on the calibration set (calibrated_confidence).
  double confidence = 0.0;
  /// The verification's score, uncalibrated, in [0, 1] (verify_pose, confidence_of): the
  /// share of the model points the sensor would see that lie within half a voxel of a
  /// scene point turned the same way, less the share it saw through.
  double score = 0.0;
  /// Covariance of the pose error (rotation vector in radians, then translation in metres,
  /// T_true = exp(delta) T_scene_model, scene frame): pose_covariance at the pose. Zero
  /// when the verification is off.
  PoseCovariance covariance = PoseCovariance::Zero();
  /// Model points (as aligned: downsampled) within inlier_distance of their nearest scene
  /// point at the pose; inlier_fraction = inliers / model points.
  int inliers = 0;
  double inlier_fraction = 0.0;  ///< inliers / model points, in [0, 1].
  /// Root mean square distance of the inliers to their nearest scene points, metres.
  double inlier_rmse = 0.0;
  double inlier_distance = 0.0;  ///< kInlierVoxels * voxel_size, metres.
  /// With global search: poses apart from this one by more than 5 degrees or 10 mm (and
  /// from each other), whose confidence is within 0.05 of this one's, best first, at most
  /// AlignParams::verification.max_alternatives.
  std::vector<AlignAlternative> alternatives;
  /// True when there is an alternative that is not `symmetric`: the scene does not tell
  /// the pose apart from another one that is not the same answer (a view that hides the
  /// object's distinguishing part, a near-symmetric object).
  bool ambiguous = false;
  double voxel_size = 0.0;   ///< The voxel the alignment worked at, metres (derived for 0).
  bool single_view = false;  ///< The scene was checked as a single view from sensor_origin
                             ///< (declared, or detected: `detect_single_view`).
  AlignTimings timings;      ///< Where the time went.
};

/// A confidence above this separates right from wrong poses: the balanced threshold
/// (0.891) of 225 poses of the tuning families at the derived voxel (C-1, C-2, C-3 and the
/// real scans: defaults, truncated searches and other objects' models), where it kept 96%
/// of the right poses and rejected 97% of the wrong ones (0.91 until that balance moved
/// in two runs in a row); docs/experiments.md "Confidence" says how it was chosen and
/// reports it on the held-out objects.
inline constexpr double kConfidenceThreshold = 0.89;

/// The default voxel of `align` for `voxel_size = 0`, metres: the rule of `view_scale`
/// applied to the model, max(extent / 12, extent / sqrt(N)) with extent its typical size
/// (twice the median distance of its points from their median) and N its points: about
/// 8 mm for the household objects of docs/experiments.md (typical sizes 0.08-0.15 m),
/// 0.2-0.3 m for a view of a room (docs/alignment.md gives the measurement). A model of
/// one place (one point, coincident points) takes the scene's typical size instead.
/// @throws std::invalid_argument for an empty cloud, or when neither spans a volume.
double alignment_voxel_size(const PointCloud& model, const PointCloud& scene);

/// The evidence that `scene` is a single view from `sensor_origin`.
struct SingleViewEvidence {
  /// Share of the scene's points that a sensor at the origin sees: in front of it (within
  /// about 72 degrees of the direction to the centroid), facing it, and the nearest
  /// surface along their ray (within `tolerance` of the plane of the nearest point of
  /// their pixel, normals within 45 degrees), in [0, 1].
  double visible = 0.0;
  bool single_view = false;  ///< visible >= single_view_threshold.
};

/// The share `detect_single_view` requires. Measured on the experiment families
/// (docs/alignment.md): a depth camera's cloud in its frame sees 0.988-1 of its points
/// (simulated single views and clutter, the real Kinect scene), a full model 0.13-0.47
/// of its own from outside, a scene in a world frame (sensor elsewhere) 0-0.07, a single
/// scan moved away from its sensor 0.25-0.94.
constexpr double single_view_threshold = 0.95;

/// Whether `scene` is a single view from `sensor_origin`: all its points visible from
/// there, within `tolerance` metres (the alignment uses its voxel). A scene seen from all
/// sides hides its far side from any one point outside it.
/// @throws std::invalid_argument for an empty scene, missing normals, a non-finite
///         origin or a tolerance that is not finite and positive.
SingleViewEvidence detect_single_view(const PointCloud& scene, const Eigen::Vector3d& sensor_origin,
                                      double tolerance);

/// Aligns `model` onto `scene`: the returned T_scene_model moves the model's points onto
/// the scene. Both clouds need normals. Rotation is about the model's centroid.
/// @throws std::invalid_argument for an empty cloud, missing normals, non-finite or
///         out-of-range parameters, an initial guess that is not a rigid transform, or a
///         grid over `params.limits` (refused before it is allocated). Not converging,
///         or running out of max_seconds, is not an error: it returns converged = false
///         and the stop_reason.
AlignResult align(const PointCloud& model, const PointCloud& scene, const AlignParams& params = {});

/// One rotation step of Algorithm 1 restricted to turns about an axis.
struct AxisRotationStep {
  double turn = 0.0;       ///< The step, radians about the axis (R <- R exp(turn hat(axis))).
  double slope = 0.0;      ///< dC/dtheta along the axis at R, per radian.
  double curvature = 0.0;  ///< d2C/dtheta2 along the axis at R, per radian^2.
  bool newton = false;     ///< The Newton step (the correlation is concave along the axis).
  bool capped = false;     ///< The step was cut to params.local.max_rotation_step.
};

/// The rotation law of Algorithm 1 (params.local.rotation_step, rotation_gain and
/// max_rotation_step, as align() steps) for rotations R exp(theta hat(axis)) only: the
/// Newton step -gain slope / curvature where the curvature is negative, else the
/// gradient law gain slope, capped at max_rotation_step. For a turn about one direction
/// (a table's normal) that the full 3D step leaves to the other two.
/// @param axis direction of the turn, in the frame R acts on (model frame); normalised here.
/// @throws std::invalid_argument for a zero or non-finite axis or an R that is no rotation.
AxisRotationStep rotation_step_about(So3Correlation& correlation, const Eigen::Matrix3d& R,
                                     const Eigen::Vector3d& axis, const AlignParams& params);

}  // namespace spectral_vs
