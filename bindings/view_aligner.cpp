// Bindings of align_views: two views of one scene registered globally.
#include "conversions.hpp"
#include "settings.hpp"
#include "timings.hpp"

#include <spectral_vs/alignment/view_aligner.hpp>

#include <pybind11/stl.h>

#include <sstream>
#include <string>

namespace spectral_vs::python {

namespace {

const char* kViewAlignParamsDoc = R"doc(
Settings of ``align_views``; every length 0 by default: derived from the views.

Takes its fields as keyword arguments, ``ViewAlignParams(hypotheses=24, threads=2)``; the
repr shows every field.

Attributes
----------
voxel_size : float
    Voxel of Algorithm 1's grid and of the support check, m; 0: ``view_scale``'s
    ``max(extent / voxels_across, 3 extent / sqrt(N))``.
search_voxel_size : float
    Voxel of the hypotheses' placement grid, m; 0: twice the voxel.
voxels_across : float
    With voxel_size 0: voxels across the larger view's typical size (twice the median
    distance of its points from their median), >= 4 (default 32).
downsample : bool
    Downsample both views to half a voxel first (default True).
bandwidth : int
    B of the EGIs and of the SO(3) search, in [2, 64] (default 16).
hypotheses : int
    Rotations of the SO(3) search placed and checked, >= 1 (default 16).
refinements : int
    Best-checked hypotheses refined by Algorithm 1 and the ICP, in [1, hypotheses].
refinement_iterations : int
    Iterations of Algorithm 1 per refinement, >= 1.
icp_refinement : bool
    Point-to-plane ICP after Algorithm 1, kept where it does not lower the score.
window_search_below : float
    The window search runs when the kept pose's score is under this, in [0, 1] (0:
    never; default 0.03): the rotation searched again on windows of the current view as
    large as the reference.
sensor_origin : ndarray (3,)
    The current view's sensor origin in its coordinates, m (the origin for a depth
    camera's cloud in its own frame), as AlignParams.sensor_origin.
max_seconds : float
    Time budget, s (0: none).
threads : int
    Threads for FFTW and the SO(3) search, in [1, 256].
occupancy : str
    'binary', 'count' or 'trilinear' voxels (default 'trilinear').
egi_method : str
    'projection' or 'histogram' EGI coefficients.
max_voxels : int
    Largest grid allowed, voxels.
)doc";

std::string repr(const ViewSupport& s) {
  std::ostringstream out;
  out << "ViewSupport(score=" << s.score << ", fitness=" << s.fitness << ", overlap=" << s.overlap
      << ", confirmed=" << s.confirmed << ", contradicted=" << s.contradicted
      << ", hidden=" << s.hidden << ")";
  return out.str();
}

// The current view's sensor origin from 3 numbers, metres; ValueError naming `name`.
void set_origin(ViewAlignParams& p, const py::handle& value, const char* name) {
  const auto array = py::array_t<double, py::array::forcecast>::ensure(value);
  if (!array || array.size() != 3)
    throw py::value_error(std::string(name) + " must be 3 numbers (metres)");
  p.sensor_origin = Eigen::Vector3d(array.at(0), array.at(1), array.at(2));
}

}  // namespace

