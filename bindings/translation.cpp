// Bindings of the translation estimation (paper, section II-B).
#include "conversions.hpp"

#include <spectral_vs/translation/phase_correlation.hpp>

#include <pybind11/stl.h>

#include <optional>
#include <sstream>

namespace spectral_vs::python {

namespace {

// A VoxelGrid as is, or a 3-D float array taken as a grid of unit voxels at the origin.
VoxelGrid to_grid(const py::handle& object, const char* argument) {
  if (py::isinstance<VoxelGrid>(object)) {
    VoxelGrid grid = object.cast<VoxelGrid>();
    if (grid.empty()) throw py::value_error(std::string(argument) + " is empty: no occupied voxel");
    return grid;
  }
  auto array = py::array::ensure(object);
  if (!array || array.ndim() != 3) {
    throw py::value_error(std::string(argument) + " must be a VoxelGrid or a 3-D array");
  }
  const char kind = array.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u' && kind != 'b') {
    throw py::value_error(std::string(argument) + " must hold numbers, got dtype " +
                          std::string(py::str(array.dtype())));
  }
  auto values = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  VoxelGrid grid;
  grid.spec.resolution = 1.0;
  grid.spec.dims = {int(array.shape(0)), int(array.shape(1)), int(array.shape(2))};
  grid.values.assign(values.data(), values.data() + values.size());
  grid.occupied_min = grid.spec.dims;
  grid.occupied_max = Eigen::Vector3i::Constant(-1);
  for (int i = 0; i < grid.spec.dims.x(); ++i)
    for (int j = 0; j < grid.spec.dims.y(); ++j)
      for (int k = 0; k < grid.spec.dims.z(); ++k) {
        const float v = grid.at(i, j, k);
        if (!std::isfinite(v))
          throw py::value_error(std::string(argument) + " has non-finite values");
        if (v != 0.0f) {
          grid.occupied_min = grid.occupied_min.cwiseMin(Eigen::Vector3i(i, j, k));
          grid.occupied_max = grid.occupied_max.cwiseMax(Eigen::Vector3i(i, j, k));
        }
      }
  if (grid.empty()) throw py::value_error(std::string(argument) + " is empty: no occupied voxel");
  return grid;
}

PhaseCorrelationParams make_params(bool subvoxel, double band, int threads, long long max_voxels) {
  PhaseCorrelationParams params;
  params.subvoxel = subvoxel;
  params.subvoxel_band = band;
  params.threads = threads;
  params.limits.max_voxels = to_max_voxels(max_voxels);
  return params;
}

}  // namespace

