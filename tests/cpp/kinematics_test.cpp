// Kinematics of tests/data/test_arm.urdf checked against an independent composition of
// its joint transforms, against finite differences, and the damped least-squares
// command against closed-form answers. The iiwa checks against PyBullet are in
// tests/python/test_kinematics.py.
#include <spectral_vs/kinematics/kinematics.hpp>

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

namespace spectral_vs {
namespace {

const std::string kArm = SPECTRAL_VS_TEST_URDF;
constexpr double kInf = std::numeric_limits<double>::infinity();

// --- An independent forward kinematics of test_arm.urdf -----------------------------

Transform origin(double x, double y, double z, double roll, double pitch, double yaw) {
  Transform T = Transform::Identity();
  // URDF rpy: fixed-axis roll about x, then pitch about y, then yaw about z.
  T.topLeftCorner<3, 3>() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(x, y, z);
  return T;
}

Transform rotation(const Eigen::Vector3d& axis, double angle) {
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  return T;
}

Transform slide(const Eigen::Vector3d& axis, double distance) {
  Transform T = Transform::Identity();
  T.topRightCorner<3, 1>() = axis * distance;
  return T;
}

// T_base_tool of test_arm.urdf, written out joint by joint from the file.
Transform arm_base_tool(const Eigen::VectorXd& q) {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  return origin(0, 0, 0.3, 0, 0, 0) * rotation(z, q[0]) *            // j1
         origin(0, 0.05, 0.2, 0, 0, 0.3) * rotation(y, q[1]) *       // j2
         origin(0.1, 0, 0.25, 0.2, 0, 0) * slide(x, q[2]) *          // j3
         origin(0, 0, 0.2, 0, 0.4, 0) * rotation(z, q[3]) *          // j4
         origin(0, 0.1, 0.15, 0.2, 0.1, -0.3) * rotation(y, q[4]) *  // j5
         origin(0, 0, 0.1, 0, 0, 0) * rotation(x, q[5]) *            // j6
         origin(0, 0, 0.06, 0, 0, 1.0);                              // flange
}

Transform camera_offset() { return origin(0.03, -0.02, 0.05, 0.3, -0.2, 0.5); }

Eigen::VectorXd random_q(std::mt19937& rng) {
  std::uniform_real_distribution<double> angle(-1.5, 1.5), stroke(-0.08, 0.18);
  Eigen::VectorXd q(6);
  q << angle(rng), angle(rng), stroke(rng), angle(rng), angle(rng), angle(rng);
  return q;
}

Eigen::Vector3d log_rotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

Kinematics arm(const Transform& T_tip_camera = camera_offset()) {
  return Kinematics(kArm, "base_link", "tool", T_tip_camera);
}

template <typename Call>
void expect_invalid(Call call, const std::string& fragment) {
  try {
    call();
    ADD_FAILURE() << "no exception; expected one mentioning '" << fragment << "'";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos) << error.what();
  }
}

// --- The chain ------------------------------------------------------------------------

TEST(Kinematics, ReadsJointsAndLimitsFromTheUrdf) {
  const Kinematics k = arm();
  ASSERT_EQ(k.joint_count(), 6);
  EXPECT_EQ(k.joint_names(), (std::vector<std::string>{"j1", "j2", "j3", "j4", "j5", "j6"}));
  Eigen::VectorXd lower(6), upper(6), velocity(6);
  lower << -2.9, -2.0, -0.1, -kInf, -2.0, -2.5;
  upper << 2.9, 2.0, 0.2, kInf, 2.0, 2.5;
  velocity << 1.5, 1.2, 0.3, 2.0, 2.0, 2.5;
  EXPECT_EQ(k.lower_limits(), lower);
  EXPECT_EQ(k.upper_limits(), upper);
  EXPECT_EQ(k.velocity_limits(), velocity);
  EXPECT_EQ(k.base_link(), "base_link");
  EXPECT_EQ(k.tip_link(), "tool");
}

TEST(Kinematics, ForwardMatchesTheJointTransformsComposedByHand) {
  const Kinematics k = arm();
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::VectorXd q = random_q(rng);
    const Transform expected_tip = arm_base_tool(q);
    EXPECT_LT((k.tip_pose(q) - expected_tip).norm(), 1e-12) << "trial " << trial;
    EXPECT_LT((k.forward(q) - expected_tip * camera_offset()).norm(), 1e-12) << "trial " << trial;
  }
}