void define_view_aligner(py::module_& m) {
  py::class_<ViewScale>(m, "ViewScale", "The lengths a registration works at, metres.")
      .def_readonly("voxel_size", &ViewScale::voxel_size, "Voxel of Algorithm 1 and the check, m.")
      .def_readonly("search_voxel_size", &ViewScale::search_voxel_size,
                    "Voxel of the hypotheses' placement, m.")
      .def_readonly("extent", &ViewScale::extent,
                    "The larger view's typical size: twice the median distance of its points from "
                    "their median, m.")
      .def("__repr__", [](const ViewScale& s) {
        std::ostringstream out;
        out << "ViewScale(voxel_size=" << s.voxel_size
            << ", search_voxel_size=" << s.search_voxel_size << ", extent=" << s.extent << ")";
        return out.str();
      });

  m.def(
      "view_scale",
      [](const PointCloud& reference, const PointCloud& current, double voxels_across) {
        return view_scale(reference, current, voxels_across);
      },
      py::arg("reference"), py::arg("current"), py::arg("voxels_across") = 32.0,
      "The scale align_views derives from two views: voxel max(extent / voxels_across, "
      "3 extent / sqrt(N)) with extent twice the median distance of the larger view's points "
      "from their median, search voxel twice that.");

  py::class_<ViewAlignParams> params(m, "ViewAlignParams", kViewAlignParamsDoc);
  define_settings(params)
      .def_readwrite("voxel_size", &ViewAlignParams::voxel_size)
      .def_readwrite("search_voxel_size", &ViewAlignParams::search_voxel_size)
      .def_readwrite("voxels_across", &ViewAlignParams::voxels_across)
      .def_readwrite("downsample", &ViewAlignParams::downsample)
      .def_readwrite("bandwidth", &ViewAlignParams::bandwidth)
      .def_readwrite("hypotheses", &ViewAlignParams::hypotheses)
      .def_readwrite("refinements", &ViewAlignParams::refinements)
      .def_readwrite("refinement_iterations", &ViewAlignParams::refinement_iterations)
      .def_readwrite("icp_refinement", &ViewAlignParams::icp_refinement)
      .def_readwrite("window_search_below", &ViewAlignParams::window_search_below)
      .def_property(
          "sensor_origin",
          [](const ViewAlignParams& p) { return Eigen::Vector3d(p.sensor_origin); },
          [](ViewAlignParams& p, const py::handle& value) {
            set_origin(p, value, "sensor_origin");
          })
      .def_readwrite("max_seconds", &ViewAlignParams::max_seconds)
      .def_readwrite("threads", &ViewAlignParams::threads)
      .def_property(
          "occupancy",
          [](const ViewAlignParams& p) { return choice_name(p.occupancy, kOccupancies); },
          [](ViewAlignParams& p, const std::string& s) {
            p.occupancy = parse_choice(s, kOccupancies, "occupancy");
          })
      .def_property(
          "egi_method",
          [](const ViewAlignParams& p) { return choice_name(p.egi_method, kEgiMethods); },
          [](ViewAlignParams& p, const std::string& s) {
            p.egi_method = parse_choice(s, kEgiMethods, "egi_method");
          })
      .def_property(
          "max_voxels", [](const ViewAlignParams& p) { return p.limits.max_voxels; },
          [](ViewAlignParams& p, long long v) { p.limits.max_voxels = to_max_voxels(v); });

  py::class_<ViewSupport>(m, "ViewSupport", R"doc(
How well the current view supports a pose of the reference: the reference, moved by the
pose, rendered from the current view's sensor in pixels of half a voxel, each pixel
compared with the current view's depth there.

Attributes
----------
confirmed, contradicted, hidden : int
    Pixels where the current view has the surface (within a voxel, normals within 45
    degrees); saw through it or a surface turned another way; saw something nearer.
reference_pixels : int
    confirmed + contradicted + hidden: the reference's pixels inside the current's field.
fitness : float
    confirmed / (confirmed + contradicted + hidden / 2), in [0, 1].
overlap : float
    Share of the reference's points (a selection of at most 4000) that lie on a surface
    of the current view turned their way, in [0, 1]: about the views' overlap when the
    pose is right.
score : float
    fitness * overlap, in [0, 1]: what ranks the hypotheses.
)doc")
      .def_readonly("confirmed", &ViewSupport::confirmed)
      .def_readonly("contradicted", &ViewSupport::contradicted)
      .def_readonly("hidden", &ViewSupport::hidden)
      .def_readonly("reference_pixels", &ViewSupport::reference_pixels)
      .def_readonly("fitness", &ViewSupport::fitness)
      .def_readonly("overlap", &ViewSupport::overlap)
      .def_readonly("score", &ViewSupport::score)
      .def("__repr__", [](const ViewSupport& s) { return repr(s); });

  py::class_<ViewAlternative>(m, "ViewAlternative", R"doc(
Another pose of the reference that the current view supports about as well as the returned
one: ``T_current_reference`` (4x4), ``confidence`` (calibrated), ``score`` (uncalibrated),
``rotation_apart`` (radians from the returned pose), ``translation_apart`` (metres between
the reference centroids of the two poses).
)doc")
      .def_property_readonly(
          "T_current_reference",
          [](const ViewAlternative& a) { return Transform(a.T_current_reference); })
      .def_readonly("confidence", &ViewAlternative::confidence)
      .def_readonly("score", &ViewAlternative::score)
      .def_readonly("rotation_apart", &ViewAlternative::rotation_apart, "Radians.")
      .def_readonly("translation_apart", &ViewAlternative::translation_apart, "Metres.")
      .def_readonly("symmetric", &ViewAlternative::symmetric)
      .def("__repr__", [](const ViewAlternative& a) {
        std::ostringstream out;
        out << "ViewAlternative(confidence=" << a.confidence << ", score=" << a.score
            << ", rotation_apart=" << a.rotation_apart
            << ", translation_apart=" << a.translation_apart << ")";
        return out.str();
      });

  // The stages of ViewAlignTimings in the order align_views() runs them, then the total.
  static const TimingField<ViewAlignTimings> kTimingFields[] = {
      {"preparation", &ViewAlignTimings::preparation,
       "The scale, the views downsampled and balanced, their EGIs and correlation, the "
       "verification's depth image, the ICP's grids."},
      {"hypotheses", &ViewAlignTimings::hypotheses,
       "The SO(3) search, its rotations refined, placed by phase correlation, checked."},
      {"refinement", &ViewAlignTimings::refinement,
       "Algorithm 1 and the ICP from the prior and the best hypotheses."},
      {"window_search", &ViewAlignTimings::window_search,
       "The window search and its refinements (0: it did not run)."},
      {"verdict", &ViewAlignTimings::verdict,
       "The verification, the alternatives, the covariance, the verdict."},
      {"total", &ViewAlignTimings::total, "The whole call."}};
  define_timings(m, "ViewAlignTimings",
                 "Where the time of one align_views() went, by stage, seconds of the wall clock "
                 "(with threads=1, its CPU time).",
                 kTimingFields);

  py::class_<ViewAlignResult>(m, "ViewAlignResult", R"doc(
Outcome of ``align_views``.

Attributes
----------
T_current_reference : ndarray (4, 4)
    Maps reference points into the current view's coordinates.
reliable : bool
    The verdict: True when status is 'reliable' (confidence at least RELIABLE_CONFIDENCE,
    no alternative as good, the search finished in time, the voxel in range). The one
    field to check before acting on the pose.
status : str
    The verdict in one word: 'reliable'; 'ambiguous' (an alternative scores as well);
    'doubtful' (confidence under RELIABLE_CONFIDENCE); 'undetermined' (a direction of the
    pose left free: its covariance is wider than 5 degrees or 10 mm); 'no_support' (no pose the search
    tried is supported: the views share nothing, or too little for the search);
    'max_seconds' (the budget ran out: the best pose found in time); 'bad_scale' (a voxel
    over half or under 1/1000 of the reference's typical size).
determined : bool
    The current view pins the pose down: two standard deviations of the covariance
    within 5 degrees and, at the reference's centroid, 10 mm.
confidence : float
    The probability that the pose is right, in [0, 1]: score through the calibration map
    fitted on the calibration set (docs/trust.md).
score : float
    The verification's score, uncalibrated, in [0, 1]: confirmed / sqrt(visible x
    checked) over at most 8000 reference points, times support.fitness (docs/trust.md).
covariance : ndarray (6, 6)
    Covariance of the pose error: rotation vector (rad) then translation (m) of a left
    perturbation T_true = exp(delta) T_current_reference, current frame.
alternatives : list of ViewAlternative
    Other poses (over 5 degrees or a voxel apart) scoring within 0.05 of this one, ICP
    refined, best first, at most 3.
ambiguous : bool
    True when there is an alternative that is not symmetric (the same answer up to the
    reference's own symmetry).
inliers, inlier_fraction, inlier_rmse, inlier_distance : int, float, float, float
    Checked reference points within inlier_distance (one voxel, metres) of their nearest
    current point, their share of the checked points, and their RMS distance (metres).
converged : bool
    The search ran to its end within max_seconds. Says nothing of whether the pose is
    right: ``reliable`` does.
support : ViewSupport
    Of the returned pose.
correlation : float
    Normalised EGI correlation at the returned rotation.
scale : ViewScale
    The voxel sizes it worked at.
hypothesis : int
    Index of the kept hypothesis (the search's in order of correlation, then the window
    search's; -1: the prior).
icp_iterations : int
    ICP steps of the kept pose (0 without, or when the ICP was not kept).
windows : int
    Windows the window search checked (0: it did not run).
hypotheses : list of (ndarray (4, 4), ViewSupport)
    Every checked hypothesis, best score first.
timings : ViewAlignTimings
    Where the time went, by stage.
)doc")
      .def_property_readonly(
          "T_current_reference",
          [](const ViewAlignResult& r) { return Transform(r.T_current_reference); })
      .def_readonly("reliable", &ViewAlignResult::reliable)
      .def_property_readonly(
          "status", [](const ViewAlignResult& r) { return std::string(verdict_name(r.status)); })
      .def_readonly("determined", &ViewAlignResult::determined)
      .def_readonly("confidence", &ViewAlignResult::confidence)
      .def_readonly("score", &ViewAlignResult::score)
      .def_property_readonly(
          "covariance",
          [](const ViewAlignResult& r) { return Eigen::Matrix<double, 6, 6>(r.covariance); })
      .def_readonly("alternatives", &ViewAlignResult::alternatives)
      .def_readonly("ambiguous", &ViewAlignResult::ambiguous)
      .def_readonly("inliers", &ViewAlignResult::inliers)
      .def_readonly("inlier_fraction", &ViewAlignResult::inlier_fraction)
      .def_readonly("inlier_rmse", &ViewAlignResult::inlier_rmse)
      .def_readonly("inlier_distance", &ViewAlignResult::inlier_distance)
      .def_readonly("converged", &ViewAlignResult::converged)
      .def_readonly("support", &ViewAlignResult::support)
      .def_readonly("correlation", &ViewAlignResult::correlation)
      .def_readonly("scale", &ViewAlignResult::scale)
      .def_readonly("hypothesis", &ViewAlignResult::hypothesis)
      .def_readonly("icp_iterations", &ViewAlignResult::icp_iterations)
      .def_readonly("windows", &ViewAlignResult::windows)
      .def_readonly("hypotheses", &ViewAlignResult::hypotheses)
      .def_readonly("timings", &ViewAlignResult::timings)
      .def("__repr__", [](const ViewAlignResult& r) {
        std::ostringstream out;
        out << "ViewAlignResult(status='" << verdict_name(r.status)
            << "', reliable=" << (r.reliable ? "True" : "False") << ", confidence=" << r.confidence
            << ", score=" << r.score << ", converged=" << (r.converged ? "True" : "False")
            << ", voxel_size=" << r.scale.voxel_size << ")";
        return out.str();
      });

  m.def(
      "view_support",
      [](const PointCloud& reference, const PointCloud& current, const py::handle& T,
         const ViewAlignParams& p) {
        const Transform pose = to_transform(T, "T_current_reference");
        py::gil_scoped_release release;
        return view_support(reference, current, pose, p);
      },
      py::arg("reference"), py::arg("current"), py::arg("T_current_reference"),
      py::arg("params") = ViewAlignParams(),
      "The support of a pose of the reference in the current view, as align_views scores "
      "its refined poses (a ViewSupport).");

  m.def(
      "align_views",
      [](const PointCloud& reference, const PointCloud& current, const ViewAlignParams& p,
         const py::handle& prior) {
        std::optional<Transform> pose;
        if (!prior.is_none()) pose = to_transform(prior, "prior");
        py::gil_scoped_release release;
        return align_views(reference, current, p, pose);
      },
      py::arg("reference"), py::arg("current"), py::arg("params") = ViewAlignParams(),
      py::arg("prior") = py::none(),
      "Registers the reference view onto the current view (both with normals toward their "
      "sensors): a ViewAlignResult whose T_current_reference maps reference points into the "
      "current view. A prior T_current_reference (4 x 4) is refined and scored beside the "
      "search's hypotheses and kept (hypothesis -1) unless a searched pose is better "
      "supported.");
}

}  // namespace spectral_vs::python
