// Bindings of the depth-image input (representation, section II-A): a depth camera's frame
// and its camera matrix to a cloud with normals, organized or not.
#include "conversions.hpp"

#include <spectral_vs/representation/depth_image.hpp>

#include <pybind11/stl.h>
#include <pybind11/warnings.h>

#include <cstdint>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>

namespace spectral_vs::python {

namespace {

std::string shape_of(const py::array& array) {
  std::string shape = "(";
  for (py::ssize_t i = 0; i < array.ndim(); ++i) {
    shape += (i ? ", " : "") + std::to_string(array.shape(i));
  }
  return shape + (array.ndim() == 1 ? ",)" : ")");
}

// A 3x3 array of numbers, or an Open3D PinholeCameraIntrinsic (its intrinsic_matrix); the
// content (a camera matrix) is checked in the core.
Eigen::Matrix3d to_camera_matrix(const py::handle& K) {
  py::object matrix = py::reinterpret_borrow<py::object>(K);
  if (py::hasattr(K, "intrinsic_matrix")) matrix = K.attr("intrinsic_matrix");
  auto array = py::array::ensure(matrix);
  const char kind = array ? array.dtype().kind() : 'O';
  if (!array || (kind != 'f' && kind != 'i' && kind != 'u')) {
    throw py::value_error(
        "K must be a 3x3 camera matrix of numbers [[fx, 0, cx], [0, fy, cy], "
        "[0, 0, 1]] (pixels)");
  }
  if (array.ndim() != 2 || array.shape(0) != 3 || array.shape(1) != 3) {
    throw py::value_error(
        "K must be a 3x3 camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "
        "got shape " +
        shape_of(array));
  }
  auto doubles = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = doubles.at(r, c);
  return out;
}

// A read-only (rows, columns, 3) view of an organized cloud's per-pixel rows.
py::array pixel_view(const Points& rows, int height, int width, py::handle owner) {
  const auto d = static_cast<py::ssize_t>(sizeof(double));
  py::array_t<double> view({py::ssize_t(height), py::ssize_t(width), py::ssize_t(3)},
                           {d * 3 * width, d * 3, d}, rows.data(), owner);
  view.attr("setflags")(py::arg("write") = false);
  return std::move(view);
}

// The InputWarning of a depth_scale that puts most valid depths outside what a depth
// camera measures, with the median found and the likely fix.
template <typename Image>
void warn_of_depth_scale(const Eigen::Map<const Image>& image, const DepthScaleCheck& check,
                         bool explicit_scale) {
  const bool raw = std::is_same_v<typename Image::Scalar, std::uint16_t>;
  const double median = median_depth(image, check.depth_scale);
  std::ostringstream message;
  message << "depth_scale: " << check.depth_scale << " sensor units per metre"
          << (explicit_scale ? ""
                             : (raw ? " (the default of a uint16 image, millimetres)"
                                    : " (the default of a float image, metres)"))
          << " puts " << check.valid - check.plausible << " of the " << check.valid
          << " valid depths outside " << kPlausibleMinDepth << "-" << kPlausibleMaxDepth
          << " m of the camera (median " << median << " m); ";
  if (median > kPlausibleMaxDepth) {
    message << "is depth_scale too small? "
            << (raw ? "a uint16 image in millimetres needs depth_scale=1000 (TUM RGB-D: 5000)"
                    : "a float image in millimetres needs depth_scale=1000")
            << ", which would put the median at " << median * check.depth_scale / 1000.0 << " m";
  } else if (median >= kPlausibleMinDepth) {
    message << "the depths are spread on both sides of that range: is this a depth image?";
  } else {
    message << "is depth_scale too large (swapped for its inverse, or applied twice)? "
            << (raw ? "a uint16 image in millimetres needs depth_scale=1000"
                    : "a float image in metres needs depth_scale=1 (the default)")
            << ", which would put the median at "
            << median * check.depth_scale / (raw ? 1000.0 : 1.0) << " m";
  }
  message << ". The cloud is returned as computed.";
  py::warnings::warn(message.str().c_str(),
                     py::module_::import("spectral_vs._core").attr("InputWarning"), 1);
}

template <typename Scalar>
py::object from_depth(const py::array& array, const Eigen::Matrix3d& K,
                      const DepthCloudParams& params, bool organized) {
  using Image = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  auto values = py::array_t<Scalar, py::array::c_style | py::array::forcecast>::ensure(array);
  const Eigen::Map<const Image> image(values.data(), values.shape(0), values.shape(1));
  py::object result;
  DepthScaleCheck check;
  if (organized) {
    OrganizedCloud cloud;
    {
      py::gil_scoped_release release;
      cloud = organized_cloud_from_depth(image, K, params);
      check = check_depth_scale(image, params.depth_scale);
    }
    result = py::cast(std::move(cloud));
  } else {
    PointCloud cloud;
    {
      py::gil_scoped_release release;
      cloud = cloud_from_depth(image, K, params);
      check = check_depth_scale(image, params.depth_scale);
    }
    result = py::cast(std::move(cloud));
  }
  if (!check.ok()) warn_of_depth_scale(image, check, params.depth_scale.has_value());
  return result;
}

const char* kCloudFromDepthDoc = R"doc(
The point cloud of a depth image, with unit normals toward the camera, in the camera frame.

Pixel (v, u) at depth d (metres) is the point d ((u - cx) / fx, (v - cy) / fy, 1) (X right,
Y down, Z along the optical axis). The normal of a pixel is the cross product of the
central differences of its neighbours' points ``normal_step`` pixels away along the row
and the column, summed over a ``window`` x ``window`` neighbourhood (an area-weighted mean
that tames depth noise), turned toward the camera; a pixel whose four stencil neighbours
are not all valid and within ``max_depth_jump`` times its depth of it (a hole, a
silhouette edge, the image border) has no normal.

Parameters
----------
depth : ndarray (height, width)
    uint16 in sensor units (metres = value / depth_scale; 0: no return), or float32 /
    float64 in metres (NaN, inf or 0: no return).
K : array_like (3, 3)
    Camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels (or an Open3D
    ``PinholeCameraIntrinsic``).
depth_scale : float, optional
    Sensor units per metre. Default: 1000 for uint16 images (millimetres: Kinect,
    RealSense, Azure Kinect; TUM RGB-D files use 5000), 1 for float images (metres).
    When at most half of the valid depths (finite, > 0) lie within 0.05-50 m at this
    scale, an ``InputWarning`` names depth_scale, the median depth and the likely fix
    (a float image in millimetres needs depth_scale=1000).
min_depth, max_depth : float
    Pixels nearer or farther, metres, are invalid (default 0 and inf: none truncated).
stride : int
    Keep the pixels whose row and column are multiples of stride (>= 1); the normals
    still use every pixel.
organized : bool
    Return an ``OrganizedCloud`` (every pixel of the strided image, NaN where invalid)
    instead of a ``PointCloud`` of the valid pixels.
normals : bool
    Compute normals. Without them every valid pixel is kept; with them only those with a
    normal (the result may be empty when none has one: isolated pixels).
normal_step, window, max_depth_jump : int, int, float
    The stencil's half-baseline (pixels, >= 1), the averaging window (odd, >= 1) and the
    largest relative depth change to a stencil neighbour (> 0).

Returns
-------
PointCloud or OrganizedCloud
    The valid pixels in row-major order; with ``organized=True`` all of them.

Warns
-----
InputWarning
    When most valid depths lie outside 0.05-50 m at depth_scale (see depth_scale).

Raises
------
ValueError
    For a depth that is not a 2-D uint16 / float32 / float64 array or is empty, a K that
    is not a camera matrix (shape, non-finite entries, fx or fy <= 0, skew, a bottom row
    other than (0, 0, 1)), a depth_scale <= 0, a depth range with max_depth <= min_depth,
    bad normal settings, or an image without a valid pixel.
)doc";

}  // namespace