TEST(Kinematics, ChainMayStartBelowTheRootAndEndMidArm) {
  const Kinematics from_root(kArm, "world", "link2");
  ASSERT_EQ(from_root.joint_count(), 2);
  Eigen::VectorXd q(2);
  q << 0.4, -0.7;
  const Transform expected = origin(0.1, 0, 0, 0, 0, 0) * origin(0, 0, 0.3, 0, 0, 0) *
                             rotation(Eigen::Vector3d::UnitZ(), 0.4) *
                             origin(0, 0.05, 0.2, 0, 0, 0.3) *
                             rotation(Eigen::Vector3d::UnitY(), -0.7);
  EXPECT_LT((from_root.forward(q) - expected).norm(), 1e-12);
}

TEST(Kinematics, JacobianMatchesCentralFiniteDifferencesInTheCameraFrame) {
  const Kinematics k = arm();
  std::mt19937 rng(5);
  const double h = 1e-6;
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd q = random_q(rng);
    const Jacobian J = k.jacobian(q);
    const Transform T = k.forward(q);
    const Eigen::Matrix3d R_base_camera = T.topLeftCorner<3, 3>();
    for (int i = 0; i < 6; ++i) {
      Eigen::VectorXd plus = q, minus = q;
      plus[i] += h;
      minus[i] -= h;
      const Transform Tp = k.forward(plus), Tm = k.forward(minus);
      const Eigen::Vector3d v_base =
          (Tp.topRightCorner<3, 1>() - Tm.topRightCorner<3, 1>()) / (2 * h);
      // Body-frame angular velocity: R(q + h) = R(q - h) exp(2 h [omega]).
      const Eigen::Vector3d omega_camera =
          log_rotation(Tm.topLeftCorner<3, 3>().transpose() * Tp.topLeftCorner<3, 3>()) / (2 * h);
      EXPECT_LT((J.block<3, 1>(0, i) - R_base_camera.transpose() * v_base).norm(), 1e-6)
          << "trial " << trial << " joint " << i;
      EXPECT_LT((J.block<3, 1>(3, i) - omega_camera).norm(), 1e-6)
          << "trial " << trial << " joint " << i;
    }
    // The prismatic joint j3 cannot rotate the camera.
    EXPECT_LT((J.block<3, 1>(3, 2)).norm(), 1e-12);
  }
}

// --- Damped least squares -------------------------------------------------------------

TEST(DampedLeastSquares, IsTheExactInverseAboveTheThreshold) {
  Eigen::MatrixXd J(2, 2);
  J << 2.0, 0.0, 0.0, 0.1;
  const DampedSolution solution = damped_least_squares(J, Eigen::Vector2d(1.0, 1.0), {0.05, 0.05});
  EXPECT_DOUBLE_EQ(solution.damping, 0.0);
  EXPECT_DOUBLE_EQ(solution.min_singular_value, 0.1);
  EXPECT_NEAR(solution.x[0], 0.5, 1e-14);
  EXPECT_NEAR(solution.x[1], 10.0, 1e-12);
}

TEST(DampedLeastSquares, DampsBelowTheThresholdByTheDocumentedRule) {
  // s_min = 0.025 = eps / 2: lambda^2 = (1 - 1/4) lambda_max^2 = 0.001875.
  Eigen::MatrixXd J(2, 2);
  J << 0.0, 2.0, 0.025, 0.0;
  const DampedSolution solution = damped_least_squares(J, Eigen::Vector2d(1.0, 1.0), {0.05, 0.05});
  EXPECT_NEAR(solution.damping * solution.damping, 0.001875, 1e-15);
  EXPECT_NEAR(solution.x[0], 0.025 / (0.025 * 0.025 + 0.001875), 1e-12);
  EXPECT_NEAR(solution.x[1], 2.0 / (4.0 + 0.001875), 1e-12);
}

TEST(DampedLeastSquares, GainStaysBoundedThroughASingularity) {
  // With max_damping = threshold the documented bound is 1 / threshold = 20.
  for (double s : {0.0, 1e-9, 1e-4, 0.01, 0.03, 0.049, 0.05}) {
    Eigen::MatrixXd J(3, 4);
    J.setZero();
    J(0, 0) = 1.0;
    J(1, 1) = 0.7;
    J(2, 3) = s;
    const DampedSolution solution = damped_least_squares(J, Eigen::Vector3d(0, 0, 1), {0.05, 0.05});
    EXPECT_LE(solution.x.norm(), 20.0 + 1e-9) << "s = " << s;
    if (s == 0.0) {
      EXPECT_EQ(solution.x.norm(), 0.0);
    }
  }
}

// --- The joint velocity command -------------------------------------------------------

