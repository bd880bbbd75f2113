// Bindings of ModelAligner: one model aligned onto many scenes (visual servoing).
#include "conversions.hpp"

#include <spectral_vs/alignment/model_aligner.hpp>
#include <spectral_vs/alignment/plane_turn.hpp>

#include <pybind11/stl.h>

#include <sstream>

namespace spectral_vs::python {

namespace {

void define_plane_turn(py::module_& m) {
  const PlaneTurnParams defaults;
  py::class_<PlaneTurn>(m, "PlaneTurn", R"doc(
The turn about a reference view's dominant plane (a table top): the registration's
rotation law along the plane's normal, on the EGIs of the normals off the plane (C++
``PlaneTurn``, the servo's ``ServoParams.plane``). Made once per reference by ``of``.
)doc")
      .def_static(
          "of",
          [](const PointCloud& reference, double plane_cone, double min_plane_share, int stride,
             int bandwidth, int fine_bandwidth, double max_tilt, const AlignParams& law) {
            PlaneTurnParams params;
            params.plane_cone = plane_cone;
            params.min_plane_share = min_plane_share;
            params.stride = stride;
            params.bandwidth = bandwidth;
            params.fine_bandwidth = fine_bandwidth;
            params.max_tilt = max_tilt;
            params.law = law;
            py::gil_scoped_release release;
            return PlaneTurn::of(reference, params);
          },
          py::arg("reference"), py::kw_only(), py::arg("plane_cone") = defaults.plane_cone,
          py::arg("min_plane_share") = defaults.min_plane_share,
          py::arg("stride") = defaults.stride, py::arg("bandwidth") = defaults.bandwidth,
          py::arg("fine_bandwidth") = defaults.fine_bandwidth,
          py::arg("max_tilt") = defaults.max_tilt, py::arg("law") = defaults.law, R"doc(
The turn of a reference view, or None when it has no dominant plane.

Parameters
----------
reference : PointCloud
    The reference view with normals, as captured.
plane_cone : float
    Half-angle about the dominant normal whose normals are the plane's, rad, in (0, pi/2).
min_plane_share : float
    None when less than this share of the reference's normals lies in the cone.
stride : int
    Every stride-th normal is read, >= 1.
bandwidth, fine_bandwidth : int
    B of the coarse step (the registration's) and of the fine one near the goal (the
    larger of the two is used), in [2, 64].
max_tilt : float
    No turn while the current view's plane normal is farther than this from where the
    estimate puts the reference's, rad.
law : AlignParams
    The rotation law (rotation_step, max_rotation_step; the gain is taken as 1).
)doc")
      .def(
          "turn",
          [](const PlaneTurn& self, const PointCloud& current, const py::handle& T) {
            const Transform T_current_reference = to_transform(T, "T_current_reference");
            py::gil_scoped_release release;
            return self.turn(current, T_current_reference.topLeftCorner<3, 3>());
          },
          py::arg("current"), py::arg("T_current_reference"),
          "The turn about ``axis`` (rad, right-multiplied: ``R exp(turn axis)``) that ascends "
          "the correlation of the off-plane EGIs from the estimate ``T_current_reference``, "
          "given the current view (with normals, as captured); 0 when it shows too few "
          "normals off its plane or its plane is tilted past max_tilt.")
      .def_property_readonly(
          "axis", [](const PlaneTurn& self) { return Eigen::Vector3d(self.axis()); },
          "The reference's dominant normal, reference frame (unit).");
}

}  // namespace

void define_model_aligner(py::module_& m) {
  py::class_<ModelAlignerTimings>(m, "ModelAlignerTimings",
                                  "Where the time of the last ModelAligner.align went, seconds.")
      .def_readonly("scene_coefficients", &ModelAlignerTimings::scene_coefficients,
                    "The scene's EGI coefficients and the correlation's set-up.")
      .def_readonly("scene_map", &ModelAlignerTimings::scene_map,
                    "The verification's set-up: the extent of its voxel screen.")
      .def_readonly("translation_grid", &ModelAlignerTimings::translation_grid,
                    "Grid spec, FFT plans when its size changed, the scene's voxels and spectrum.")
      .def_readonly("rotation", &ModelAlignerTimings::rotation,
                    "EGI correlation and rotation steps.")
      .def_readonly("translation", &ModelAlignerTimings::translation,
                    "The model's voxels and the phase correlation.")
      .def_readonly("records", &ModelAlignerTimings::records,
                    "J_t and J_r of the iteration records.")
      .def_readonly("fitness", &ModelAlignerTimings::fitness,
                    "The verification's fitness and check of the result, and the verdict.")
      .def_readonly("icp", &ModelAlignerTimings::icp,
                    "The ICP after Algorithm 1 (AlignParams.local_icp).")
      .def_readonly("total", &ModelAlignerTimings::total, "The whole call.")
      .def("__repr__", [](const ModelAlignerTimings& t) {
        std::ostringstream out;
        out << "ModelAlignerTimings(total=" << t.total << ")";
        return out.str();
      });

  py::class_<ModelAligner>(m, "ModelAligner", R"doc(
One model aligned onto many scenes with the same settings.

``align(scene)`` returns what ``align(model, scene, params)`` returns (the same pose to
rounding). With ``global_search = False`` and ``max_translation > 0`` (the servo's bounded
search) the model's side is prepared once (centred points, EGI coefficients) and the FFT
plans of the translation grid are kept while its size stays the same; otherwise each call
runs the plain alignment. ``align`` may be called from several threads: calls on one
object share its buffers and run one after the other (the GIL is released while they
wait); use one ModelAligner per thread for parallel alignments.

Parameters
----------
model : PointCloud
    The model, with normals (prepared: downsampled as ``align`` would).
params : AlignParams
    Settings of every alignment; ``initial_guess`` is the default start.
)doc")
      .def(py::init<const PointCloud&, const AlignParams&>(), py::arg("model"), py::arg("params"))
      .def(
          "align",
          [](ModelAligner& self, const PointCloud& scene, const py::handle& initial_guess) {
            const Transform guess = initial_guess.is_none()
                                        ? self.params().initial_guess
                                        : to_transform(initial_guess, "initial_guess");
            py::gil_scoped_release release;
            return self.align(scene, guess);
          },
          py::arg("scene"), py::arg("initial_guess") = py::none(),
          "Aligns the model onto ``scene`` (with normals) from ``initial_guess`` (T_scene_model, "
          "4x4; params.initial_guess by default): an AlignResult.")
      .def_property_readonly(
          "params", [](const ModelAligner& a) { return AlignParams(a.params()); },
          "A copy of the settings.")
      .def_property_readonly(
          "model", [](const ModelAligner& a) { return PointCloud(a.model()); },
          "The model (a copy).")
      .def_property_readonly(
          "model_coefficients",
          [](const ModelAligner& a) { return ShCoefficients(a.model_coefficients()); },
          "The model's EGI coefficients, shape (bandwidth**2,).")
      .def_property_readonly(
          "last_timings",
          [](const ModelAligner& a) { return ModelAlignerTimings(a.last_timings()); },
          "Stage times of the last align (a copy).")
      .def("__repr__", [](const ModelAligner& a) {
        std::ostringstream out;
        out << "ModelAligner(points=" << a.model().size()
            << ", voxel_size=" << a.params().scene.voxel_size
            << ", bandwidth=" << a.params().scene.bandwidth << ")";
        return out.str();
      });

  define_plane_turn(m);
}

}  // namespace spectral_vs::python
