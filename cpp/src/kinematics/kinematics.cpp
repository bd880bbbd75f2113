#include <spectral_vs/kinematics/kinematics.hpp>

#include "common/checks.hpp"
#include "common/paths.hpp"

#include <urdf_parser/urdf_parser.h>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace spectral_vs {

using detail::fail;

constexpr double kInfinity = std::numeric_limits<double>::infinity();

struct Kinematics::Model {
  KDL::Chain chain;
  std::vector<std::string> joint_names;
  Eigen::VectorXd lower, upper, velocity;
  std::string base_link, tip_link;
  Transform T_tip_camera = Transform::Identity();
};

namespace {

// --- URDF -> KDL --------------------------------------------------------------------

KDL::Frame to_kdl(const urdf::Pose& pose) {
  double x, y, z, w;
  pose.rotation.getQuaternion(x, y, z, w);
  return KDL::Frame(KDL::Rotation::Quaternion(x, y, z, w),
                    KDL::Vector(pose.position.x, pose.position.y, pose.position.z));
}

// The joint as kdl_parser builds it: an axis through the joint origin, in the parent frame.
KDL::Joint to_kdl(const urdf::Joint& joint) {
  const KDL::Frame F_parent_joint = to_kdl(joint.parent_to_joint_origin_transform);
  const KDL::Vector axis = F_parent_joint.M * KDL::Vector(joint.axis.x, joint.axis.y, joint.axis.z);
  const double axis_length = std::sqrt(joint.axis.x * joint.axis.x + joint.axis.y * joint.axis.y +
                                       joint.axis.z * joint.axis.z);
  if (joint.type != urdf::Joint::FIXED && !(axis_length > 1e-9 && std::isfinite(axis_length))) {
    // KDL would divide by the length: every pose and Jacobian would be NaN.
    fail("urdf: joint '", joint.name, "' has a zero or non-finite axis (", joint.axis.x, " ",
         joint.axis.y, " ", joint.axis.z, ")");
  }
  switch (joint.type) {
    case urdf::Joint::FIXED:
      return KDL::Joint(joint.name, KDL::Joint::Fixed);
    case urdf::Joint::REVOLUTE:
    case urdf::Joint::CONTINUOUS:
      return KDL::Joint(joint.name, F_parent_joint.p, axis, KDL::Joint::RotAxis);
    case urdf::Joint::PRISMATIC:
      return KDL::Joint(joint.name, F_parent_joint.p, axis, KDL::Joint::TransAxis);
    default:
      fail("urdf: joint '", joint.name,
           "' is floating or planar; only revolute, continuous, prismatic and fixed joints are "
           "supported");
  }
}

std::string link_names(const urdf::ModelInterface& model) {
  std::vector<urdf::LinkSharedPtr> links;
  model.getLinks(links);
  std::ostringstream out;
  for (std::size_t i = 0; i < links.size(); ++i) out << (i ? ", " : "") << links[i]->name;
  return out.str();
}

urdf::LinkConstSharedPtr require_link(const urdf::ModelInterface& model, const std::string& name,
                                      const char* argument) {
  auto link = model.getLink(name);
  if (!link) fail(argument, ": no link named '", name, "' in the URDF; links: ", link_names(model));
  return link;
}

// The joints from base to tip, in chain order.
std::vector<urdf::JointConstSharedPtr> joints_between(const urdf::ModelInterface& model,
                                                      const std::string& base,
                                                      const std::string& tip) {
  require_link(model, base, "base_link");
  auto link = require_link(model, tip, "tip_link");
  std::vector<urdf::JointConstSharedPtr> joints;
  const std::size_t links = model.links_.size();
  while (link->name != base) {
    if (!link->parent_joint) fail("tip_link: '", tip, "' is not below base_link '", base, "'");
    // urdfdom accepts a loop of links that does not reach the root: walking up it would
    // never end.
    if (joints.size() > links) fail("urdf: the links above '", tip, "' form a loop");
    joints.push_back(link->parent_joint);
    link = model.getLink(link->parent_joint->parent_link_name);
    if (!link) fail("urdf: joint '", joints.back()->name, "' has no parent link");
  }
  std::reverse(joints.begin(), joints.end());
  return joints;
}

void append_limits(const urdf::Joint& joint, std::vector<double>& lower, std::vector<double>& upper,
                   std::vector<double>& velocity) {
  const bool bounded = joint.type != urdf::Joint::CONTINUOUS && joint.limits;
  lower.push_back(bounded ? joint.limits->lower : -kInfinity);
  upper.push_back(bounded ? joint.limits->upper : kInfinity);
  if (joint.limits && !(joint.limits->velocity > 0.0)) {
    fail("urdf: joint '", joint.name, "' has velocity limit ", joint.limits->velocity,
         ": it must be > 0 rad/s (or m/s)");
  }
  velocity.push_back(joint.limits ? joint.limits->velocity : kInfinity);
  if (bounded && !(lower.back() <= upper.back())) {
    fail("urdf: joint '", joint.name, "' has lower limit ", lower.back(), " above upper limit ",
         upper.back());
  }
}

Eigen::VectorXd to_vector(const std::vector<double>& values) {
  return Eigen::Map<const Eigen::VectorXd>(values.data(), Eigen::Index(values.size()));
}

Transform to_transform(const KDL::Frame& F) {
  Transform T = Transform::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T(r, c) = F.M(r, c);
    T(r, 3) = F.p(r);
  }
  return T;
}