void define_depth_image(py::module_& m) {
  py::warnings::new_warning_type(m, "InputWarning", PyExc_UserWarning).attr("__doc__") =
      "Input that is accepted but probably not what was meant, named by its argument: a "
      "depth_scale that puts most depths outside 0.05-50 m, a viewpoint inside the cloud it "
      "orients normals toward.";
  py::class_<DepthScaleCheck>(m, "DepthScaleCheck", R"doc(
How the depths of an image fall at a depth scale (``check_depth_scale``).

Attributes
----------
depth_scale : float
    The scale used, sensor units per metre.
valid : int
    Pixels whose depth is finite and > 0.
plausible : int
    Of them, those within 0.05-50 m.
ok : bool
    False when there are valid pixels and at most half of them are plausible.
)doc")
      .def_readonly("depth_scale", &DepthScaleCheck::depth_scale)
      .def_readonly("valid", &DepthScaleCheck::valid)
      .def_readonly("plausible", &DepthScaleCheck::plausible)
      .def_property_readonly("ok", &DepthScaleCheck::ok)
      .def("__repr__", [](const DepthScaleCheck& c) {
        std::ostringstream out;
        out << "DepthScaleCheck(depth_scale=" << c.depth_scale << ", valid=" << c.valid
            << ", plausible=" << c.plausible << ")";
        return out.str();
      });
  py::class_<OrganizedCloud>(m, "OrganizedCloud", R"doc(
The cloud of a depth image pixel by pixel (of the strided image), camera frame.

Attributes
----------
height, width : int
    Pixels of the strided image: ceil(rows / stride) and ceil(columns / stride).
points : ndarray (height, width, 3)
    Read-only; metres, NaN where the pixel is invalid (what ``load_organized`` gives for
    an organized file).
normals : ndarray (height, width, 3) or None
    Read-only unit normals toward the camera, NaN where a pixel has none; None when they
    were not computed.
valid : ndarray (height, width) of bool
    Pixels with a point and, with normals, a normal: the rows of ``valid_cloud()``.
)doc")
      .def_readonly("height", &OrganizedCloud::height)
      .def_readonly("width", &OrganizedCloud::width)
      .def_property_readonly("points",
                             [](py::object self) {
                               const auto& c = self.cast<const OrganizedCloud&>();
                               return pixel_view(c.points, c.height, c.width, self);
                             })
      .def_property_readonly("normals",
                             [](py::object self) -> py::object {
                               const auto& c = self.cast<const OrganizedCloud&>();
                               if (!c.has_normals()) return py::none();
                               return pixel_view(c.normals, c.height, c.width, self);
                             })
      .def_property_readonly("has_normals", &OrganizedCloud::has_normals)
      .def_property_readonly(
          "valid",
          [](const OrganizedCloud& c) {
            py::array_t<bool> mask({py::ssize_t(c.height), py::ssize_t(c.width)});
            bool* out = mask.mutable_data();
            for (Eigen::Index i = 0; i < c.points.rows(); ++i) out[i] = c.valid(i);
            return mask;
          })
      .def("valid_cloud", &OrganizedCloud::valid_cloud, py::call_guard<py::gil_scoped_release>(),
           "The valid pixels' points (and normals) in row-major order, as a PointCloud: what "
           "cloud_from_depth returns with organized=False.")
      .def("__repr__", [](const OrganizedCloud& c) {
        std::size_t valid = 0;
        for (Eigen::Index i = 0; i < c.points.rows(); ++i) valid += c.valid(i);
        std::ostringstream out;
        out << "OrganizedCloud(height=" << c.height << ", width=" << c.width << ", " << valid
            << " valid pixels, " << (c.has_normals() ? "with" : "no") << " normals)";
        return out.str();
      });

  m.def(
      "check_depth_scale",
      [](const py::handle& depth, std::optional<double> depth_scale) {
        auto array = py::array::ensure(depth);
        if (!array || array.ndim() != 2) throw py::value_error("depth must be a 2-D image");
        const char kind = array.dtype().kind();
        const auto size = array.dtype().itemsize();
        const auto check = [&](auto scalar) {
          using Scalar = decltype(scalar);
          using Image = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
          auto values =
              py::array_t<Scalar, py::array::c_style | py::array::forcecast>::ensure(array);
          const Eigen::Map<const Image> image(values.data(), values.shape(0), values.shape(1));
          py::gil_scoped_release release;
          return check_depth_scale(image, depth_scale);
        };
        if (kind == 'u' && size == 2) return check(std::uint16_t{});
        if (kind == 'f' && size == 4) return check(float{});
        if (kind == 'f' && size == 8) return check(double{});
        throw py::value_error("depth must have dtype uint16, float32 or float64, got " +
                              std::string(py::str(array.dtype())));
      },
      py::arg("depth"), py::kw_only(), py::arg("depth_scale") = py::none(),
      "How many of the image's valid depths (finite, > 0) lie within 0.05-50 m at "
      "depth_scale (default as cloud_from_depth's): the check behind its InputWarning.");

  m.def(
      "cloud_from_depth",
      [](const py::handle& depth, const py::handle& K, std::optional<double> depth_scale,
         double min_depth, double max_depth, int stride, bool organized, bool normals,
         int normal_step, int window, double max_depth_jump) {
        auto array = py::array::ensure(depth);
        if (!array) throw py::value_error("depth must be a 2-D array (height, width)");
        if (array.ndim() != 2) {
          throw py::value_error("depth must be a 2-D image (height, width), got shape " +
                                shape_of(array));
        }
        DepthCloudParams params;
        params.normal_step = normal_step;
        params.window = window;
        params.max_depth_jump = max_depth_jump;
        params.stride = stride;
        params.depth_scale = depth_scale;
        params.min_depth = min_depth;
        params.max_depth = max_depth;
        params.normals = normals;
        const Eigen::Matrix3d camera = to_camera_matrix(K);
        const char kind = array.dtype().kind();
        const auto size = array.dtype().itemsize();
        if (kind == 'u' && size == 2)
          return from_depth<std::uint16_t>(array, camera, params, organized);
        if (kind == 'f' && size == 4) return from_depth<float>(array, camera, params, organized);
        if (kind == 'f' && size == 8) return from_depth<double>(array, camera, params, organized);
        throw py::value_error(
            "depth must have dtype uint16 (sensor units, see depth_scale) or float32 / float64 "
            "(metres), got " +
            std::string(py::str(array.dtype())));
      },
      py::arg("depth"), py::arg("K"), py::kw_only(), py::arg("depth_scale") = py::none(),
      py::arg("min_depth") = 0.0, py::arg("max_depth") = std::numeric_limits<double>::infinity(),
      py::arg("stride") = 1, py::arg("organized") = false, py::arg("normals") = true,
      py::arg("normal_step") = 2, py::arg("window") = 5, py::arg("max_depth_jump") = 0.05,
      kCloudFromDepthDoc);
}

}  // namespace spectral_vs::python
