// Bindings of ModelAligner: one model aligned onto many scenes (visual servoing).
#include "conversions.hpp"

#include <spectral_vs/alignment/model_aligner.hpp>

#include <pybind11/stl.h>

#include <sstream>

namespace spectral_vs::python {

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
}

}  // namespace spectral_vs::python