// The XML parser under urdfdom recurses once per level of nesting: about 100,000 levels
// overflowed the stack (SIGSEGV). A URDF is a few levels deep (robot, joint, limit): the
// depth is counted before anything is parsed.
constexpr int kMaxUrdfNesting = 256;

void require_shallow_xml(const std::string& xml) {
  int depth = 0;
  std::size_t i = 0;
  const auto skip_past = [&](const char* end) {
    const std::size_t at = xml.find(end, i);
    i = at == std::string::npos ? xml.size() : at + std::strlen(end);
  };
  while ((i = xml.find('<', i)) != std::string::npos) {
    if (xml.compare(i, 4, "<!--") == 0) {
      skip_past("-->");
    } else if (xml.compare(i, 9, "<![CDATA[") == 0) {
      skip_past("]]>");
    } else if (xml.compare(i, 2, "<?") == 0 || xml.compare(i, 2, "<!") == 0) {
      skip_past(">");
    } else if (xml.compare(i, 2, "</") == 0) {
      --depth;
      skip_past(">");
    } else {
      // An opening tag: its end is the first '>' outside a quoted attribute value.
      char quote = 0;
      std::size_t j = i + 1;
      for (; j < xml.size(); ++j) {
        const char c = xml[j];
        if (quote) {
          if (c == quote) quote = 0;
        } else if (c == '"' || c == '\'') {
          quote = c;
        } else if (c == '>') {
          break;
        }
      }
      const bool closes_itself = j < xml.size() && j > i + 1 && xml[j - 1] == '/';
      if (!closes_itself && ++depth > kMaxUrdfNesting) {
        fail("urdf: the XML is nested deeper than ", kMaxUrdfNesting,
             " levels (a URDF needs a few): refused before parsing");
      }
      i = j;
    }
  }
}

