// The URDF-to-chain path of Kinematics on any text. The input is "base\ntip\n" followed
// by the URDF's XML (the seeds: the test arm and the simulation's robots). A bad URDF or
// chain is std::invalid_argument; a chain that is built gives finite poses, Jacobians
// and joint velocities within its limits at its joints' middle (or zero) positions.
// An input that begins with byte 1 is a nesting instead: its next two bytes give a depth
// up to 2^18 (a mutated file cannot reach such depths within max_len; 100,000 levels
// overflowed the XML parser's stack), its rest the element's name and what it wraps.

#include <spectral_vs/kinematics/kinematics.hpp>

#include "fuzz_support.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace {

// "base\ntip\n" and a robot whose first link holds an element nested `depth` levels.
std::string nested_urdf(const uint8_t* data, size_t size) {
  const int depth = 4 * (data[1] | (data[2] << 8));
  const std::string rest(reinterpret_cast<const char*>(data) + 3, size - 3);
  const std::string name = rest.empty() ? "visual" : rest.substr(0, rest.find_first_of("<>/ ="));
  std::string xml = "base\ntip\n<robot name=\"r\"><link name=\"base\">";
  xml.reserve(xml.size() + std::size_t(depth) * (2 * name.size() + 5) + rest.size() + 64);
  for (int i = 0; i < depth; ++i) xml += "<" + name + ">";
  xml += rest;
  for (int i = 0; i < depth; ++i) xml += "</" + name + ">";
  return xml + "</link></robot>";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace spectral_vs;
  const std::string text = size >= 3 && data[0] == 1
                               ? nested_urdf(data, size)
                               : std::string(reinterpret_cast<const char*>(data), size);
  const auto first = text.find('\n');
  if (first == std::string::npos) return 0;
  const auto second = text.find('\n', first + 1);
  if (second == std::string::npos) return 0;
  const std::string base = text.substr(0, first), tip = text.substr(first + 1, second - first - 1);
  const std::string xml = text.substr(second + 1);
  try {
    const Kinematics chain = Kinematics::from_urdf_string(xml, base, tip);
    const int n = chain.joint_count();
    fuzz::check(n >= 1, "a chain without joints was built");
    fuzz::check(int(chain.joint_names().size()) == n, "joint_names size");
    Eigen::VectorXd q = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; ++i) {
      const double lo = chain.lower_limits()[i], hi = chain.upper_limits()[i];
      fuzz::check(!(lo > hi), "lower limit above upper limit");
      fuzz::check(!(chain.velocity_limits()[i] < 0.0), "negative velocity limit");
      if (std::isfinite(lo) && std::isfinite(hi)) q[i] = 0.5 * (lo + hi);
    }
    const Transform T = chain.forward(q);
    const Jacobian J = chain.jacobian(q);
    fuzz::check(T.allFinite() && J.allFinite(), "non-finite pose or Jacobian");
    Twist twist;
    twist << 0.01, -0.02, 0.03, 0.1, 0.0, -0.1;
    const VelocityCommand command = chain.joint_velocities(q, twist);
    fuzz::check(command.q_dot.size() == n, "q_dot size");
    fuzz::check(command.q_dot.allFinite(), "non-finite joint velocities");
    for (int i = 0; i < n; ++i) {
      fuzz::check(std::abs(command.q_dot[i]) <= chain.velocity_limits()[i] * (1.0 + 1e-9) + 1e-12,
                  "joint velocity beyond its limit");
    }
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
