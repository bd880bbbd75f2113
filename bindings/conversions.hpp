#pragma once
// numpy <-> Eigen conversions with the checks a Python user needs: dtype, shape and
// finiteness errors name the argument, as ValueError.

#include <spectral_vs/representation/point_cloud.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>

#include "common/paths.hpp"

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

namespace spectral_vs::python {

namespace py = pybind11;

/// The rows of an (N, 3) array of `Scalar`s (native byte order, any strides) into `out`.
template <typename Scalar>
void copy_rows(const py::array& array, Points& out) {
  const auto* base = static_cast<const char*>(array.data());
  const py::ssize_t row_stride = array.strides(0), column_stride = array.strides(1);
  for (py::ssize_t i = 0; i < array.shape(0); ++i) {
    const char* row = base + i * row_stride;
    for (py::ssize_t j = 0; j < 3; ++j) {
      Scalar value;  // memcpy: a numpy view need not be aligned
      std::memcpy(&value, row + j * column_stride, sizeof(Scalar));
      out(i, j) = static_cast<double>(value);
    }
  }
}

/// An (N, 3) array of any floating dtype and memory layout, copied to float64 rows.
/// Integer, boolean and object arrays are refused: silently casting them hides bugs.
inline Points to_points(const py::handle& object, const char* argument) {
  auto array = py::array::ensure(object);
  if (!array) throw py::value_error(std::string(argument) + " must be an array-like of floats");
  const char kind = array.dtype().kind();
  if (kind != 'f') {
    throw py::value_error(std::string(argument) +
                          " must have a floating dtype (float32 or float64), got " +
                          std::string(py::str(array.dtype())));
  }
  if (array.ndim() != 2 || array.shape(1) != 3) {
    std::string shape = "(";
    for (py::ssize_t i = 0; i < array.ndim(); ++i)
      shape += (i ? ", " : "") + std::to_string(array.shape(i));
    throw py::value_error(std::string(argument) + " must have shape (N, 3), got " + shape + ")");
  }
  Points out(array.shape(0), 3);
  // float64 and float32 are read in place, whatever their strides: a servo's (N, 6) frame
  // split into points and normals is two strided views, and a cast to a contiguous copy
  // first cost 0.7 ms of a 71 k-point frame.
  if (py::isinstance<py::array_t<double>>(array)) {
    copy_rows<double>(array, out);
  } else if (py::isinstance<py::array_t<float>>(array)) {
    copy_rows<float>(array, out);
  } else {  // float16, long double, another byte order: cast first
    auto doubles = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
    std::copy(doubles.data(), doubles.data() + doubles.size(), out.data());
  }
  return out;
}

/// A read-only numpy view of `matrix`, kept alive by `owner`.
template <typename Matrix>
py::array readonly_view(const Matrix& matrix, py::handle owner) {
  using Scalar = typename Matrix::Scalar;
  static_assert(Matrix::IsRowMajor || Matrix::ColsAtCompileTime == 1, "row-major expected");
  py::array_t<Scalar> view(
      {static_cast<py::ssize_t>(matrix.rows()), static_cast<py::ssize_t>(matrix.cols())},
      {static_cast<py::ssize_t>(sizeof(Scalar) * matrix.cols()),
       static_cast<py::ssize_t>(sizeof(Scalar))},
      matrix.data(), owner);
  view.attr("setflags")(py::arg("write") = false);
  return std::move(view);
}

/// A 4 x 4 float array checked to be a rigid transform.
inline Transform to_transform(const py::handle& object, const char* argument) {
  auto array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(object);
  if (!array || array.ndim() != 2 || array.shape(0) != 4 || array.shape(1) != 4) {
    throw py::value_error(std::string(argument) + " must be a (4, 4) array");
  }
  Transform T;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) T(r, c) = array.at(r, c);
  require_rigid_transform(T, argument);
  return T;
}

/// The names a string setting accepts and the enum value of each.
template <typename Enum, std::size_t N>
using Choices = std::array<std::pair<const char*, Enum>, N>;

/// The value named `name`; otherwise ValueError "<argument> must be 'a', 'b' or 'c', got 'x'".
template <typename Enum, std::size_t N>
Enum parse_choice(const std::string& name, const Choices<Enum, N>& choices, const char* argument) {
  std::string valid;
  for (std::size_t i = 0; i < N; ++i) {
    if (name == choices[i].first) return choices[i].second;
    valid += (i == 0 ? "'" : (i + 1 == N ? " or '" : ", '")) + std::string(choices[i].first) + "'";
  }
  throw py::value_error(std::string(argument) + " must be " + valid + ", got '" + name + "'");
}

/// The name of `value` among `choices`.
template <typename Enum, std::size_t N>
const char* choice_name(Enum value, const Choices<Enum, N>& choices) {
  for (const auto& [name, choice] : choices) {
    if (choice == value) return name;
  }
  return "unknown";
}

inline constexpr Choices<Occupancy, 3> kOccupancies{{{"binary", Occupancy::binary},
                                                     {"count", Occupancy::count},
                                                     {"trilinear", Occupancy::trilinear}}};
inline constexpr Choices<EgiMethod, 2> kEgiMethods{
    {{"projection", EgiMethod::projection}, {"histogram", EgiMethod::histogram}}};

/// The normals of a PointCloud (which must have them) or an (N, 3) float array of normals.
/// A voxel budget from Python: an int >= 1, named (a negative int otherwise fails the
/// size_t conversion with a message that names no limit).
inline std::size_t to_max_voxels(long long value) {
  if (value < 1) {
    throw py::value_error("max_voxels must be >= 1 (a voxel budget), got " + std::to_string(value));
  }
  const GridLimits limits{static_cast<std::size_t>(value)};
  check_grid_limits(limits);  // refused where it is set, as well as where it is used
  return limits.max_voxels;
}

[[noreturn]] inline void raise_path_error(PyObject* type, const char* argument,
                                          const std::string& what,
                                          const std::filesystem::path& path) {
  PyErr_SetString(type, (std::string(argument) + ": " + what + ": " + path.string()).c_str());
  throw py::error_already_set();
}

// What a reader is given must be a regular file: a folder, a FIFO (whose reader would
// block) or a symbolic link loop is named as such, not as a missing file.
inline void require_file(const std::filesystem::path& path, const char* argument) {
  using detail::PathKind;
  const PathKind kind = detail::path_kind(path);
  PyObject* const type = kind == PathKind::loop      ? PyExc_OSError
                         : kind == PathKind::missing ? PyExc_FileNotFoundError
                         : kind == PathKind::folder  ? PyExc_IsADirectoryError
                                                     : PyExc_ValueError;
  if (kind != PathKind::file) raise_path_error(type, argument, detail::path_problem(kind), path);
}

inline Points normals_of(const py::handle& object) {
  if (py::isinstance<PointCloud>(object)) {
    const auto& cloud = object.cast<const PointCloud&>();
    require_normals(cloud, "cloud");
    return cloud.normals();
  }
  return to_points(object, "normals");
}

void define_representation(py::module_& m);
void define_depth_image(py::module_& m);
void define_translation(py::module_& m);
void define_rotation(py::module_& m);
void define_alignment(py::module_& m);
void define_model_aligner(py::module_& m);
void define_view_aligner(py::module_& m);
void define_kinematics(py::module_& m);

}  // namespace spectral_vs::python