std::string read_file(const std::string& path) {
  if (const auto kind = detail::path_kind(path); kind != detail::PathKind::file) {
    fail("urdf_path: ", detail::path_problem(kind), ": '", path, "'");
  }
  std::ifstream in(path);
  if (!in) fail("urdf_path: cannot read '", path, "'");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// --- Least squares -------------------------------------------------------------------

void check_damping(const DampingParams& params) {
  detail::require_positive_finite(params.singular_value_threshold, "singular_value_threshold");
  if (!std::isfinite(params.max_damping) || params.max_damping < 0.0) {
    fail("max_damping must be finite and >= 0, got ", params.max_damping);
  }
}

double damping_for(double s_min, const DampingParams& params) {
  if (s_min >= params.singular_value_threshold) return 0.0;
  const double ratio = s_min / params.singular_value_threshold;
  return params.max_damping * std::sqrt(1.0 - ratio * ratio);
}

void check_command_params(const VelocityCommandParams& params) {
  detail::require_positive_finite(params.dt, "dt");
  if (!std::isfinite(params.position_margin) || params.position_margin < 0.0) {
    fail("position_margin must be finite and >= 0, got ", params.position_margin);
  }
  if (std::isnan(params.max_joint_speed) || params.max_joint_speed <= 0.0) {
    fail("max_joint_speed must be > 0 (infinity for no cap), got ", params.max_joint_speed);
  }
  check_damping(params.damping);
  if (!std::isfinite(params.limit_avoidance_gain) || params.limit_avoidance_gain < 0.0) {
    fail("limit_avoidance_gain must be finite and >= 0 (1/s), got ", params.limit_avoidance_gain);
  }
  if (!std::isfinite(params.limit_avoidance_exponent) || params.limit_avoidance_exponent < 1.0) {
    fail("limit_avoidance_exponent must be finite and >= 1, got ", params.limit_avoidance_exponent);
  }
}

// q_dot_0 = -gain grad H, H = sum_i h_i^2 |x_i|^(p + 1) / (p + 1), x_i = (q_i - m_i) / h_i:
// toward the middle of every bounded joint's range, zero there and for unbounded joints.
Eigen::VectorXd centring_velocity(const Eigen::VectorXd& q, const Eigen::VectorXd& lower,
                                  const Eigen::VectorXd& upper, double gain, double exponent) {
  Eigen::VectorXd z = Eigen::VectorXd::Zero(q.size());
  if (gain == 0.0) return z;
  for (Eigen::Index i = 0; i < q.size(); ++i) {
    const double half = 0.5 * (upper[i] - lower[i]);
    if (!std::isfinite(half) || !(half > 0.0)) continue;
    const double x = std::clamp((q[i] - 0.5 * (upper[i] + lower[i])) / half, -1.0, 1.0);
    z[i] = -gain * half * std::copysign(std::pow(std::abs(x), exponent), x);
  }
  return z;
}

// The damped solution of J x = b plus the part of z in the null space of J, from one SVD.
// The null space is that of the exact J (singular values above a rank tolerance count as
// its row space, damped or not), so J (x - J^+_lambda b) = J N z = 0 to rounding.
DampedSolution solve(const Eigen::MatrixXd& J, const Eigen::VectorXd& b,
                     const DampingParams& params, const Eigen::VectorXd* z) {
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& s = svd.singularValues();
  DampedSolution out;
  out.min_singular_value = s.minCoeff();
  out.damping = damping_for(out.min_singular_value, params);
  const double lambda2 = out.damping * out.damping;
  Eigen::VectorXd gains(s.size());
  for (Eigen::Index i = 0; i < s.size(); ++i) {
    const double denominator = s[i] * s[i] + lambda2;
    gains[i] = denominator > 0.0 ? s[i] / denominator : 0.0;
  }
  out.x = svd.matrixV() * gains.cwiseProduct(svd.matrixU().transpose() * b);
  if (z != nullptr) {
    const double tolerance = double(std::max(J.rows(), J.cols())) *
                             std::numeric_limits<double>::epsilon() * s.maxCoeff();
    const Eigen::Index rank = (s.array() > tolerance).count();  // s is sorted, decreasing
    const auto V_row = svd.matrixV().leftCols(rank);
    out.x += *z - V_row * (V_row.transpose() * *z);
  }
  return out;
}

}  // namespace

DampedSolution damped_least_squares(const Eigen::MatrixXd& J, const Eigen::VectorXd& b,
                                    const DampingParams& params) {
  check_damping(params);
  if (J.size() == 0) fail("J is empty: it needs at least 1 row and 1 column");
  if (!J.allFinite()) fail("J has non-finite entries");
  if (b.size() != J.rows()) fail("b: expected ", J.rows(), " entries (rows of J), got ", b.size());
  if (!b.allFinite()) fail("b has non-finite entries");
  return solve(J, b, params, nullptr);
}

// --- Kinematics ------------------------------------------------------------------------

Kinematics::Kinematics(std::shared_ptr<const Model> model) : model_(std::move(model)) {}

