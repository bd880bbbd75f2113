// Bindings of the aligner (paper, section II-D and Algorithm 1).
#include "conversions.hpp"
#include "settings.hpp"
#include "timings.hpp"

#include <spectral_vs/alignment/aligner.hpp>

#include <pybind11/stl.h>

#include <limits>
#include <sstream>

namespace spectral_vs::python {

namespace {

constexpr Choices<RotationStep, 2> kRotationSteps{
    {{"newton", RotationStep::newton}, {"gradient", RotationStep::gradient}}};

constexpr Choices<AlignStopReason, 5> kStopReasons{
    {{"converged", AlignStopReason::converged},
     {"max_iterations", AlignStopReason::max_iterations},
     {"max_seconds", AlignStopReason::max_seconds},
     {"kept_start", AlignStopReason::kept_start},
     {"reselected", AlignStopReason::reselected}}};

constexpr Choices<RegistrationKind, 4> kRegistrationKinds{
    {{"align", RegistrationKind::model_to_scene},
     {"views", RegistrationKind::view_to_view},
     {"servo", RegistrationKind::servo_step},
     {"servo_carried", RegistrationKind::servo_carried}}};

RegistrationKind registration_kind(const std::string& kind) {
  return parse_choice(kind, kRegistrationKinds, "kind");
}

constexpr Choices<SceneView, 3> kSceneViews{{{"auto", SceneView::automatic},
                                             {"single_view", SceneView::single_view},
                                             {"all_sides", SceneView::all_sides}}};

void define_align_groups(py::module_& m) {
  py::class_<SceneParams> scene(m, "SceneParams", R"doc(
The scene and its representation: ``AlignParams.scene``, read by every stage of
:func:`align` (the voxel is the unit of its lengths).

Attributes
----------
voxel_size : float
    Voxel edge of the translation grid, metres; 0 (default): derived from the model by
    ``alignment_voxel_size`` (its typical size / 12: about 8 mm for a household object,
    0.2-0.3 m for a view of a room).
bandwidth : int
    B: EGI harmonics of degree l < B are correlated (default 16).
occupancy : str
    'trilinear' (default), 'binary' (the paper) or 'count'.
egi_method : str
    'projection' (default) or 'histogram' (the paper).
sensor_origin : ndarray (3,)
    Where the scene's sensor was, scene coordinates, metres (default the origin: a depth
    camera's cloud in its own frame). Estimated normals point toward it.
scene_view : str
    'auto' (default): the scene is a single view from sensor_origin when
    ``detect_single_view`` finds one (at least 95% of its points visible from there),
    else seen from all sides; 'single_view': declared one; 'all_sides': never (a full
    model, a fused map). For a single view fitness checks the pose against what the view
    saw (the model rendered from there, pixel by pixel against the scan's depth), which
    tells a pose from its flip; without a support plane the whole view is searched as
    one part.
suppress_support_plane : bool
    With global search: search the scene without its support plane (a plane wider than 4
    model reaches holding over a fifth of the points, e.g. a table; fitness still sees
    it), and where there is one, search each connected part of the scene above it that
    could be the object on its own EGI, its rotations placed from the model's side
    facing the sensor of a single view by phase correlation in a window around the part,
    at twice the voxel and then at the voxel (default True).
)doc");
  define_settings(scene)
      .def_readwrite("voxel_size", &SceneParams::voxel_size)
      .def_readwrite("bandwidth", &SceneParams::bandwidth)
      .def_property(
          "occupancy", [](const SceneParams& p) { return choice_name(p.occupancy, kOccupancies); },
          [](SceneParams& p, const std::string& s) {
            p.occupancy = parse_choice(s, kOccupancies, "occupancy");
          })
      .def_property(
          "egi_method", [](const SceneParams& p) { return choice_name(p.egi_method, kEgiMethods); },
          [](SceneParams& p, const std::string& s) {
            p.egi_method = parse_choice(s, kEgiMethods, "egi_method");
          })
      .def_property(
          "sensor_origin", [](const SceneParams& p) { return Eigen::Vector3d(p.sensor_origin); },
          [](SceneParams& p, const Eigen::Vector3d& origin) { p.sensor_origin = origin; })
      .def_property(
          "scene_view", [](const SceneParams& p) { return choice_name(p.scene_view, kSceneViews); },
          [](SceneParams& p, const std::string& s) {
            p.scene_view = parse_choice(s, kSceneViews, "scene_view");
          })
      .def_readwrite("suppress_support_plane", &SceneParams::suppress_support_plane);

  py::class_<LocalParams> local(m, "LocalParams", R"doc(
The local controller, Algorithm 1 (paper, eq. 16-17): ``AlignParams.local``, read by every
run of Algorithm 1 (the paper's mode, the global search's refinements, ModelAligner).

Attributes
----------
translation_gain, rotation_gain : float
    lambda_t in (0, 1] and lambda_r of eq. (16). With Newton steps lambda_r is the share
    of the Newton step in (0, 1]; with gradient steps, radians per unit gradient.
rotation_step : str
    'newton' (default) or 'gradient' (the paper's law).
max_rotation_step : float
    Largest rotation of one iteration, radians.
tolerance : float
    eps_g of eq. (17): |translation step| (voxels) + |grad C| below which it stops.
max_iterations : int
    Iterations of Algorithm 1 in the paper's mode (default 100).
subvoxel : bool
    Sub-voxel refinement of the phase-correlation peak.
max_translation : float
    Without global search: the largest translation from the initial guess sought, metres
    per axis; the grid then holds the scene and the model's start grown by this instead
    of by the model's reach, and farther peaks are ignored (two views of one scene, as in
    servoing). 0 (default): unbounded.
local_icp : bool
    Without global search: the point-to-plane ICP of icp_refinement after Algorithm 1,
    kept unless it lowers fitness by more than 0.05.
    Off (default): the paper's Algorithm 1 alone.
)doc");
  define_settings(local)
      .def_readwrite("translation_gain", &LocalParams::translation_gain)
      .def_readwrite("rotation_gain", &LocalParams::rotation_gain)
      .def_property(
          "rotation_step",
          [](const LocalParams& p) { return choice_name(p.rotation_step, kRotationSteps); },
          [](LocalParams& p, const std::string& s) {
            p.rotation_step = parse_choice(s, kRotationSteps, "rotation_step");
          })
      .def_readwrite("max_rotation_step", &LocalParams::max_rotation_step)
      .def_readwrite("tolerance", &LocalParams::tolerance)
      .def_readwrite("max_iterations", &LocalParams::max_iterations)
      .def_readwrite("subvoxel", &LocalParams::subvoxel)
      .def_readwrite("max_translation", &LocalParams::max_translation)
      .def_readwrite("local_icp", &LocalParams::icp);

  py::class_<GlobalSearchParams> search(m, "GlobalSearchParams", R"doc(
The global search (beyond the paper): ``AlignParams.search``, read by the hypothesis
generation (the SO(3) search, the placement of its rotations) and the choice of the
hypotheses refined.

Attributes
----------
global_search : bool
    Start from the best rotations of the SO(3) search (default True); False: Algorithm 1
    from initial_guess (the paper's mode), and the rest of this group is not read.
hypotheses : int
    Rotations of the global search that are placed and verified (default 48); half as
    many per part of a cluttered scene, each at least 10 degrees from the part's others.
refinements : int
    The best-verified hypotheses Algorithm 1 then runs from, each in a window of the
    scene around it; the best final fitness is kept (default 3, at most hypotheses).
    At most: after the first, a hypothesis fitting under 0.65 of the best refined
    pose's fitness is skipped (with a neighbourhood, never the guess).
search_voxel_size : float
    Voxel of the global search's translation grid, metres; 0 (default): twice
    voxel_size, coarser where needed to keep that grid under 2^19 voxels.
window_margin : float
    How far the model may move per window placement, metres; 0 (default): the larger of
    5 voxels and 2.5 search voxels.
guess_angle_deg : float
    The largest rotation from initial_guess searched, degrees, in [0, 180] (default 0:
    no limit).
guess_distance : float
    The largest distance of the model's centroid from where initial_guess puts it,
    metres (default 0: no limit). With either limit the guess is always refined and only
    hypotheses inside both are kept.
max_parts : int
    The connected parts of a cluttered scene (above its support plane) searched, at
    most, largest first (default 8, >= 1); the search's time grows about linearly with
    them. Raise it for a scene of many objects (a room): with 13 or more objects on a
    table the default may leave the object out, and the answer is doubtful.
)doc");
  define_settings(search)
      .def_readwrite("global_search", &GlobalSearchParams::global_search)
      .def_readwrite("hypotheses", &GlobalSearchParams::hypotheses)
      .def_readwrite("refinements", &GlobalSearchParams::refinements)
      .def_readwrite("search_voxel_size", &GlobalSearchParams::search_voxel_size)
      .def_readwrite("window_margin", &GlobalSearchParams::window_margin)
      .def_readwrite("guess_angle_deg", &GlobalSearchParams::guess_angle_deg)
      .def_readwrite("guess_distance", &GlobalSearchParams::guess_distance)
      .def_readwrite("max_parts", &GlobalSearchParams::max_parts);

  py::class_<RefinementParams> refinement(m, "RefinementParams", R"doc(
The refinement of the global search's hypotheses: ``AlignParams.refinement``, read after
the search (not in the paper's mode).

Attributes
----------
refinement_iterations : int
    Iterations of Algorithm 1 per refinement (default 20); each refined pose is then
    polished and ICP-refined.
polish : bool
    For a model whose EGI has a flat axis (a mug's), each pose Algorithm 1 ends at is
    turned to the best of the turns about that axis every 15 degrees, scored by the
    overlap of the model's voxels with the scene's, before the poses are compared;
    without icp_refinement, then a pattern search on the kept rotation (4 to 1/4 degree
    steps) for the same overlap (default True). Skipped for models sampled sparser than
    2 points per occupied voxel.
icp_refinement : bool
    A point-to-plane ICP (pairs within voxel_size whose normals agree within 45 degrees,
    then, for a model of at least 2 points per occupied voxel, within 0.4 voxel_size; for
    a single view the model's points facing its sensor only), kept unless it lowers
    fitness by more than 0.05 (default True); for a single view on every Algorithm 1
    result before they are compared, and last on the kept one. The one step that is not
    spectral.
)doc");
  define_settings(refinement)
      .def_readwrite("refinement_iterations", &RefinementParams::refinement_iterations)
      .def_readwrite("polish", &RefinementParams::polish)
      .def_readwrite("icp_refinement", &RefinementParams::icp_refinement);

  py::class_<VerificationParams> verification(m, "VerificationParams", R"doc(
The check of the result and its alternatives: ``AlignParams.verification``, read after the
last refinement.

Attributes
----------
verify : bool
    Without global search: verify the final pose (``AlignResult.confidence``, ``inliers``,
    ``inlier_rmse``, ``inlier_distance``; default True). False leaves those 0, with the same
    pose, fitness and history bit for bit (a tracker that reads only the fitness). With
    global search the poses are always verified.
max_alternatives : int
    With global search: at most this many alternatives reported (``AlignResult.alternatives``),
    in [0, 64] (default 8); 0 skips their search, ``ambiguous`` and the reselection.
reselect_margin : float
    With global search and alternatives: an alternative more confident than the refined
    pose by more than this is returned instead (``stop_reason`` ``'reselected'``), in
    [0, 1] (default 0.1; 1 never reselects). Below 1, so is, in clutter, an alternative
    within 0.01 as confident that explains a share of its object's part of the scene
    larger by over 0.2, else one at least as confident with more inliers.
expect_resting : bool
    With global search, in a scene where a support plane is found: objects rest on it or
    on each other, so a pose that does neither (``AlignResult.rests`` False) is not
    reliable (status ``'floating'``) and, below a ``reselect_margin`` of 1, gives way to a
    resting one (default True). False for an object that may hang above the table (held in
    a gripper).
)doc");
  define_settings(verification)
      .def_readwrite("verify", &VerificationParams::verify)
      .def_readwrite("max_alternatives", &VerificationParams::max_alternatives)
      .def_readwrite("reselect_margin", &VerificationParams::reselect_margin)
      .def_readwrite("expect_resting", &VerificationParams::expect_resting);
}

void define_align_params(py::module_& m) {
  define_align_groups(m);
  py::class_<AlignParams> align_params(m, "AlignParams", R"doc(
Settings of :func:`align`, grouped by the stage they steer; every field has the default
measured best.

The groups are attributes, each a settings object of its own: ``scene``
(:class:`SceneParams`), ``local`` (Algorithm 1, :class:`LocalParams`), ``search`` (the
global search, :class:`GlobalSearchParams`), ``refinement`` (:class:`RefinementParams`)
and ``verification`` (:class:`VerificationParams`); ``params.search.hypotheses = 8``
changes ``params``. Every field of a group is also a field of AlignParams under the same
name (``params.hypotheses``), and takes a keyword argument,
``AlignParams(voxel_size=0.005, hypotheses=8, threads=2)``; the repr shows every field.

Attributes
----------
scene, local, search, refinement, verification
    The groups (read-only references; their fields are settable).
initial_guess : ndarray (4, 4)
    T_scene_model to start from. With global search it seeds the search: verified and
    ranked with its hypotheses (and, with guess_angle_deg or guess_distance, always
    refined, the search kept to that neighbourhood).
threads : int
    Threads for FFTW and the SO(3) search, in [1, 256].
max_seconds : float
    Time budget of the whole alignment, seconds (default 0: none). Past it, the best pose
    so far is returned with ``converged = False`` and ``stop_reason = 'max_seconds'``.
max_voxels : int
    Memory cap: any grid over this many voxels is refused with ``ValueError`` before it
    is allocated (default 2^24, about 1 GB for an alignment; at most 2^32).
)doc");
  define_settings(align_params);
  define_group(align_params, "scene", &AlignParams::scene,
               "The scene and its representation (SceneParams).");
  define_group(align_params, "local", &AlignParams::local, "Algorithm 1 (LocalParams).");
  define_group(align_params, "search", &AlignParams::search,
               "The global search (GlobalSearchParams).");
  define_group(align_params, "refinement", &AlignParams::refinement,
               "The refinement of the search's hypotheses (RefinementParams).");
  define_group(align_params, "verification", &AlignParams::verification,
               "The check of the result and its alternatives (VerificationParams).");
  align_params
      .def_property(
          "initial_guess", [](const AlignParams& p) { return Eigen::Matrix4d(p.initial_guess); },
          [](AlignParams& p, const py::handle& T) {
            p.initial_guess = to_transform(T, "initial_guess");
          })
      .def_readwrite("threads", &AlignParams::threads)
      .def_readwrite("max_seconds", &AlignParams::max_seconds)
      .def_property(
          "max_voxels", [](const AlignParams& p) { return p.limits.max_voxels; },
          [](AlignParams& p, long long v) { p.limits.max_voxels = to_max_voxels(v); });
}

}  // namespace

void define_alignment(py::module_& m) {
  define_align_params(m);

  py::class_<AlignIteration>(m, "AlignIteration", "One iteration of Algorithm 1, after its update.")
      .def_readonly("translation_cost", &AlignIteration::translation_cost,
                    "J_t of eq. (9), voxel units.")
      .def_readonly("rotation_cost", &AlignIteration::rotation_cost, "J_r of eq. (16), normalised.")
      .def_readonly("translation_step", &AlignIteration::translation_step,
                    "|lambda_t shift|, voxels.")
      .def_readonly("rotation_gradient", &AlignIteration::rotation_gradient,
                    "|grad C|, per radian.")
      .def_readonly("correlation", &AlignIteration::correlation, "Normalised EGI correlation.")
      .def_readonly("translation_peak", &AlignIteration::translation_peak,
                    "Phase-correlation peak.")
      .def_readonly("seconds", &AlignIteration::seconds, "Wall time of the iteration, seconds.")
      .def_property_readonly("T_scene_model", [](const AlignIteration& i) {
        return Eigen::Matrix4d(i.T_scene_model);
      });

  py::class_<AlignAlternative>(m, "AlignAlternative", R"doc(
Another pose that the scene supports about as well as the returned one.

Attributes: ``T_scene_model`` (4x4), ``confidence`` (as AlignResult.confidence: calibrated),
``score`` (as AlignResult.score: uncalibrated), ``inliers``,
``inlier_rmse`` (metres), ``rotation_apart`` (radians from the returned pose),
``translation_apart`` (metres between the model centroids of the two poses), ``symmetric``
(the model maps onto itself by the turn between the poses: the same answer).
)doc")
      .def_property_readonly(
          "T_scene_model",
          [](const AlignAlternative& a) { return Eigen::Matrix4d(a.T_scene_model); })
      .def_readonly("confidence", &AlignAlternative::confidence)
      .def_readonly("score", &AlignAlternative::score)
      .def_readonly("inliers", &AlignAlternative::inliers)
      .def_readonly("inlier_rmse", &AlignAlternative::inlier_rmse, "Metres.")
      .def_readonly("rotation_apart", &AlignAlternative::rotation_apart, "Radians.")
      .def_readonly("translation_apart", &AlignAlternative::translation_apart, "Metres.")
      .def_readonly("symmetric", &AlignAlternative::symmetric,
                    "True when the model maps onto itself by the turn from the returned pose "
                    "to this one: the same answer up to the object's symmetry (not ambiguous).")
      .def("__repr__", [](const AlignAlternative& a) {
        std::ostringstream out;
        out << "AlignAlternative(confidence=" << a.confidence << ", inliers=" << a.inliers
            << ", rotation_apart=" << a.rotation_apart
            << ", translation_apart=" << a.translation_apart << ")";
        return out.str();
      });

  py::class_<PoseVerification>(m, "PoseVerification", R"doc(
The scene's support of one model pose (verify_pose); counts are over model points.

Attributes
----------
inlier_distance : float
    d = 1 voxel, metres.
inliers : int
    Model points whose nearest scene point is within d (Euclidean, normals ignored).
inlier_rmse : float
    Root mean square of those nearest distances over the inliers, metres (0 with none).
inlier_fraction : float
    inliers / model points (Open3D's ``fitness`` with max distance d).
visible : int
    Model points the sensor would see: facing the viewpoint, in view and not more than
    2 voxels behind the scanned surface (all points without a viewpoint).
tight : int
    Visible points within half a voxel of the tangent plane of their nearest scene point
    within 2 voxels whose normal is within 45 degrees of theirs.
seen_through : int
    Visible points more than 2 voxels in front of the scanned surface and no inlier,
    where the sensor saw through them (0 without a viewpoint).
hidden : int
    Points facing the viewpoint, in view, more than 2 voxels behind the scanned surface:
    neither confirmed nor refuted (0 without a viewpoint).
confidence : float
    tight / visible * (1 - seen_through / visible), in [0, 1].
)doc")
      .def_readonly("inlier_distance", &PoseVerification::inlier_distance)
      .def_readonly("inliers", &PoseVerification::inliers)
      .def_readonly("inlier_rmse", &PoseVerification::inlier_rmse)
      .def_readonly("inlier_fraction", &PoseVerification::inlier_fraction)
      .def_readonly("visible", &PoseVerification::visible)
      .def_readonly("tight", &PoseVerification::tight)
      .def_readonly("seen_through", &PoseVerification::seen_through)
      .def_readonly("hidden", &PoseVerification::hidden)
      .def_readonly("confidence", &PoseVerification::confidence)
      .def("__repr__", [](const PoseVerification& v) {
        std::ostringstream out;
        out << "PoseVerification(confidence=" << v.confidence << ", inliers=" << v.inliers
            << ", inlier_rmse=" << v.inlier_rmse << ", visible=" << v.visible
            << ", tight=" << v.tight << ", seen_through=" << v.seen_through << ")";
        return out.str();
      });

  m.attr("CONFIDENCE_THRESHOLD") = kConfidenceThreshold;
  m.attr("RELIABLE_CONFIDENCE") = kReliableConfidence;

  m.def(
      "_verify_pose",
      [](const PointCloud& model, const PointCloud& scene, const py::handle& T, double voxel_size,
         std::optional<Eigen::Vector3d> viewpoint) {
        const Transform T_scene_model = to_transform(T, "T_scene_model");
        VerifyParams params;
        params.voxel_size = voxel_size;
        params.viewpoint = viewpoint;
        py::gil_scoped_release release;
        return verify_pose(model, scene, T_scene_model, params);
      },
      py::arg("model"), py::arg("scene"), py::arg("T_scene_model"), py::arg("voxel_size"),
      py::arg("viewpoint"), "verify_pose on clouds with normals; see spectral_vs.verify_pose.");

  m.def(
      "field_share",
      [](const py::handle& reference_points, const py::handle& T, const py::handle& current_points,
         double max_depth) {
        const Points reference = to_points(reference_points, "reference_points");
        const Transform T_current_reference = to_transform(T, "T_current_reference");
        const Points current = to_points(current_points, "current_points");
        return field_share(reference, T_current_reference, current, max_depth);
      },
      py::arg("reference_points"), py::arg("T_current_reference"), py::arg("current_points"),
      py::arg("max_depth") = std::numeric_limits<double>::infinity(), R"doc(
The share of ``reference_points`` that ``T_current_reference`` puts inside the current
view's field: in front of the camera (z over 1 mm), no deeper than ``max_depth`` (m) and
within the bounds of the current points' x/z and y/z (a pinhole camera's image as far as
the view has returns; at most 4000 of them, evenly strided, bound it), in [0, 1]; 0 for no
reference point or no current point in front. Occlusion is ignored. The servo divides its
tracking fitness by it. Raises ValueError for non-finite points, a T that is not rigid or
a max_depth that is not > 0.)doc");

  m.def(
      "step_score",
      [](double visible_fitness, bool carried, const py::handle& reference_points,
         const py::handle& T, const py::handle& current_points, double relocalize_fitness,
         double min_field_share, double max_depth) {
        StepScoreParams params;
        params.relocalize_fitness = relocalize_fitness;
        params.min_field_share = min_field_share;
        params.max_depth = max_depth;
        const Transform T_current_reference = to_transform(T, "T_current_reference");
        // The clouds cross into C++ only when the score reads the field (a copy of the
        // view's points is a third of a millisecond).
        StepScore score;
        if (step_score_needs_field(visible_fitness, params)) {
          score =
              step_score(visible_fitness, carried, to_points(reference_points, "reference_points"),
                         T_current_reference, to_points(current_points, "current_points"), params);
        } else {
          score =
              step_score(visible_fitness, carried, Points(), T_current_reference, Points(), params);
        }
        return py::make_tuple(score.score, score.confidence);
      },
      py::arg("visible_fitness"), py::arg("carried"), py::arg("reference_points"),
      py::arg("T_current_reference"), py::arg("current_points"), py::arg("relocalize_fitness"),
      py::arg("min_field_share") = StepScoreParams().min_field_share,
      py::arg("max_depth") = std::numeric_limits<double>::infinity(), R"doc(
The servo's judgement of one step's estimate: ``(score, confidence)``. ``score`` is
``visible_fitness`` (the registration's fitness over the reference's part no occluder
hides) from ``relocalize_fitness`` up; under it, that fitness over the share of
``reference_points`` that ``T_current_reference`` puts in the field of ``current_points``
(``field_share``, at least ``min_field_share``), at most 1. ``confidence`` is
``calibrated_confidence(score, 'servo_carried' if carried else 'servo')``. The clouds are
read only under ``relocalize_fitness``. Raises ValueError for a fitness outside [0, 1], a
``min_field_share`` outside (0, 1], and as ``field_share`` when the field is read.)doc");

  m.def(
      "calibrated_confidence",
      [](double score, const std::string& kind) {
        return calibrated_confidence(score, registration_kind(kind));
      },
      py::arg("score"), py::arg("kind"), R"doc(
The probability that an answer of uncalibrated ``score`` (in [0, 1]; clamped, NaN gives 0)
is right, by the calibration map of ``kind``: 'align' (AlignResult.score), 'views'
(ViewAlignResult.score), 'servo' (ServoRecord.score of a step whose estimate is the
registration's) or 'servo_carried' (of a step whose estimate was carried along the
odometry). The maps are the isotonic regressions fitted on the calibration sets
(docs/trust.md). Raises ValueError for another kind.)doc");

  m.def(
      "covariance_inflation",
      [](const std::string& kind) { return covariance_inflation(registration_kind(kind)); },
      py::arg("kind"),
      "The inflation k of the covariance of align() ('align') or align_views() ('views'), "
      "fitted on the calibration set (docs/trust.md).");

  m.def(
      "pose_covariance",
      [](const PointCloud& model, const PointCloud& scene, const py::handle& T, double voxel_size) {
        const Transform T_scene_model = to_transform(T, "T_scene_model");
        py::gil_scoped_release release;
        return Eigen::Matrix<double, 6, 6>(
            pose_covariance(model, scene, T_scene_model, voxel_size));
      },
      py::arg("model"), py::arg("scene"), py::arg("T_scene_model"), py::arg("voxel_size"),
      R"doc(
The 6x6 covariance of the pose error at T_scene_model, as align() reports it: rotation
vector (rad) then translation (m) of a left perturbation T_true = exp(delta) T_scene_model
in the scene frame. From the point-to-plane fit of the model (with normals) onto the scene
(with normals): pairs within voxel_size (metres) whose normals agree within 45 degrees,
the residuals' variance, an inflation calibrated on the calibration set, and a weak prior
that keeps unconstrained directions finite (docs/trust.md).
)doc");

  // The stages of AlignTimings in the order align() runs them, then the total.
  static const TimingField<AlignTimings> kTimingFields[] = {
      {"preparation", &AlignTimings::preparation,
       "The scene as searched (support plane out), the EGIs and their correlation, the "
       "single-view detection, the model's flat axis."},
      {"rotation_search", &AlignTimings::rotation_search, "The SO(3) searches of the hypotheses."},
      {"placement", &AlignTimings::placement,
       "The hypotheses placed by phase correlation and ranked by the verification's screen."},
      {"algorithm1", &AlignTimings::algorithm1,
       "Algorithm 1 from each refined hypothesis (or the guess), the sweeps and the polish."},
      {"icp", &AlignTimings::icp, "The ICP refinement of the refined hypotheses."},
      {"alternatives", &AlignTimings::alternatives,
       "The check of the pose, the alternatives, the reselection, the resting poses."},
      {"verdict", &AlignTimings::verdict, "The verdict: covariance, symmetries, calibration."},
      {"total", &AlignTimings::total, "The whole call."}};
  define_timings(m, "AlignTimings",
                 "Where the time of one align() went, by stage, seconds of the wall clock (with "
                 "threads=1, its CPU time).",
                 kTimingFields);

  py::class_<AlignResult>(m, "AlignResult", "Outcome of align().")
      .def_property_readonly(
          "T_scene_model", [](const AlignResult& r) { return Eigen::Matrix4d(r.T_scene_model); },
          "4x4 transform mapping model coordinates into the scene.")
      .def_readonly("converged", &AlignResult::converged)
      .def_property_readonly(
          "stop_reason",
          [](const AlignResult& r) { return choice_name(r.stop_reason, kStopReasons); },
          "Why the run of the returned pose stopped: 'converged', 'max_iterations', "
          "'max_seconds', 'kept_start' (global search: Algorithm 1 ended less fit than "
          "the hypothesis it started from, whose pose was kept) or 'reselected' (global "
          "search: an alternative more confident by over reselect_margin, or as confident and "
          "explaining more of its object or with more inliers, was returned).")
      .def_readonly("iterations", &AlignResult::iterations,
                    "Iterations of the Algorithm 1 run that produced the returned pose: "
                    "len(history); 0 for 'kept_start' and 'reselected'.")
      .def_readonly(
          "fitness", &AlignResult::fitness,
          "How well the scene supports the pose, in [0, 1]: the share of the model's occupied "
          "voxels next to scene points with like normals; for a single view, "
          "confirmed / (confirmed + contradicted + hidden / 2) over the pixels of the "
          "model rendered from sensor_origin.")
      .def_readonly("correlation", &AlignResult::correlation)
      .def_readonly("translation_peak", &AlignResult::translation_peak)
      .def_readonly("hypothesis", &AlignResult::hypothesis)
      .def_readonly("search_voxel_size", &AlignResult::search_voxel_size,
                    "Voxel of the global search's translation grid, metres (0 without it).")
      .def_readonly("polish_evaluations", &AlignResult::polish_evaluations,
                    "Phase correlations of the final polish (0 without).")
      .def_readonly("icp_iterations", &AlignResult::icp_iterations,
                    "Steps of the ICP refinement (0 without, or if not kept).")
      .def_readonly("refinements_run", &AlignResult::refinements_run,
                    "Global-search hypotheses refined by Algorithm 1: at most "
                    "search.refinements (those fitting under 0.65 of the best refined pose "
                    "are skipped); 0 without global search.")
      .def_property_readonly(
          "window_dims", [](const AlignResult& r) { return Eigen::Vector3i(r.window_dims); },
          "Voxels of the window Algorithm 1 ran in, per axis.")
      .def_readonly("history", &AlignResult::history,
                    "Every iteration of that run; history[-1].T_scene_model is where "
                    "Algorithm 1 ended, T_scene_model that pose after the polish and ICP.")
      .def_readonly("voxel_size", &AlignResult::voxel_size,
                    "The voxel the alignment worked at, metres (derived for voxel_size=0).")
      .def_readonly("single_view", &AlignResult::single_view,
                    "True when the scene was checked as a single view from sensor_origin "
                    "(declared, or detected by detect_single_view).")
      .def_readonly("timings", &AlignResult::timings, "Where the time went (AlignTimings).")
      .def_readonly("reliable", &AlignResult::reliable,
                    "The verdict: True when status is 'reliable' (confidence at least "
                    "RELIABLE_CONFIDENCE, no alternative as good, the search finished in time, "
                    "the voxel in range). The one field to check before acting on the pose.")
      .def_property_readonly(
          "status", [](const AlignResult& r) { return std::string(verdict_name(r.status)); },
          "The verdict in one word: 'reliable', 'ambiguous', 'doubtful', 'floating', "
          "'undetermined', 'no_support', "
          "'max_seconds', 'bad_scale' or 'unverified' (docs/trust.md).")
      .def_readonly("determined", &AlignResult::determined,
                    "True when the scene pins the pose down: two standard deviations of "
                    "the covariance within 5 degrees and, at the model's centroid, 10 mm.")
      .def_readonly("rests", &AlignResult::rests,
                    "True unless a support plane was found and the pose neither touches it "
                    "nor stands on an upward-facing surface of the scene (a flat object flush "
                    "with another object's face, the rest of it inside that object).")
      .def_readonly("confidence", &AlignResult::confidence,
                    "The probability that the pose is right (within 5 degrees and 10 mm), in "
                    "[0, 1]: score through the calibration map fitted on the calibration set.")
      .def_readonly("score", &AlignResult::score,
                    "The verification's score, uncalibrated, in [0, 1]: the share of the "
                    "model points the sensor would see that lie within half a voxel of a "
                    "scene point turned the same way, times one minus the share it saw "
                    "through.")
      .def_property_readonly(
          "covariance",
          [](const AlignResult& r) { return Eigen::Matrix<double, 6, 6>(r.covariance); },
          "6x6 covariance of the pose error: rotation vector (rad) then translation (m) of "
          "a left perturbation T_true = exp(delta) T_scene_model, scene frame.")
      .def_readonly("inliers", &AlignResult::inliers,
                    "Model points (as aligned, downsampled) within inlier_distance of their "
                    "nearest scene point.")
      .def_readonly("inlier_fraction", &AlignResult::inlier_fraction,
                    "inliers / model points (as aligned), in [0, 1].")
      .def_readonly("inlier_rmse", &AlignResult::inlier_rmse,
                    "RMS distance of the inliers to their nearest scene points, metres.")
      .def_readonly("inlier_distance", &AlignResult::inlier_distance,
                    "The inlier distance d: one voxel_size, metres.")
      .def_readonly("alternatives", &AlignResult::alternatives,
                    "Poses more than 5 degrees or 10 mm from this one (and from each other) "
                    "whose confidence is within 0.05 of this one's, best first.")
      .def_readonly("ambiguous", &AlignResult::ambiguous,
                    "True when there is an alternative that is not symmetric: the scene "
                    "does not tell the pose from another one that is not the same answer.")
      .def("__repr__", [](const AlignResult& r) {
        std::ostringstream out;
        out << "AlignResult(status='" << verdict_name(r.status)
            << "', reliable=" << (r.reliable ? "True" : "False")
            << ", converged=" << (r.converged ? "True" : "False") << ", stop_reason='"
            << choice_name(r.stop_reason, kStopReasons) << "', iterations=" << r.iterations
            << ", fitness=" << r.fitness << ", correlation=" << r.correlation
            << ", confidence=" << r.confidence << ", inliers=" << r.inliers
            << ", inlier_rmse=" << r.inlier_rmse
            << ", ambiguous=" << (r.ambiguous ? "True" : "False")
            << ", alternatives=" << r.alternatives.size() << ")";
        return out.str();
      });

  py::class_<AxisRotationStep>(m, "AxisRotationStep",
                               "One rotation step of Algorithm 1 about one axis.")
      .def_readonly("turn", &AxisRotationStep::turn,
                    "The step, radians about the axis (R <- R exp(turn hat(axis))).")
      .def_readonly("slope", &AxisRotationStep::slope, "dC/dtheta at R, per radian.")
      .def_readonly("curvature", &AxisRotationStep::curvature,
                    "d2C/dtheta2 at R, per radian^2 (0 with the gradient law).")
      .def_readonly("newton", &AxisRotationStep::newton,
                    "True for the Newton step (C concave along the axis).")
      .def_readonly("capped", &AxisRotationStep::capped,
                    "True when the step was cut to max_rotation_step.")
      .def("__repr__", [](const AxisRotationStep& s) {
        std::ostringstream out;
        out << "AxisRotationStep(turn=" << s.turn << ", slope=" << s.slope
            << ", curvature=" << s.curvature << ", newton=" << (s.newton ? "True" : "False")
            << ", capped=" << (s.capped ? "True" : "False") << ")";
        return out.str();
      });

  m.def(
      "rotation_step_about",
      [](So3Correlation& correlation, const Eigen::Matrix3d& R, const Eigen::Vector3d& axis,
         const AlignParams& params) {
        py::gil_scoped_release release;
        return rotation_step_about(correlation, R, axis, params);
      },
      py::arg("correlation"), py::arg("R"), py::arg("axis"), py::arg("params"), R"doc(
The rotation law of Algorithm 1 restricted to turns R @ expm(theta hat(axis)).

The Newton step -rotation_gain slope / curvature where the correlation is concave along
the axis, else the gradient law rotation_gain slope (``params.rotation_step``), capped at
``params.max_rotation_step``: what ``align`` steps, in one dimension.

Parameters
----------
correlation : So3Correlation
    The EGI correlation (scene as target, model as model).
R : array_like of float, shape (3, 3)
    The rotation to step from (a rotation matrix).
axis : array_like of float, shape (3,)
    Direction of the turn in the model's frame (normalised here; not zero).
params : AlignParams
    rotation_step, rotation_gain and max_rotation_step are used.

Returns
-------
AxisRotationStep
    ``turn`` (rad), ``slope``, ``curvature``, ``newton``, ``capped``.
)doc");

  py::class_<SingleViewEvidence>(m, "SingleViewEvidence",
                                 "The evidence that a scene is a single view from a point.")
      .def_readonly("visible", &SingleViewEvidence::visible,
                    "Share of the points a sensor there sees (in front, facing it, nearest "
                    "along their ray), in [0, 1].")
      .def_readonly("single_view", &SingleViewEvidence::single_view,
                    "visible >= SINGLE_VIEW_THRESHOLD.")
      .def("__repr__", [](const SingleViewEvidence& e) {
        std::ostringstream out;
        out << "SingleViewEvidence(visible=" << e.visible
            << ", single_view=" << (e.single_view ? "True" : "False") << ")";
        return out.str();
      });
  m.attr("SINGLE_VIEW_THRESHOLD") = single_view_threshold;

  m.def(
      "detect_single_view",
      [](const PointCloud& scene, const Eigen::Vector3d& sensor_origin, double tolerance) {
        py::gil_scoped_release release;
        return detect_single_view(scene, sensor_origin, tolerance);
      },
      py::arg("scene"), py::arg("sensor_origin"), py::arg("tolerance"), R"doc(
Whether ``scene`` is a single view from ``sensor_origin``: what ``align`` decides with
``scene_view='auto'``.

Parameters
----------
scene : PointCloud
    With normals, metres.
sensor_origin : array_like of float, shape (3,)
    The candidate sensor origin, scene coordinates, metres.
tolerance : float
    Metres (align uses its voxel): a point within it of the plane of its pixel's nearest
    point counts as visible.

Returns
-------
SingleViewEvidence
    ``visible`` (share of points seen from there) and ``single_view``
    (``visible >= SINGLE_VIEW_THRESHOLD``).
)doc");

  m.def(
      "alignment_voxel_size",
      [](const PointCloud& model, const PointCloud& scene) {
        return alignment_voxel_size(model, scene);
      },
      py::arg("model"), py::arg("scene"), R"doc(
The voxel ``align`` derives for ``voxel_size=0``, metres: max(extent / 12, extent /
sqrt(N)), extent the model's typical size (twice the median distance of its points from
their median), N its points (the rule of ``view_scale`` with its own constants); for a
model of one place (one point, coincident points) the scene's.
)doc");

  m.def("_align", &align, py::arg("model"), py::arg("scene"), py::arg("params"),
        py::call_guard<py::gil_scoped_release>(),
        "Algorithm 1 on clouds with normals; see spectral_vs.align.");
}

}  // namespace spectral_vs::python
