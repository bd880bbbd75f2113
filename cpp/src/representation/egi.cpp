#include <spectral_vs/representation/egi.hpp>

#include "common/checks.hpp"

#include <cmath>

namespace spectral_vs {

using detail::fail;

void require_bandwidth(int bandwidth, const char* argument) {
  if (bandwidth < 1 || bandwidth > kMaxBandwidth) {
    fail(argument, " must be in [1, ", kMaxBandwidth, "], got ", bandwidth);
  }
}

double grid_theta(int j, int bandwidth) { return M_PI * (2.0 * j + 1.0) / (4.0 * bandwidth); }

double grid_phi(int k, int bandwidth) { return M_PI * k / bandwidth; }

Eigen::Vector2i egi_cell(const Eigen::Vector3d& normal, int bandwidth) {
  require_bandwidth(bandwidth);
  if (!normal.allFinite() || normal.norm() == 0.0) {
    fail("normal must be finite and non-zero, got ", normal.transpose());
  }
  const int size = 2 * bandwidth;
  const double theta = std::atan2(std::hypot(normal.x(), normal.y()), normal.z());
  double phi = std::atan2(normal.y(), normal.x());
  if (phi < 0.0) phi += 2.0 * M_PI;
  const int j = std::min(static_cast<int>(std::floor(theta * size / M_PI)), size - 1);
  const int k = static_cast<int>(std::lround(phi * bandwidth / M_PI)) % size;
  return {j, k};
}

SphereGrid egi_histogram(const Points& normals, int bandwidth, const Eigen::VectorXd* weights) {
  require_bandwidth(bandwidth);
  if (normals.rows() == 0) fail("normals is empty: at least 1 normal is needed");
  if (weights && weights->size() != normals.rows()) {
    fail("weights: expected ", normals.rows(), " entries (one per normal), got ", weights->size());
  }
  SphereGrid grid = SphereGrid::Zero(2 * bandwidth, 2 * bandwidth);
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    const Eigen::Vector3d n = normals.row(i).transpose();
    if (!n.allFinite() || n.norm() == 0.0)
      fail("normals: row ", i, " is not finite or has zero length");
    const double weight = weights ? (*weights)[i] : 1.0;
    if (!(std::isfinite(weight) && weight >= 0.0)) {
      fail("weights: entry ", i, " must be finite and >= 0 (a count of points), got ", weight);
    }
    const Eigen::Vector2i cell = egi_cell(n, bandwidth);
    grid(cell.x(), cell.y()) += weight;
  }
  return grid;
}

}  // namespace spectral_vs