Kinematics::Kinematics(const std::string& urdf_path, const std::string& base_link,
                       const std::string& tip_link, const Transform& T_tip_camera)
    : Kinematics(from_urdf_string(read_file(urdf_path), base_link, tip_link, T_tip_camera)) {}

Kinematics Kinematics::from_urdf_string(const std::string& urdf_xml, const std::string& base_link,
                                        const std::string& tip_link,
                                        const Transform& T_tip_camera) {
  require_rigid_transform(T_tip_camera, "T_tip_camera");
  require_shallow_xml(urdf_xml);
  const urdf::ModelInterfaceSharedPtr urdf_model = urdf::parseURDF(urdf_xml);
  if (!urdf_model) fail("urdf: the XML is not a valid URDF (urdfdom could not parse it)");
  // urdfdom links own their children: a loop of links would own itself and leak. The
  // model is only read here, so its tree is cut on the way out, however that is.
  struct CutTree {
    urdf::ModelInterface& model;
    ~CutTree() {
      for (auto& [name, link] : model.links_) {
        link->child_links.clear();
        link->child_joints.clear();
      }
    }
  } cut{*urdf_model};

  auto model = std::make_shared<Model>();
  model->base_link = base_link;
  model->tip_link = tip_link;
  model->T_tip_camera = T_tip_camera;
  std::vector<double> lower, upper, velocity;
  for (const auto& joint : joints_between(*urdf_model, base_link, tip_link)) {
    model->chain.addSegment(KDL::Segment(joint->child_link_name, to_kdl(*joint),
                                         to_kdl(joint->parent_to_joint_origin_transform)));
    if (joint->type == urdf::Joint::FIXED) continue;
    model->joint_names.push_back(joint->name);
    append_limits(*joint, lower, upper, velocity);
  }
  if (model->joint_names.empty()) {
    fail("tip_link: no movable joint between '", base_link, "' and '", tip_link, "'");
  }
  model->lower = to_vector(lower);
  model->upper = to_vector(upper);
  model->velocity = to_vector(velocity);
  return Kinematics(std::move(model));
}

int Kinematics::joint_count() const { return static_cast<int>(model_->joint_names.size()); }
const std::vector<std::string>& Kinematics::joint_names() const { return model_->joint_names; }
const Eigen::VectorXd& Kinematics::lower_limits() const { return model_->lower; }
const Eigen::VectorXd& Kinematics::upper_limits() const { return model_->upper; }
const Eigen::VectorXd& Kinematics::velocity_limits() const { return model_->velocity; }
const std::string& Kinematics::base_link() const { return model_->base_link; }
const std::string& Kinematics::tip_link() const { return model_->tip_link; }
const Transform& Kinematics::T_tip_camera() const { return model_->T_tip_camera; }

void Kinematics::require_q(const Eigen::VectorXd& q) const {
  if (q.size() != joint_count()) {
    fail("q: expected ", joint_count(), " joint positions, got ", q.size());
  }
  if (!q.allFinite()) fail("q has non-finite entries");
}

Transform Kinematics::tip_pose(const Eigen::VectorXd& q) const {
  require_q(q);
  KDL::JntArray joints(joint_count());
  joints.data = q;
  KDL::Frame F_base_tip;
  KDL::ChainFkSolverPos_recursive solver(model_->chain);
  if (solver.JntToCart(joints, F_base_tip) < 0) fail("q: KDL forward kinematics failed");
  const Transform T_base_tip = to_transform(F_base_tip);
  // A prismatic joint at 1e308 m moves the tip past the largest double.
  if (!T_base_tip.allFinite()) fail("q: the tip's pose at these joint positions overflows");
  return T_base_tip;
}

Transform Kinematics::forward(const Eigen::VectorXd& q) const {
  return tip_pose(q) * model_->T_tip_camera;
}

