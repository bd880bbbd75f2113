#include <spectral_vs/representation/egi.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>

#include "common/checks.hpp"
#include "rotation/harmonics_detail.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

ShCoefficients project_normals(const Points& normals, int bandwidth,
                               const Eigen::VectorXd* weights) {
  ShCoefficients out = ShCoefficients::Zero(sh_count(bandwidth));
  constexpr int K = detail::kHarmonicsBlock;
  double x[K], y[K], z[K], w[K];
  // Blocks of normals, each block's harmonics summed across its normals (about 3 times
  // faster than one normal at a time at B = 16).
  for (Eigen::Index begin = 0; begin < normals.rows(); begin += K) {
    const int count = int(std::min<Eigen::Index>(K, normals.rows() - begin));
    for (int j = 0; j < count; ++j) {
      const Eigen::Index i = begin + j;
      const Eigen::Vector3d n = normals.row(i).transpose();
      const double norm = n.norm();
      if (!std::isfinite(norm) || norm == 0.0)
        fail("normals: row ", i, " is not finite or has zero length");
      const double weight = weights ? (*weights)[i] : 1.0;
      if (!std::isfinite(weight)) fail("weights: entry ", i, " is not finite");
      x[j] = n.x() / norm;
      y[j] = n.y() / norm;
      z[j] = n.z() / norm;
      w[j] = weight;
    }
    detail::accumulate_real_sh(x, y, z, w, count, bandwidth - 1, out.data());
  }
  return out;
}

}  // namespace

ShCoefficients egi_coefficients(const Points& normals, int bandwidth, EgiMethod method,
                                const Eigen::VectorXd* weights) {
  require_bandwidth(bandwidth);
  if (normals.rows() == 0) fail("normals is empty: at least 1 normal is needed");
  if (weights && weights->size() != normals.rows()) {
    fail("weights: expected ", normals.rows(), " entries (one per normal), got ", weights->size());
  }
  if (method == EgiMethod::histogram) {
    return sh_coefficients(egi_histogram(normals, bandwidth, weights), bandwidth);
  }
  return project_normals(normals, bandwidth, weights);
}

ShCoefficients egi_coefficients(const PointCloud& cloud, int bandwidth, EgiMethod method,
                                const Eigen::VectorXd* weights) {
  require_normals(cloud, "cloud");
  return egi_coefficients(cloud.normals(), bandwidth, method, weights);
}

void smooth_coefficients(ShCoefficients& coefficients, int bandwidth, double sigma) {
  require_coefficients(coefficients, bandwidth, "coefficients");
  if (!std::isfinite(sigma) || sigma < 0.0)
    fail("sigma must be finite and >= 0 (radians), got ", sigma);
  for (int l = 1; l < bandwidth; ++l) {
    coefficients.segment(l * l, 2 * l + 1) *= std::exp(-0.5 * l * (l + 1.0) * sigma * sigma);
  }
}

}  // namespace spectral_vs
