#include "conversions.hpp"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "spectral_vs compiled core: representation, translation and rotation estimation.";
  spectral_vs::python::define_representation(m);
  spectral_vs::python::define_depth_image(m);
  spectral_vs::python::define_translation(m);
  spectral_vs::python::define_rotation(m);
  spectral_vs::python::define_alignment(m);
  spectral_vs::python::define_model_aligner(m);
  spectral_vs::python::define_view_aligner(m);
  spectral_vs::python::define_kinematics(m);
}