void define_translation(py::module_& m) {
  py::class_<TranslationEstimate>(m, "TranslationEstimate", R"doc(
Shift of a moving grid onto a target: target(x) ~ moving(x - shift).

Attributes
----------
shift : ndarray (3,)
    Refined shift, metres (shift_voxels times the grid's resolution).
shift_voxels : ndarray (3,)
    Refined shift, voxels.
peak_voxels : ndarray (3,) of int
    Integer correlation peak, voxels.
peak : float
    Normalised peak height in [0, 1]: 1 for exact shifts of one grid, near 0 for no match.
)doc")
      .def_readonly("shift", &TranslationEstimate::shift, "Refined shift, metres.")
      .def_readonly("shift_voxels", &TranslationEstimate::shift_voxels, "Refined shift, voxels.")
      .def_readonly("peak_voxels", &TranslationEstimate::peak_voxels,
                    "Integer correlation peak, voxels.")
      .def_readonly("peak", &TranslationEstimate::peak, "Normalised peak height in [0, 1].")
      .def("__repr__", [](const TranslationEstimate& e) {
        std::ostringstream out;
        out << "TranslationEstimate(shift=[" << e.shift.x() << ", " << e.shift.y() << ", "
            << e.shift.z() << "], shift_voxels=[" << e.shift_voxels.x() << ", "
            << e.shift_voxels.y() << ", " << e.shift_voxels.z() << "], peak_voxels=["
            << e.peak_voxels.x() << ", " << e.peak_voxels.y() << ", " << e.peak_voxels.z()
            << "], peak=" << e.peak << ")";
        return out.str();
      });

  py::class_<PhaseCorrelation>(m, "PhaseCorrelation", R"doc(
Phase correlation (eq. 7) against a cached target on a fixed grid, FFTW plans made once.

Parameters
----------
spec : GridSpec
subvoxel : bool
    Refine the integer peak by fitting the cross-power spectrum's phase plane.
subvoxel_band : float
    Frequencies used by that fit, cycles per voxel, in (0, 0.5].
threads : int
    FFTW threads, in [1, 256].
max_voxels : int
    Grids with more voxels are refused before any buffer is allocated (about 20 bytes
    per voxel).
)doc")
      .def(py::init([](const GridSpec& spec, bool subvoxel, double band, int threads,
                       long long max_voxels) {
             return PhaseCorrelation(spec, make_params(subvoxel, band, threads, max_voxels));
           }),
           py::arg("spec"), py::arg("subvoxel") = true, py::arg("subvoxel_band") = 0.25,
           py::arg("threads") = 1,
           py::arg("max_voxels") = static_cast<long long>(GridLimits{}.max_voxels))
      .def("set_target", &PhaseCorrelation::set_target, py::arg("target"),
           py::call_guard<py::gil_scoped_release>())
      .def(
          "estimate",
          [](PhaseCorrelation& self, const VoxelGrid& moving,
             std::optional<Eigen::Vector3i> max_shift_voxels) {
            py::gil_scoped_release release;
            return max_shift_voxels ? self.estimate(moving, *max_shift_voxels)
                                    : self.estimate(moving);
          },
          py::arg("moving"), py::arg("max_shift_voxels") = py::none(),
          "Shift of `moving` onto the target; `max_shift_voxels` (voxels per axis, integers) "
          "bounds the search.")
      .def_property_readonly("has_target", &PhaseCorrelation::has_target)
      .def_property_readonly("spec", &PhaseCorrelation::spec);

  m.def(
      "phase_correlation",
      [](const py::handle& grid_a, const py::handle& grid_b, bool subvoxel, double band,
         long long max_voxels) {
        const VoxelGrid a = to_grid(grid_a, "grid_a");
        const VoxelGrid b = to_grid(grid_b, "grid_b");
        TranslationEstimate estimate;
        {
          py::gil_scoped_release release;
          estimate = phase_correlation(a, b, make_params(subvoxel, band, 1, max_voxels));
        }
        return estimate;
      },
      py::arg("grid_a"), py::arg("grid_b"), py::arg("subvoxel") = true,
      py::arg("subvoxel_band") = 0.25,
      py::arg("max_voxels") = static_cast<long long>(GridLimits{}.max_voxels), R"doc(
The shift of grid_a onto grid_b, grid_b(x) ~ grid_a(x - shift), as a TranslationEstimate:
``shift`` in metres, ``shift_voxels``, ``peak_voxels`` and the peak height in [0, 1].

Grids are VoxelGrids on the same spec or 3-D arrays of the same shape (taken as unit
voxels at the origin: there ``shift`` equals ``shift_voxels``). Only shifts for which the
occupied parts overlap are searched. Grids over ``max_voxels`` voxels are refused before
the transforms are allocated.
)doc");

  m.def(
      "translation_cost",
      [](const py::handle& moving, const py::handle& target, const Eigen::Vector3i& shift) {
        return translation_cost(to_grid(moving, "moving"), to_grid(target, "target"), shift);
      },
      py::arg("moving"), py::arg("target"), py::arg("shift_voxels"),
      "J_t of eq. (9): 0.5 * sum (target(x) - moving(x - shift))^2 for an integer shift in "
      "voxels (TranslationEstimate.peak_voxels).");
}

}  // namespace spectral_vs::python