TEST(JointVelocities, InvertsTheJacobianAwayFromLimitsAndSingularities) {
  const Kinematics k = arm();
  Eigen::VectorXd q(6);
  q << 0.3, 0.5, 0.05, -0.4, 0.6, 0.2;
  Twist twist;
  twist << 0.01, -0.02, 0.015, 0.02, -0.01, 0.03;
  VelocityCommandParams params;
  params.damping = {1e-3, 1e-3};
  const VelocityCommand command = k.joint_velocities(q, twist, params);
  ASSERT_GT(command.min_singular_value, 1e-3);
  const Eigen::MatrixXd J = k.jacobian(q);
  const Eigen::VectorXd expected = J.fullPivLu().solve(twist);
  EXPECT_LT((command.q_dot - expected).norm(), 1e-10);
  EXPECT_LT((J * command.q_dot - twist).norm(), 1e-10);
  EXPECT_DOUBLE_EQ(command.velocity_scale, 1.0);
  EXPECT_TRUE(command.position_limited.empty());
}

TEST(JointVelocities, ScalesUniformlyToTheVelocityLimits) {
  const Kinematics k = arm();
  Eigen::VectorXd q(6);
  q << 0.3, 0.5, 0.05, -0.4, 0.6, 0.2;
  Twist twist;
  twist << 0.5, -0.4, 0.3, 0.8, -0.6, 1.0;
  VelocityCommandParams params;
  params.damping = {1e-3, 1e-3};
  params.dt = 1e-3;  // position limits far away at this period
  const Eigen::VectorXd unscaled = k.jacobian(q).fullPivLu().solve(twist);
  const Eigen::ArrayXd limits = k.velocity_limits().array();
  const VelocityCommand command = k.joint_velocities(q, twist, params);
  const double ratio = (command.q_dot.array().abs() / limits).maxCoeff();
  EXPECT_NEAR(ratio, 1.0, 1e-12);
  EXPECT_NEAR(command.velocity_scale, 1.0 / (unscaled.array().abs() / limits).maxCoeff(), 1e-12);
  EXPECT_LT((command.q_dot - command.velocity_scale * unscaled).norm(), 1e-10);

  params.max_joint_speed = 0.1;
  const VelocityCommand capped = k.joint_velocities(q, twist, params);
  EXPECT_NEAR(capped.q_dot.cwiseAbs().maxCoeff(), 0.1, 1e-12);
  EXPECT_LT((capped.q_dot - capped.velocity_scale * unscaled).norm(), 1e-10);
}

TEST(JointVelocities, NeverCrossesAPositionLimitWithinOnePeriod) {
  const Kinematics k = arm();
  Eigen::VectorXd q(6);
  q << 0.3, 1.985, 0.05, -0.4, 0.6, 0.2;  // j2 0.015 rad below its upper limit 2.0
  VelocityCommandParams params;
  params.dt = 0.1;
  params.position_margin = 0.01;
  params.damping = {1e-3, 1e-3};
  const Twist twist = k.jacobian(q).col(1) * 0.5;  // exactly "move j2 at +0.5 rad/s"
  const VelocityCommand command = k.joint_velocities(q, twist, params);
  ASSERT_EQ(command.position_limited, std::vector<int>{1});
  EXPECT_NEAR(command.q_dot[1], (2.0 - 0.01 - 1.985) / 0.1, 1e-12);
  const Eigen::VectorXd next = q + command.q_dot * params.dt;
  for (int i = 0; i < 6; ++i) {
    EXPECT_LE(next[i], k.upper_limits()[i] - params.position_margin + 1e-12) << "joint " << i;
    EXPECT_GE(next[i], k.lower_limits()[i] + params.position_margin - 1e-12) << "joint " << i;
  }
}

TEST(JointVelocities, AJointBeyondItsMarginOnlyMovesBack) {
  const Kinematics k = arm();
  Eigen::VectorXd q(6);
  q << 0.3, 2.0, 0.05, -0.4, 0.6, 0.2;  // j2 at its limit, inside the margin
  const Twist push = k.jacobian(q).col(1);
  const VelocityCommand pushed = k.joint_velocities(q, push);
  EXPECT_EQ(pushed.q_dot[1], 0.0);
  const VelocityCommand pulled = k.joint_velocities(q, -push, {0.05, 0.01, kInf, {1e-3, 1e-3}});
  EXPECT_NEAR(pulled.q_dot[1], -1.0, 1e-9);
}

// --- Joint-limit avoidance in the redundancy --------------------------------------------

