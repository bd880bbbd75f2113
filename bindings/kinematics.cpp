// Bindings of the robot kinematics (paper, section II-D, eq. 18): the chain from a URDF,
// the camera Jacobian and the damped least-squares joint velocity command.
#include "conversions.hpp"
#include "settings.hpp"

#include <spectral_vs/kinematics/kinematics.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <filesystem>
#include <sstream>

namespace spectral_vs::python {

namespace {

// A 1-D float array of a given length (or any length when expected < 0), as float64.
Eigen::VectorXd to_vector(const py::handle& object, const char* argument, Eigen::Index expected) {
  auto array = py::array::ensure(object);
  if (!array ||
      (array.dtype().kind() != 'f' && array.dtype().kind() != 'i' && array.dtype().kind() != 'u')) {
    throw py::value_error(std::string(argument) + " must be a 1-D array of numbers");
  }
  if (array.ndim() != 1) {
    throw py::value_error(std::string(argument) + " must be 1-D, got " +
                          std::to_string(array.ndim()) + " dimensions");
  }
  if (expected >= 0 && array.shape(0) != expected) {
    throw py::value_error(std::string(argument) + ": expected " + std::to_string(expected) +
                          " entries, got " + std::to_string(array.shape(0)));
  }
  auto doubles = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
  return Eigen::Map<const Eigen::VectorXd>(doubles.data(), array.shape(0));
}

Eigen::MatrixXd to_matrix(const py::handle& object, const char* argument) {
  auto array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(object);
  if (!array || array.ndim() != 2)
    throw py::value_error(std::string(argument) + " must be a 2-D array");
  Eigen::MatrixXd out(array.shape(0), array.shape(1));
  for (py::ssize_t r = 0; r < array.shape(0); ++r)
    for (py::ssize_t c = 0; c < array.shape(1); ++c) out(r, c) = array.at(r, c);
  return out;
}

Transform camera_offset(const py::handle& T) {
  return T.is_none() ? Transform::Identity() : to_transform(T, "T_tip_camera");
}

std::string joint_list(const std::vector<int>& joints) {
  std::ostringstream out;
  out << "[";
  for (std::size_t i = 0; i < joints.size(); ++i) out << (i ? ", " : "") << joints[i];
  out << "]";
  return out.str();
}

}  // namespace

void define_kinematics(py::module_& m) {
  py::class_<DampingParams> damping_params(m, "DampingParams", R"doc(
Damping of the least-squares pseudo-inverse (Nakamura; Chiaverini).

With s_min the smallest singular value of J, ``lambda^2 = (1 - (s_min / eps)^2) lambda_max^2``
when ``s_min < eps`` and 0 otherwise; ``x = sum_i s_i / (s_i^2 + lambda^2) v_i u_i^T b``.

Attributes
----------
singular_value_threshold : float
    eps, where damping starts (units of J: m/rad for linear rows, 1 for angular rows).
max_damping : float
    lambda_max, the damping at s_min = 0 (same unit).
)doc");
  define_settings(damping_params)
      .def_readwrite("singular_value_threshold", &DampingParams::singular_value_threshold)
      .def_readwrite("max_damping", &DampingParams::max_damping);

  py::class_<DampedSolution>(m, "DampedSolution", "x = J^+ b with the damping that was used.")
      .def_readonly("x", &DampedSolution::x)
      .def_readonly("damping", &DampedSolution::damping)
      .def_readonly("min_singular_value", &DampedSolution::min_singular_value)
      .def("__repr__", [](const DampedSolution& s) {
        std::ostringstream out;
        out << "DampedSolution(damping=" << s.damping
            << ", min_singular_value=" << s.min_singular_value << ")";
        return out.str();
      });

  m.def(
      "damped_least_squares",
      [](const py::handle& J, const py::handle& b, const DampingParams& params) {
        const Eigen::MatrixXd matrix = to_matrix(J, "J");
        return damped_least_squares(matrix, to_vector(b, "b", -1), params);
      },
      py::arg("J"), py::arg("b"), py::arg("params") = DampingParams{},
      "x = J^+ b with the damped pseudo-inverse of DampingParams (SVD of J).");

  py::class_<VelocityCommandParams> command_params(m, "VelocityCommandParams", R"doc(
Settings of :meth:`Kinematics.joint_velocities`.

Attributes
----------
dt : float
    Control period, s: no joint may cross a position limit within it.
position_margin : float
    Distance kept from every position limit, rad (m for prismatic joints).
max_joint_speed : float
    Cap on every joint speed on top of the URDF velocity limits, rad/s (m/s).
damping : DampingParams
    Damping of the pseudo-inverse.
limit_avoidance_gain : float
    k, 1/s: joint-limit avoidance in the null space of the camera Jacobian,
    ``q_dot += (I - J^+ J) q_dot_0`` with ``q_dot_0_i = -k h_i sign(x_i) |x_i|^p``,
    ``x_i = (q_i - m_i) / h_i`` (m_i the middle of the range, h_i half of it). A joint at a
    limit is pushed at ``k h_i`` rad/s; the camera twist is unchanged. 0 turns it off.
limit_avoidance_exponent : float
    p >= 1: 1 is linear centring, larger values push mostly near the limits.
)doc");
  define_settings(command_params)
      .def_readwrite("dt", &VelocityCommandParams::dt)
      .def_readwrite("position_margin", &VelocityCommandParams::position_margin)
      .def_readwrite("max_joint_speed", &VelocityCommandParams::max_joint_speed)
      .def_readwrite("damping", &VelocityCommandParams::damping)
      .def_readwrite("limit_avoidance_gain", &VelocityCommandParams::limit_avoidance_gain)
      .def_readwrite("limit_avoidance_exponent", &VelocityCommandParams::limit_avoidance_exponent);

  py::class_<VelocityCommand>(m, "VelocityCommand",
                              "A joint velocity command and how the limits shaped it.")
      .def_readonly("q_dot", &VelocityCommand::q_dot,
                    "Joint velocities, rad/s (m/s for prismatic joints).")
      .def_readonly("damping", &VelocityCommand::damping, "lambda of the last least-squares solve.")
      .def_readonly("min_singular_value", &VelocityCommand::min_singular_value,
                    "Smallest singular value of the camera Jacobian at q.")
      .def_readonly("velocity_scale", &VelocityCommand::velocity_scale,
                    "Uniform factor in (0, 1] applied to meet the velocity limits.")
      .def_readonly("position_limited", &VelocityCommand::position_limited,
                    "Indices of the joints clamped at a position limit.")
      .def("__repr__", [](const VelocityCommand& c) {
        std::ostringstream out;
        out << "VelocityCommand(|q_dot|=" << c.q_dot.norm() << ", damping=" << c.damping
            << ", min_singular_value=" << c.min_singular_value
            << ", velocity_scale=" << c.velocity_scale
            << ", position_limited=" << joint_list(c.position_limited) << ")";
        return out.str();
      });

  py::class_<Kinematics>(m, "Kinematics", R"doc(
A serial chain of a URDF with a camera rigidly mounted on its tip link.

Parameters
----------
urdf_path : str or os.PathLike
    URDF file (meshes are not needed).
base_link : str
    Link whose frame poses and Jacobians refer to.
tip_link : str
    Link the camera is mounted on; must lie below ``base_link``.
T_tip_camera : array_like, shape (4, 4), optional
    Rigid pose of the camera in the tip frame (camera: Z forward, X right, Y down).
    Identity by default.

Raises
------
FileNotFoundError
    If ``urdf_path`` does not exist.
ValueError
    If the URDF does not parse, a link is missing, the tip is not below the base, a
    joint is floating or planar, or ``T_tip_camera`` is not rigid.
)doc")
      .def(py::init([](const std::filesystem::path& path, const std::string& base,
                       const std::string& tip, const py::handle& T_tip_camera) {
             require_file(path, "urdf_path");
             return Kinematics(path.string(), base, tip, camera_offset(T_tip_camera));
           }),
           py::arg("urdf_path"), py::arg("base_link"), py::arg("tip_link"),
           py::arg("T_tip_camera") = py::none())
      .def_static(
          "from_urdf_string",
          [](const std::string& xml, const std::string& base, const std::string& tip,
             const py::handle& T_tip_camera) {
            return Kinematics::from_urdf_string(xml, base, tip, camera_offset(T_tip_camera));
          },
          py::arg("urdf_xml"), py::arg("base_link"), py::arg("tip_link"),
          py::arg("T_tip_camera") = py::none(),
          "The same from the XML text of a URDF (a ROS robot_description).")
      .def_property_readonly("joint_count", &Kinematics::joint_count)
      .def_property_readonly("joint_names", &Kinematics::joint_names,
                             "Movable joints from base to tip.")
      .def_property_readonly("lower_limits", &Kinematics::lower_limits,
                             "rad or m; -inf for continuous joints.")
      .def_property_readonly("upper_limits", &Kinematics::upper_limits,
                             "rad or m; +inf for continuous joints.")
      .def_property_readonly("velocity_limits", &Kinematics::velocity_limits,
                             "rad/s or m/s from the URDF; +inf where it gives none.")
      .def_property_readonly("base_link", &Kinematics::base_link)
      .def_property_readonly("tip_link", &Kinematics::tip_link)
      .def_property_readonly("T_tip_camera", &Kinematics::T_tip_camera)
      .def(
          "tip_pose",
          [](const Kinematics& k, const py::handle& q) {
            return k.tip_pose(to_vector(q, "q", k.joint_count()));
          },
          py::arg("q"), "T_base_tip, the (4, 4) pose of the tip link in the base frame.")
      .def(
          "forward",
          [](const Kinematics& k, const py::handle& q) {
            return k.forward(to_vector(q, "q", k.joint_count()));
          },
          py::arg("q"), "T_base_camera, the (4, 4) pose of the camera in the base frame.")
      .def(
          "jacobian",
          [](const Kinematics& k, const py::handle& q) {
            return k.jacobian(to_vector(q, "q", k.joint_count()));
          },
          py::arg("q"), R"doc(
J_c, shape (6, n): q_dot -> camera twist (v, omega) of the camera origin, in the camera frame.
)doc")
      .def(
          "joint_velocities",
          [](const Kinematics& k, const py::handle& q, const py::handle& twist,
             const VelocityCommandParams& params) {
            const Eigen::VectorXd joints = to_vector(q, "q", k.joint_count());
            const Twist camera_twist = to_vector(twist, "camera_twist", 6);
            return k.joint_velocities(joints, camera_twist, params);
          },
          py::arg("q"), py::arg("camera_twist"), py::arg("params") = VelocityCommandParams{}, R"doc(
q_dot = J_c^+ camera_twist with the damped pseudo-inverse and the joint limits respected.

The joint-limit avoidance (``limit_avoidance_gain``) adds a push toward the middles of the
joint ranges in the null space of J_c: it never changes the camera twist. Joints that would come within ``position_margin`` of a limit within ``dt`` are clamped and
the rest of the twist is re-solved with the other joints; then the vector is scaled
uniformly so that every speed stays within min(URDF limit, ``max_joint_speed``).

Parameters
----------
q : array_like, shape (n,)
    Joint positions, rad (m for prismatic joints).
camera_twist : array_like, shape (6,)
    (v, omega) of the camera in the camera frame, m/s and rad/s.
params : VelocityCommandParams
)doc")
      .def("__repr__", [](const Kinematics& k) {
        std::ostringstream out;
        out << "Kinematics(" << k.base_link() << " -> " << k.tip_link() << ", " << k.joint_count()
            << " joints)";
        return out.str();
      });
}

}  // namespace spectral_vs::python