Jacobian Kinematics::jacobian(const Eigen::VectorXd& q) const {
  const Transform T_base_tip = tip_pose(q);
  KDL::JntArray joints(joint_count());
  joints.data = q;
  KDL::Jacobian J_kdl(joint_count());
  KDL::ChainJntToJacSolver solver(model_->chain);
  if (solver.JntToJac(joints, J_kdl) < 0) fail("q: KDL Jacobian solver failed");

  // KDL: expressed in the base frame, reference point at the tip. Move the reference
  // point to the camera origin (v += omega x p), then rotate both halves into the camera frame.
  const Eigen::Matrix3d R_base_tip = T_base_tip.topLeftCorner<3, 3>();
  const Eigen::Vector3d p_base = R_base_tip * model_->T_tip_camera.topRightCorner<3, 1>();
  const Eigen::Matrix3d R_camera_base =
      (R_base_tip * model_->T_tip_camera.topLeftCorner<3, 3>()).transpose();
  Jacobian J(6, joint_count());
  for (int i = 0; i < joint_count(); ++i) {
    const Eigen::Vector3d v = J_kdl.data.block<3, 1>(0, i);
    const Eigen::Vector3d omega = J_kdl.data.block<3, 1>(3, i);
    J.block<3, 1>(0, i) = R_camera_base * (v + omega.cross(p_base));
    J.block<3, 1>(3, i) = R_camera_base * omega;
  }
  if (!J.allFinite()) fail("q: the Jacobian at these joint positions overflows");
  return J;
}

VelocityCommand Kinematics::joint_velocities(const Eigen::VectorXd& q, const Twist& camera_twist,
                                             const VelocityCommandParams& params) const {
  check_command_params(params);
  if (!camera_twist.allFinite()) fail("camera_twist has non-finite entries");
  const Jacobian J = jacobian(q);  // checks q
  const int n = joint_count();

  // Admissible velocities over one period: [low, high] always contains 0.
  const Eigen::VectorXd low =
      ((model_->lower.array() + params.position_margin - q.array()) / params.dt).min(0.0);
  const Eigen::VectorXd high =
      ((model_->upper.array() - params.position_margin - q.array()) / params.dt).max(0.0);

  // The push toward the middles of the ranges, applied in the null space of the free joints.
  const Eigen::VectorXd q_dot_0 =
      centring_velocity(q, model_->lower, model_->upper, params.limit_avoidance_gain,
                        params.limit_avoidance_exponent);
  const bool avoid = params.limit_avoidance_gain > 0.0;

  VelocityCommand out;
  out.q_dot = Eigen::VectorXd::Zero(n);
  std::vector<bool> locked(std::size_t(n), false);
  for (int pass = 0; pass <= n; ++pass) {
    std::vector<int> free;
    Twist remaining = camera_twist;
    for (int i = 0; i < n; ++i) {
      if (locked[std::size_t(i)])
        remaining -= J.col(i) * out.q_dot[i];
      else
        free.push_back(i);
    }
    if (free.empty()) break;
    Eigen::MatrixXd J_free(6, Eigen::Index(free.size()));
    Eigen::VectorXd push_free(Eigen::Index(free.size()));
    for (std::size_t k = 0; k < free.size(); ++k) {
      J_free.col(Eigen::Index(k)) = J.col(free[k]);
      push_free[Eigen::Index(k)] = q_dot_0[free[k]];
    }
    const DampedSolution solution =
        solve(J_free, remaining, params.damping, avoid ? &push_free : nullptr);
    if (pass == 0) out.min_singular_value = solution.min_singular_value;
    out.damping = solution.damping;

    bool violated = false;
    for (std::size_t k = 0; k < free.size(); ++k) {
      const int i = free[k];
      const double value = solution.x[Eigen::Index(k)];
      out.q_dot[i] = std::clamp(value, low[i], high[i]);
      if (out.q_dot[i] != value) {
        locked[std::size_t(i)] = true;
        out.position_limited.push_back(i);
        violated = true;
      }
    }
    if (!violated) break;
  }
  std::sort(out.position_limited.begin(), out.position_limited.end());

  for (int i = 0; i < n; ++i) {
    const double limit = std::min(model_->velocity[i], params.max_joint_speed);
    const double speed = std::abs(out.q_dot[i]);
    if (speed > limit) out.velocity_scale = std::min(out.velocity_scale, limit / speed);
  }
  out.q_dot *= out.velocity_scale;
  return out;
}

}  // namespace spectral_vs