// A 7-joint arm (one more than the task needs): revolute joints about z, y, z, y, z, y, x
// with offsets, asymmetric limits, velocity limits too high to scale (none in these tests).
Kinematics redundant_arm() {
  const char* axes[] = {"0 0 1", "0 1 0", "0 0 1", "0 1 0", "0 0 1", "0 1 0", "1 0 0"};
  const double lower[] = {-2.9, -2.0, -2.9, -2.1, -2.9, -1.5, -3.0};
  const double upper[] = {2.9, 2.0, 2.9, 1.2, 2.9, 2.5, 3.0};
  std::ostringstream xml;
  xml << "<robot name='redundant'><link name='l0'/>";
  for (int i = 0; i < 7; ++i) {
    xml << "<link name='l" << i + 1 << "'/><joint name='r" << i + 1 << "' type='revolute'>"
        << "<parent link='l" << i << "'/><child link='l" << i + 1 << "'/>"
        << "<origin xyz='0.02 0.01 " << 0.1 + 0.03 * i << "' rpy='0.1 0 " << 0.2 * i << "'/>"
        << "<axis xyz='" << axes[i] << "'/><limit lower='" << lower[i] << "' upper='" << upper[i]
        << "' velocity='1e6' effort='10'/></joint>";
  }
  xml << "</robot>";
  return Kinematics::from_urdf_string(xml.str(), "l0", "l7", camera_offset());
}

// The centring cost H of VelocityCommandParams::limit_avoidance_gain.
double centring_cost(const Kinematics& k, const Eigen::VectorXd& q, double exponent) {
  double cost = 0.0;
  for (int i = 0; i < k.joint_count(); ++i) {
    const double half = 0.5 * (k.upper_limits()[i] - k.lower_limits()[i]);
    const double x = (q[i] - 0.5 * (k.upper_limits()[i] + k.lower_limits()[i])) / half;
    cost += half * half * std::pow(std::abs(x), exponent + 1.0) / (exponent + 1.0);
  }
  return cost;
}

VelocityCommandParams avoiding(double gain, double exponent = 3.0) {
  VelocityCommandParams params;
  params.dt = 1e-3;  // the position limits stay out of the way
  params.damping = {1e-3, 1e-3};
  params.limit_avoidance_gain = gain;
  params.limit_avoidance_exponent = exponent;
  return params;
}

TEST(LimitAvoidance, LeavesTheCameraTwistUnchanged) {
  const Kinematics k = redundant_arm();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int trial = 0; trial < 30; ++trial) {
    Eigen::VectorXd q(7);
    for (int i = 0; i < 7; ++i) {  // anywhere up to 95% of the way to a limit
      const double middle = 0.5 * (k.upper_limits()[i] + k.lower_limits()[i]);
      q[i] = middle + 0.95 * unit(rng) * 0.5 * (k.upper_limits()[i] - k.lower_limits()[i]);
    }
    Twist twist;
    for (int r = 0; r < 6; ++r) twist[r] = 0.05 * unit(rng);
    const Eigen::MatrixXd J = k.jacobian(q);
    for (const double exponent : {1.0, 3.0}) {
      const VelocityCommand plain = k.joint_velocities(q, twist, avoiding(0.0));
      const VelocityCommand avoided = k.joint_velocities(q, twist, avoiding(2.0, exponent));
      ASSERT_GT(plain.min_singular_value, 1e-3) << "trial " << trial;
      ASSERT_TRUE(avoided.position_limited.empty());
      EXPECT_DOUBLE_EQ(avoided.velocity_scale, 1.0);
      EXPECT_LT((J * plain.q_dot - twist).norm(), 1e-9) << "trial " << trial;
      EXPECT_LT((J * avoided.q_dot - twist).norm(), 1e-9) << "trial " << trial;
    }
  }
}

TEST(LimitAvoidance, NullSpaceMotionLowersTheCentringCost) {
  const Kinematics k = redundant_arm();
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (const double exponent : {1.0, 3.0}) {
    for (int trial = 0; trial < 30; ++trial) {
      Eigen::VectorXd q(7);
      for (int i = 0; i < 7; ++i) {
        const double middle = 0.5 * (k.upper_limits()[i] + k.lower_limits()[i]);
        q[i] = middle + 0.9 * unit(rng) * 0.5 * (k.upper_limits()[i] - k.lower_limits()[i]);
      }
      const Twist twist = Twist::Zero();  // the command is the null-space motion alone
      const Eigen::VectorXd motion = k.joint_velocities(q, twist, avoiding(1.0, exponent)).q_dot;
      ASSERT_GT(motion.norm(), 1e-6) << "trial " << trial;
      const double h = 1e-6;
      const double slope = (centring_cost(k, q + h * motion, exponent) -
                            centring_cost(k, q - h * motion, exponent)) /
                           (2 * h);
      // dH/dt = grad H^T N (-k grad H) = -k |N grad H|^2 = -|motion|^2 / k (k = 1).
      EXPECT_LT(slope, 0.0) << "trial " << trial;
      EXPECT_NEAR(slope, -motion.squaredNorm(), 1e-6 * (1.0 + motion.squaredNorm()));
    }
  }
}

