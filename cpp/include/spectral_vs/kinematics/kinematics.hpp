#pragma once
/// @file kinematics.hpp
/// Robot kinematics for the servo law q_dot = J_c^+ X_dot_c (paper, section II-D, eq. 18):
/// the chain from a URDF, forward kinematics of a camera rigidly mounted on the tip, the
/// Jacobian in the camera frame, and a damped least-squares joint velocity command that
/// respects the joint limits. Built on orocos KDL and urdfdom, which the header hides.

#include <spectral_vs/representation/point_cloud.hpp>

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace spectral_vs {

/// 6 x n Jacobian: rows (v_x, v_y, v_z, omega_x, omega_y, omega_z), one column per joint.
using Jacobian = Eigen::Matrix<double, 6, Eigen::Dynamic>;

/// Twist (v, omega): linear velocity in m/s, then angular velocity in rad/s.
using Twist = Eigen::Matrix<double, 6, 1>;

/// Damping of the least-squares pseudo-inverse (Nakamura and Hanafusa 1986; Chiaverini 1997).
///
/// With s_min the smallest singular value of J, the damping is
///   lambda^2 = (1 - (s_min / singular_value_threshold)^2) * max_damping^2  if s_min < threshold,
///   lambda^2 = 0                                                            otherwise,
/// and x = sum_i s_i / (s_i^2 + lambda^2) v_i u_i^T b. Far from singularities this is the
/// exact pseudo-inverse. The gain |x| / |b| of every singular direction stays bounded: by
/// 1 / threshold when max_damping >= threshold / sqrt(2) (the defaults give 1 / 0.05 = 20),
/// else by 1 / (2 max_damping sqrt(1 - (max_damping / threshold)^2)).
/// The singular values of a camera Jacobian mix m/rad (linear rows) and 1 (angular rows).
struct DampingParams {
  double singular_value_threshold = 0.05;  ///< epsilon: damping starts below it, m/rad or 1. > 0.
  double max_damping = 0.05;               ///< lambda_max: damping at s_min = 0, same unit. >= 0.
};

/// The solution of a damped least-squares problem J x = b and what the damping did.
struct DampedSolution {
  Eigen::VectorXd x;                ///< The solution, one entry per column of J.
  double damping = 0.0;             ///< lambda used (0 when s_min >= threshold).
  double min_singular_value = 0.0;  ///< Smallest of the min(rows, cols) singular values of J.
};

/// x = J^+_lambda b with the damping rule of DampingParams (singular values of J from an SVD).
/// @throws std::invalid_argument if J is empty or non-finite, b has the wrong size or is
/// non-finite, or the parameters are out of range.
DampedSolution damped_least_squares(const Eigen::MatrixXd& J, const Eigen::VectorXd& b,
                                    const DampingParams& params = {});

/// Settings of the joint velocity command for a camera twist.
struct VelocityCommandParams {
  /// Control period, s: no joint may cross a position limit within it. > 0.
  double dt = 0.05;
  /// Distance kept from each position limit, rad (m for prismatic joints). >= 0.
  double position_margin = 0.01;
  /// Cap on every |q_dot_i| on top of the URDF velocity limits, rad/s (m/s). > 0.
  double max_joint_speed = std::numeric_limits<double>::infinity();
  /// Damping of the pseudo-inverse.
  DampingParams damping;
  /// Joint-limit avoidance in the redundancy (gradient projection, Liegeois 1977): the
  /// command becomes q_dot = J^+ v + (I - J^+ J) q_dot_0 with, for every bounded joint,
  ///   q_dot_0,i = -gain * h_i * sign(x_i) |x_i|^exponent,  x_i = (q_i - m_i) / h_i,
  /// m_i the middle of its range and h_i half the range (x_i clipped to [-1, 1]):
  /// q_dot_0 = -gain grad H for H = sum_i h_i^2 |x_i|^(exponent + 1) / (exponent + 1).
  /// In 1/s: with exponent 1 every joint would drift to its middle with time constant
  /// 1 / gain; a joint at a limit is pushed at gain * h_i rad/s. The push acts only
  /// through the null space of J (of the unclamped joints), so it never changes the
  /// camera twist; a 6-joint chain (no redundancy) is unaffected away from singularities.
  /// 0 turns it off (the minimum-norm solution of eq. 18). >= 0, finite.
  /// Default 0.5 1/s with exponent 3, against 0 on `spectral-vs servo-sim --set large
  /// --starts 20` (iiwa, seed 0): the same success (12/20 stopping at a limit, 14/20
  /// sliding), the redundant joints' median closest approach to a limit 0.53 rad against
  /// 0.48; other gains not measured (docs/kinematics.md, "Joint-limit avoidance").
  double limit_avoidance_gain = 0.5;
  /// Shape of the push: 1 is Liegeois' linear centring, larger values leave joints near
  /// their middle almost free and push hard only near the limits. >= 1, finite.
  double limit_avoidance_exponent = 3.0;
};

/// A joint velocity command and how the limits shaped it.
struct VelocityCommand {
  /// Joint velocities, rad/s (m/s for prismatic joints).
  Eigen::VectorXd q_dot;
  /// lambda of the last least-squares solve.
  double damping = 0.0;
  /// s_min of the camera Jacobian at q.
  double min_singular_value = 0.0;
  /// Uniform factor in (0, 1] applied to meet the velocity limits.
  double velocity_scale = 1.0;
  /// Indices of the joints whose velocity was clamped at a position limit.
  std::vector<int> position_limited;
};

/// A serial chain from `base_link` to `tip_link` of a URDF, with a camera rigidly mounted
/// on the tip at `T_tip_camera` (camera frame: Z forward, X right, Y down).
///
/// Joint order is the order along the chain from the base; fixed joints are folded in.
/// Revolute, continuous and prismatic joints are supported; continuous joints have
/// infinite position limits; a missing or non-positive URDF velocity limit means
/// unlimited. The object is immutable and its const methods are thread-safe.
class Kinematics {
 public:
  /// @param urdf_path    URDF file; meshes are not needed.
  /// @param base_link    Link whose frame the poses are expressed in.
  /// @param tip_link     Link the camera is mounted on; must lie below `base_link`.
  /// @param T_tip_camera Rigid pose of the camera in the tip link frame.
  /// @throws std::invalid_argument if the file is missing or does not parse, a link is
  /// not found, the tip is not below the base, a joint type is unsupported, or
  /// T_tip_camera is not rigid.
  Kinematics(const std::string& urdf_path, const std::string& base_link,
             const std::string& tip_link, const Transform& T_tip_camera = Transform::Identity());

  /// The same from the XML text of a URDF (as a ROS robot_description holds it).
  static Kinematics from_urdf_string(const std::string& urdf_xml, const std::string& base_link,
                                     const std::string& tip_link,
                                     const Transform& T_tip_camera = Transform::Identity());

  int joint_count() const;
  const std::vector<std::string>& joint_names() const;
  const Eigen::VectorXd& lower_limits() const;     ///< rad or m; -inf for continuous joints.
  const Eigen::VectorXd& upper_limits() const;     ///< rad or m; +inf for continuous joints.
  const Eigen::VectorXd& velocity_limits() const;  ///< rad/s or m/s; +inf when the URDF gives none.
  const std::string& base_link() const;
  const std::string& tip_link() const;
  const Transform& T_tip_camera() const;

  /// Pose of the tip link in the base frame, T_base_tip.
  /// @throws std::invalid_argument if q has the wrong length or is not finite.
  Transform tip_pose(const Eigen::VectorXd& q) const;

  /// Pose of the camera in the base frame, T_base_camera = T_base_tip T_tip_camera.
  Transform forward(const Eigen::VectorXd& q) const;

  /// J_c: maps q_dot to the camera twist (v, omega) of the camera origin, both expressed
  /// in the camera frame.
  Jacobian jacobian(const Eigen::VectorXd& q) const;

  /// q_dot = J_c^+ camera_twist with the damped pseudo-inverse, plus the joint-limit
  /// avoidance in the null space of J_c (VelocityCommandParams::limit_avoidance_gain), then
  /// (1) joints that would come within `position_margin` of a limit within `dt` are
  /// clamped to the largest admissible velocity and the rest of the twist is re-solved
  /// with the other joints, the avoidance in their null space (repeated until no joint is
  /// violated), and
  /// (2) the whole vector is scaled uniformly so that every |q_dot_i| stays within
  /// min(URDF velocity limit, max_joint_speed): the direction in joint space is kept.
  /// A joint already beyond its margin may only move back toward the admissible range.
  /// @param camera_twist (v, omega) in the camera frame, m/s and rad/s.
  VelocityCommand joint_velocities(const Eigen::VectorXd& q, const Twist& camera_twist,
                                   const VelocityCommandParams& params = {}) const;

 private:
  struct Model;
  explicit Kinematics(std::shared_ptr<const Model> model);
  void require_q(const Eigen::VectorXd& q) const;
  std::shared_ptr<const Model> model_;
};

}  // namespace spectral_vs
