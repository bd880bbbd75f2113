// Bindings of the rotation estimation (paper, section II-C): real spherical harmonics,
// real Wigner matrices, EGI coefficients, the SO(3) correlation, the global search.
#include "conversions.hpp"

#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <sstream>

namespace spectral_vs::python {

namespace {

py::array_t<double> float_array(const py::handle& object, const char* argument) {
  auto array = py::array::ensure(object);
  if (!array) throw py::value_error(std::string(argument) + " must be an array-like of floats");
  if (array.dtype().kind() != 'f') {
    throw py::value_error(std::string(argument) +
                          " must have a floating dtype (float32 or float64), got " +
                          std::string(py::str(array.dtype())));
  }
  return py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
}

std::string shape_of(const py::array& array) {
  std::string shape = "(";
  for (py::ssize_t i = 0; i < array.ndim(); ++i)
    shape += (i ? ", " : "") + std::to_string(array.shape(i));
  return shape + (array.ndim() == 1 ? ",)" : ")");
}

/// A flat coefficient vector; its length must be B^2 (B given, or inferred when 0).
ShCoefficients to_coefficients(const py::handle& object, const char* argument, int& bandwidth) {
  const auto array = float_array(object, argument);
  if (array.ndim() != 1) {
    throw py::value_error(std::string(argument) +
                          " must be a 1-D array of B^2 coefficients, got shape " + shape_of(array));
  }
  const auto size = array.shape(0);
  if (bandwidth == 0) {
    const auto root = static_cast<int>(std::lround(std::sqrt(static_cast<double>(size))));
    if (size == 0 || py::ssize_t(root) * root != size) {
      throw py::value_error(std::string(argument) + ": length " + std::to_string(size) +
                            " is not B^2 for any bandwidth B >= 1");
    }
    bandwidth = root;
  }
  require_bandwidth(bandwidth);
  ShCoefficients out = Eigen::Map<const Eigen::VectorXd>(array.data(), size);
  require_coefficients(out, bandwidth, argument);
  return out;
}

/// Both coefficient vectors of a correlation, of one bandwidth (given or inferred).
std::pair<ShCoefficients, ShCoefficients> to_pair(const py::handle& target, const py::handle& model,
                                                  int& bandwidth) {
  ShCoefficients t = to_coefficients(target, "target_coefficients", bandwidth);
  ShCoefficients m = to_coefficients(model, "model_coefficients", bandwidth);
  return {std::move(t), std::move(m)};
}

Eigen::Matrix3d to_rotation(const py::handle& object, const char* argument) {
  const auto array = float_array(object, argument);
  if (array.ndim() != 2 || array.shape(0) != 3 || array.shape(1) != 3) {
    throw py::value_error(std::string(argument) + " must have shape (3, 3), got " +
                          shape_of(array));
  }
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = array.at(r, c);
  require_rotation(R, argument);
  return R;
}

Eigen::Vector3d to_rotation_vector(const py::handle& object, const char* argument) {
  const auto array = float_array(object, argument);
  if (array.ndim() != 1 || array.shape(0) != 3) {
    throw py::value_error(std::string(argument) + " must have shape (3,), got " + shape_of(array));
  }
  const Eigen::Vector3d v(array.at(0), array.at(1), array.at(2));
  if (!v.allFinite()) throw py::value_error(std::string(argument) + " is not finite");
  return v;
}

SphereGrid to_grid(const py::handle& object, int bandwidth) {
  require_bandwidth(bandwidth);
  const auto array = float_array(object, "grid");
  const int n = 2 * bandwidth;
  if (array.ndim() != 2 || array.shape(0) != n || array.shape(1) != n) {
    throw py::value_error("grid must have shape (2B, 2B) = (" + std::to_string(n) + ", " +
                          std::to_string(n) + ") for bandwidth " + std::to_string(bandwidth) +
                          ", got " + shape_of(array));
  }
  return Eigen::Map<const SphereGrid>(array.data(), n, n);
}

py::list matrix_list(const std::vector<Eigen::MatrixXd>& matrices) {
  py::list out;
  for (const auto& m : matrices) out.append(py::cast(Eigen::MatrixXd(m)));
  return out;
}

py::tuple correlation_tuple(const CorrelationValue& v, bool hessian) {
  if (hessian) return py::make_tuple(v.value, v.gradient, v.hessian);
  return py::make_tuple(v.value, v.gradient);
}

// Median wall time, seconds, of `repeats` calls of f after a warm-up call.
template <typename F>
double median_seconds(int repeats, F&& f) {
  f();
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    f();
    times.push_back(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  std::nth_element(times.begin(), times.begin() + repeats / 2, times.end());
  return times[repeats / 2];
}

}  // namespace

void define_rotation(py::module_& m) {
  m.def(
      "so3_exp",
      [](const py::handle& rotation_vector) {
        return exp_so3(to_rotation_vector(rotation_vector, "rotation_vector"));
      },
      py::arg("rotation_vector"), R"doc(
The rotation exp(hat(rotation_vector)): |rotation_vector| radians about its direction
(Rodrigues' formula; the update of the paper's eq. 17).

Parameters
----------
rotation_vector : array_like, shape (3,)
    Axis times angle, radians; finite.

Returns
-------
numpy.ndarray, shape (3, 3)
)doc");

  m.def(
      "so3_log", [](const py::handle& R) { return log_so3(to_rotation(R, "R")); }, py::arg("R"),
      R"doc(
The rotation vector of R: axis times angle, the angle in [0, pi] radians, with
so3_exp(so3_log(R)) = R. Computed through the quaternion, so it is well conditioned at
every angle; at exactly pi the sign of the axis is arbitrary.

Parameters
----------
R : array_like, shape (3, 3)
    A rotation matrix: finite, max |R^T R - I| and |det R - 1| at most 1e-6.

Returns
-------
numpy.ndarray, shape (3,)
)doc");

  m.def(
      "rotation_angle",
      [](const py::handle& R) {
        return rotation_distance(Eigen::Matrix3d::Identity(), to_rotation(R, "R"));
      },
      py::arg("R"), R"doc(
The angle of the rotation R, radians in [0, pi]: the geodesic distance of R from the
identity on SO(3), |so3_log(R)|. The angle between two rotations A and B is
rotation_angle(A.T @ B).
)doc");

  m.def(
      "sh_index",
      [](int l, int m) {
        if (l < 0 || l >= kMaxBandwidth || m < -l || m > l) {
          throw py::value_error("sh_index: need 0 <= l < " + std::to_string(kMaxBandwidth) +
                                " and -l <= m <= l, got l = " + std::to_string(l) +
                                ", m = " + std::to_string(m));
        }
        return sh_index(l, m);
      },
      py::arg("l"), py::arg("m"),
      "Position l*l + l + m of the coefficient (l, m) in a flat coefficient array.");

  m.def(
      "real_spherical_harmonics",
      [](const Eigen::Vector3d& direction, int lmax) {
        const int size = std::clamp(lmax, 0, kMaxBandwidth) + 1;  // an invalid lmax throws below
        Eigen::VectorXd out(size * size);
        real_spherical_harmonics(direction, lmax, out);
        return out;
      },
      py::arg("direction"), py::arg("lmax"), R"doc(
Orthonormal real spherical harmonics S^l_m(direction) for all l <= lmax.

No Condon-Shortley phase: S^1_{-1}, S^1_0, S^1_1 = sqrt(3 / (4 pi)) (y, z, x);
m > 0 terms carry cos(m phi), m < 0 terms sin(|m| phi).

Parameters
----------
direction : array_like, shape (3,)
    Any non-zero finite vector; it is normalised.
lmax : int
    Largest degree, 0 <= lmax <= 127.

Returns
-------
numpy.ndarray, shape ((lmax + 1)**2,)
    Entry l*l + l + m holds S^l_m.
)doc");

  m.def(
      "sh_coefficients",
      [](const py::handle& grid, int bandwidth) {
        const SphereGrid samples = to_grid(grid, bandwidth);
        py::gil_scoped_release release;
        return sh_coefficients(samples, bandwidth);
      },
      py::arg("grid"), py::arg("bandwidth"), R"doc(
Real spherical harmonic coefficients of a function sampled on the EGI grid.

Uses the Driscoll-Healy quadrature of the (2B, 2B) grid theta_j = pi (2j+1) / (4B),
phi_k = pi k / B (see ``sphere_grid``), exact for degrees l < B.

Parameters
----------
grid : array_like of float, shape (2B, 2B)
    Samples f(theta_j, phi_k), indexed [j, k] (the layout of ``egi``).
bandwidth : int
    B, 1 <= B <= 128.

Returns
-------
numpy.ndarray, shape (B**2,)
    Coefficient (l, m) at index l*l + l + m, l = 0..B-1, m = -l..l, for the orthonormal
    real harmonics of ``real_spherical_harmonics``.
)doc");

  m.def(
      "sh_synthesis",
      [](const py::handle& coefficients, int bandwidth) {
        const ShCoefficients c = to_coefficients(coefficients, "coefficients", bandwidth);
        py::gil_scoped_release release;
        return sh_synthesis(c, bandwidth);
      },
      py::arg("coefficients"), py::arg("bandwidth"), R"doc(
The band-limited function with these coefficients, sampled on the (2B, 2B) grid.

The inverse of ``sh_coefficients``: ``sh_synthesis(sh_coefficients(f, B), B) == f`` for any
f of degree < B.

Parameters
----------
coefficients : array_like of float, shape (B**2,)
bandwidth : int

Returns
-------
numpy.ndarray, shape (2B, 2B)
)doc");

  m.def(
      "wigner_real",
      [](const py::handle& R, int lmax) {
        const Eigen::Matrix3d rotation = to_rotation(R, "R");
        WignerMatrices U;
        {
          py::gil_scoped_release release;
          wigner_real_into(rotation, lmax, U);
        }
        return matrix_list(U);
      },
      py::arg("R"), py::arg("lmax"), R"doc(
Real Wigner matrices U^l(R), l = 0..lmax, built from R (Ivanic-Ruedenberg recursion).

Convention: if g(x) = f(R^T x), the coefficients satisfy G^l = U^l(R) F^l, i.e.
``G[l*l : (l+1)**2] = U[l] @ F[l*l : (l+1)**2]``. Each U^l is orthogonal and
U^l(R1 R2) = U^l(R1) U^l(R2).

Parameters
----------
R : array_like of float, shape (3, 3)
    A rotation matrix (orthonormal to 1e-6, determinant +1).
lmax : int
    Largest degree, 0 <= lmax <= 127.

Returns
-------
list of numpy.ndarray
    U^l with shape (2l+1, 2l+1), indexed [m + l, m' + l].
)doc");

  m.def(
      "wigner_generators",
      [](int lmax) {
        const WignerGenerators g = wigner_generators(lmax);
        return py::make_tuple(matrix_list(g.x), matrix_list(g.y), matrix_list(g.z));
      },
      py::arg("lmax"), R"doc(
Generators u^l(e_k) = d/de U^l(exp(e hat(e_k))) at e = 0, for k = x, y, z.

Constant, antisymmetric, at most two non-zeros per row; built at each call.

Returns
-------
tuple of three lists of numpy.ndarray
    (u_x, u_y, u_z), each a list over l = 0..lmax of (2l+1, 2l+1) arrays.
)doc");

  m.def(
      "egi_coefficients",
      [](const py::handle& normals_or_cloud, int bandwidth, const std::string& method,
         const py::handle& weights) {
        const Points normals = normals_of(normals_or_cloud);
        const EgiMethod parsed = parse_choice(method, kEgiMethods, "method");
        std::optional<Eigen::VectorXd> w;
        if (!weights.is_none()) {
          const auto array = float_array(weights, "weights");
          if (array.ndim() != 1)
            throw py::value_error("weights must be a 1-D array, got shape " + shape_of(array));
          w = Eigen::Map<const Eigen::VectorXd>(array.data(), array.shape(0));
        }
        py::gil_scoped_release release;
        return egi_coefficients(normals, bandwidth, parsed, w ? &*w : nullptr);
      },
      py::arg("normals_or_cloud"), py::arg("bandwidth"), py::arg("method") = "projection",
      py::arg("weights") = py::none(), R"doc(
Real SH coefficients of the Extended Gaussian Image of a set of normals.

Parameters
----------
normals_or_cloud : PointCloud or array_like of float, shape (N, 3)
    A cloud with normals, or the normals themselves (normalised here).
bandwidth : int
    B, 1 <= B <= 128; degrees l < B are computed.
method : {"projection", "histogram"}
    "projection" (default): F^l = sum_i w_i S^l(n_i), exact and rotation-covariant.
    "histogram": the paper's gridded histogram (``egi``) transformed with the grid
    quadrature; 35-67 % covariance error (docs/rotation.md).
weights : array_like of float, shape (N,), optional
    One weight per normal (default 1).

Returns
-------
numpy.ndarray, shape (B**2,)
)doc");

  m.def(
      "smooth_coefficients",
      [](const py::handle& coefficients, int bandwidth, double sigma) {
        ShCoefficients c = to_coefficients(coefficients, "coefficients", bandwidth);
        smooth_coefficients(c, bandwidth, sigma);
        return c;
      },
      py::arg("coefficients"), py::arg("bandwidth"), py::arg("sigma"), R"doc(
A copy of the coefficients blurred by the heat kernel exp(-l (l + 1) sigma**2 / 2).

Parameters
----------
coefficients : array_like of float, shape (B**2,)
bandwidth : int
sigma : float
    Width of the blur on the sphere, radians, >= 0 (0 leaves them unchanged).
)doc");

  py::class_<So3Correlation>(m, "So3Correlation", R"doc(
The correlation C(R) = sum_l (F_target^l)^T U^l(R) F_model^l with re-used buffers.

C is largest at the rotation R with target normals = R @ model normals. See
``so3_correlation`` for the normalisation and the derivatives. Not thread-safe.

Parameters
----------
target_coefficients, model_coefficients : array_like of float, shape (B**2,)
normalised : bool
    Cosine similarity over degrees l >= 1 (default), or the paper's raw sum.
)doc")
      .def(py::init([](const py::handle& target, const py::handle& model, bool normalised) {
             int bandwidth = 0;
             auto [t, f] = to_pair(target, model, bandwidth);
             return So3Correlation(t, f, bandwidth, normalised);
           }),
           py::arg("target_coefficients"), py::arg("model_coefficients"),
           py::arg("normalised") = true)
      .def(
          "evaluate",
          [](So3Correlation& self, const py::handle& R, bool hessian) {
            const Eigen::Matrix3d rotation = to_rotation(R, "R");
            CorrelationValue v;
            {
              py::gil_scoped_release release;
              v = self.evaluate(rotation, hessian);
            }
            return correlation_tuple(v, hessian);
          },
          py::arg("R"), py::arg("hessian") = false,
          "(C, gradient) or (C, gradient, hessian) at R; see so3_correlation.")
      .def_property_readonly("bandwidth", &So3Correlation::bandwidth)
      .def_property_readonly("normalised", &So3Correlation::normalised)
      .def("__repr__", [](const So3Correlation& c) {
        std::ostringstream out;
        out << "So3Correlation(bandwidth=" << c.bandwidth()
            << ", normalised=" << (c.normalised() ? "True" : "False") << ")";
        return out.str();
      });

  m.def(
      "so3_correlation",
      [](const py::handle& target, const py::handle& model, const py::handle& R, bool normalised,
         bool hessian) {
        int bandwidth = 0;
        auto [t, f] = to_pair(target, model, bandwidth);
        const Eigen::Matrix3d rotation = to_rotation(R, "R");
        CorrelationValue v;
        {
          py::gil_scoped_release release;
          So3Correlation correlation(t, f, bandwidth, normalised);
          v = correlation.evaluate(rotation, hessian);
        }
        return correlation_tuple(v, hessian);
      },
      py::arg("target_coefficients"), py::arg("model_coefficients"), py::arg("R"),
      py::arg("normalised") = true, py::arg("hessian") = false, R"doc(
The EGI correlation over SO(3) at R, with its gradient (eq. 12-15).

C(R) = sum_l (F_target^l)^T U^l(R) F_model^l is largest at the R that maps the model onto
the target (target normals = R @ model normals).

Parameters
----------
target_coefficients, model_coefficients : array_like of float, shape (B**2,)
    From ``egi_coefficients``, same bandwidth.
R : array_like of float, shape (3, 3)
    A rotation matrix.
normalised : bool
    True (default): cosine similarity of the coefficient vectors with l = 0 left out, in
    [-1, 1], so a gain means the same for any point count and bandwidth. False: the
    paper's sum over l = 0..B-1 (without its 1 / (4 pi)).
hessian : bool
    Also return the Hessian.

Returns
-------
C : float
gradient : numpy.ndarray, shape (3,)
    dC/de for the right perturbation R exp(hat(e)), per radian: the update
    R <- R @ expm(gain * hat(gradient)) climbs C (eq. 17).
hessian : numpy.ndarray, shape (3, 3)
    Only when ``hessian`` is True: d2C/de2 at e = 0, symmetric.
)doc");

  m.def(
      "rotation_cost",
      [](const py::handle& target, const py::handle& model, const py::handle& R, bool normalised) {
        int bandwidth = 0;
        auto [t, f] = to_pair(target, model, bandwidth);
        const Eigen::Matrix3d rotation = to_rotation(R, "R");
        py::gil_scoped_release release;
        return rotation_cost(t, f, rotation, bandwidth, normalised);
      },
      py::arg("target_coefficients"), py::arg("model_coefficients"), py::arg("R"),
      py::arg("normalised") = true, R"doc(
The rotation cost J_r of eq. (16): 0.5 * ||g - f(R^T .)||^2 over the sphere.

Computed from the coefficients (Parseval), in the normalisation of ``so3_correlation``:
normalised, J_r = 1 - C(R), in [0, 2].
)doc");

  m.def(
      "so3_search",
      [](const py::handle& target, const py::handle& model, int bandwidth, int k, int threads,
         bool normalised) {
        require_bandwidth(bandwidth);
        auto [t, f] = to_pair(target, model, bandwidth);
        So3SearchParams params;
        params.candidates = k;
        params.threads = threads;
        params.normalised = normalised;
        std::vector<RotationCandidate> candidates;
        {
          py::gil_scoped_release release;
          candidates = so3_search(t, f, bandwidth, params);
        }
        py::list out;
        for (const auto& c : candidates) out.append(py::make_tuple(c.R, c.correlation));
        return out;
      },
      py::arg("target_coefficients"), py::arg("model_coefficients"), py::arg("bandwidth"),
      py::arg("k") = 8, py::arg("threads") = 1, py::arg("normalised") = true, R"doc(
Global rotation search: C over all of SO(3), its k best local maxima.

C is evaluated on the (2B)**3 ZYZ Euler grid by FFTs (grid step pi / B radians, 11.25
degrees at B = 16); refine the candidates with ``refine_rotation``.

Parameters
----------
target_coefficients, model_coefficients : array_like of float, shape (B**2,)
bandwidth : int
    B; both arrays must have B**2 entries.
k : int
    Largest number of candidates returned, >= 1.
threads : int
    Worker threads, >= 1.
normalised : bool
    As in ``so3_correlation``.

Returns
-------
list of (numpy.ndarray of shape (3, 3), float)
    (R, C(R)) of distinct local maxima, best first.
)doc");

  py::class_<RotationRefineResult>(m, "RotationRefineResult", "Outcome of refine_rotation.")
      .def_readonly("R", &RotationRefineResult::R, "(3, 3) refined rotation.")
      .def_readonly("correlation", &RotationRefineResult::correlation, "C at R.")
      .def_readonly("iterations", &RotationRefineResult::iterations, "Iterations run.")
      .def_readonly("converged", &RotationRefineResult::converged,
                    "|gradient| < gradient_tolerance.")
      .def("__repr__", [](const RotationRefineResult& r) {
        std::ostringstream out;
        out << "RotationRefineResult(angle_deg=" << log_so3(r.R).norm() * 180.0 / M_PI
            << ", correlation=" << r.correlation << ", iterations=" << r.iterations
            << ", converged=" << (r.converged ? "True" : "False") << ")";
        return out.str();
      });

  const RotationRefineParams defaults;
  m.def(
      "refine_rotation",
      [](const py::handle& target, const py::handle& model, const py::handle& R0, double gain,
         int max_iterations, double gradient_tolerance, bool newton, double max_step,
         bool normalised) {
        int bandwidth = 0;
        auto [t, f] = to_pair(target, model, bandwidth);
        const Eigen::Matrix3d start = to_rotation(R0, "R0");
        RotationRefineParams params;
        params.gain = gain;
        params.max_iterations = max_iterations;
        params.gradient_tolerance = gradient_tolerance;
        params.newton = newton;
        params.max_step = max_step;
        py::gil_scoped_release release;
        So3Correlation correlation(t, f, bandwidth, normalised);
        return refine_rotation(correlation, start, params);
      },
      py::arg("target_coefficients"), py::arg("model_coefficients"), py::arg("R0"),
      py::arg("gain") = defaults.gain, py::arg("max_iterations") = defaults.max_iterations,
      py::arg("gradient_tolerance") = defaults.gradient_tolerance,
      py::arg("newton") = defaults.newton, py::arg("max_step") = defaults.max_step,
      py::arg("normalised") = true, R"doc(
Local ascent of the correlation from R0 (the paper's controller, eq. 17, made robust).

Newton steps with the analytic Hessian where C is locally concave (``newton``), else
gradient steps R <- R exp(gain hat(gradient)) whose gain is halved on an overshoot; a
step that would lower C is halved until it does not.

Parameters
----------
target_coefficients, model_coefficients : array_like of float, shape (B**2,)
R0 : array_like of float, shape (3, 3)
    Start rotation: the identity (the paper) or a candidate of ``so3_search``.
gain : float
    Initial gradient gain, radians per unit of gradient.
max_iterations : int
gradient_tolerance : float
    Converged when |gradient| falls below it (correlation per radian).
newton : bool
max_step : float
    Largest rotation of one step, radians.
normalised : bool
    As in ``so3_correlation``.

Returns
-------
RotationRefineResult
)doc");

  m.def(
      "_rotation_timings",
      [](int bandwidth, int repeats) {
        require_bandwidth(bandwidth);
        if (repeats < 1) throw py::value_error("repeats must be >= 1");
        py::dict out;
        // Coefficients of a fixed asymmetric set of normals.
        Points normals(400, 3);
        for (int i = 0; i < 400; ++i) {
          normals.row(i) << std::sin(1.3 * i), std::cos(0.7 * i * i), 0.5 + std::sin(0.1 * i);
        }
        const ShCoefficients model = egi_coefficients(normals, bandwidth);
        const Eigen::Matrix3d R = euler_zyz(0.3, 1.1, -2.0);
        const ShCoefficients target = rotate_coefficients(model, wigner_real(R, bandwidth - 1));
        double wigner = 0.0, gradient = 0.0, hessian = 0.0, search = 0.0;
        {
          py::gil_scoped_release release;
          WignerMatrices U;
          So3Correlation correlation(target, model, bandwidth);
          const Eigen::Matrix3d at = euler_zyz(0.2, 1.0, -1.9);
          wigner = median_seconds(repeats, [&] { wigner_real_into(at, bandwidth - 1, U); });
          gradient = median_seconds(repeats, [&] { correlation.evaluate(at); });
          hessian = median_seconds(repeats, [&] { correlation.evaluate(at, true); });
          search = median_seconds(std::max(1, repeats / 10),
                                  [&] { so3_search(target, model, bandwidth); });
        }
        out["wigner"] = wigner;
        out["wigner_and_gradient"] = gradient;
        out["wigner_gradient_hessian"] = hessian;
        out["search"] = search;
        return out;
      },
      py::arg("bandwidth"), py::arg("repeats"),
      "Benchmark helper: median seconds, timed in C++ on one thread, of wigner_real "
      "(l < bandwidth), So3Correlation.evaluate without and with the Hessian, and so3_search.");
}

}  // namespace spectral_vs::python