TEST(LimitAvoidance, IsZeroAtTheMiddleOfEveryRange) {
  const Kinematics k = redundant_arm();
  const Eigen::VectorXd middle = 0.5 * (k.upper_limits() + k.lower_limits());
  Twist twist;
  twist << 0.01, -0.02, 0.015, 0.02, -0.01, 0.03;
  const VelocityCommand plain = k.joint_velocities(middle, twist, avoiding(0.0));
  const VelocityCommand avoided = k.joint_velocities(middle, twist, avoiding(5.0));
  EXPECT_LT((avoided.q_dot - plain.q_dot).norm(), 1e-15);
  EXPECT_EQ(k.joint_velocities(middle, Twist::Zero(), avoiding(5.0)).q_dot.norm(), 0.0);
}

TEST(LimitAvoidance, ChangesNothingWithoutRedundancy) {
  const Kinematics k = arm();  // 6 joints for a 6-D twist: no null space
  Eigen::VectorXd q(6);
  q << 0.3, 1.7, 0.05, -0.4, 0.6, 2.2;  // j2 and j6 near their upper limits
  Twist twist;
  twist << 0.01, -0.02, 0.015, 0.02, -0.01, 0.03;
  const VelocityCommand plain = k.joint_velocities(q, twist, avoiding(0.0));
  const VelocityCommand avoided = k.joint_velocities(q, twist, avoiding(5.0));
  EXPECT_LT((avoided.q_dot - plain.q_dot).norm(), 1e-12);
}

TEST(LimitAvoidance, RejectsBadSettings) {
  const Kinematics k = redundant_arm();
  expect_invalid([&] { k.joint_velocities(Eigen::VectorXd::Zero(7), Twist::Zero(), avoiding(-1)); },
                 "limit_avoidance_gain");
  expect_invalid(
      [&] { k.joint_velocities(Eigen::VectorXd::Zero(7), Twist::Zero(), avoiding(kInf)); },
      "limit_avoidance_gain");
  expect_invalid(
      [&] { k.joint_velocities(Eigen::VectorXd::Zero(7), Twist::Zero(), avoiding(1.0, 0.5)); },
      "limit_avoidance_exponent");
}

// --- Bad input ------------------------------------------------------------------------

TEST(Kinematics, RejectsBadInputNamingTheArgument) {
  expect_invalid([] { Kinematics("/no/such/robot.urdf", "base_link", "tool"); }, "urdf_path");
  expect_invalid([] { Kinematics::from_urdf_string("<robot name='x'><link", "a", "b"); }, "urdf");
  expect_invalid([] { Kinematics(kArm, "base", "tool"); }, "base_link");
  expect_invalid([] { Kinematics(kArm, "base_link", "flange"); }, "tip_link");
  expect_invalid([] { Kinematics(kArm, "link3", "sensor_mount"); }, "tip_link");
  expect_invalid([] { Kinematics(kArm, "link6", "tool"); }, "tip_link");  // no movable joint
  Transform sheared = Transform::Identity();
  sheared(0, 1) = 0.2;
  expect_invalid([&] { Kinematics(kArm, "base_link", "tool", sheared); }, "T_tip_camera");

  const Kinematics k = arm();
  expect_invalid([&] { k.forward(Eigen::VectorXd::Zero(5)); }, "q");
  Eigen::VectorXd q = Eigen::VectorXd::Zero(6);
  q[2] = std::nan("");
  expect_invalid([&] { k.jacobian(q); }, "q");
  Twist twist = Twist::Zero();
  VelocityCommandParams zero_period;
  zero_period.dt = 0.0;
  expect_invalid([&] { k.joint_velocities(Eigen::VectorXd::Zero(6), twist, zero_period); }, "dt");
  twist[4] = kInf;
  expect_invalid([&] { k.joint_velocities(Eigen::VectorXd::Zero(6), twist); }, "camera_twist");
  expect_invalid(
      [] { damped_least_squares(Eigen::MatrixXd::Identity(2, 2), Eigen::Vector3d::Zero()); }, "b");
  expect_invalid(
      [] {
        damped_least_squares(Eigen::MatrixXd::Identity(2, 2), Eigen::Vector2d::Zero(), {0.0, 0.1});
      },
      "singular_value_threshold");
}

}  // namespace
}  // namespace spectral_vs
