#include "alignment/normal_directions.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

namespace spectral_vs::detail {

namespace {

// The 26 directions to the neighbours of a voxel, about 35-45 degrees apart.
const std::array<Eigen::Vector3d, 26>& directions() {
  static const std::array<Eigen::Vector3d, 26> table = [] {
    std::array<Eigen::Vector3d, 26> d;
    int n = 0;
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z) {
          if (x || y || z) d[n++] = Eigen::Vector3d(x, y, z).normalized();
        }
    return d;
  }();
  return table;
}

}  // namespace

namespace {

// The nearest of the 26 directions without trying each: the best direction with k
// non-zero components takes the signs of the normal's k largest components, and scores
// the sum of their magnitudes over sqrt(k).
int nearest_direction(const Eigen::Vector3d& normal) {
  const Eigen::Array3d a = normal.cwiseAbs();
  int order[3] = {0, 1, 2};
  if (a[order[0]] < a[order[1]]) std::swap(order[0], order[1]);
  if (a[order[1]] < a[order[2]]) std::swap(order[1], order[2]);
  if (a[order[0]] < a[order[1]]) std::swap(order[0], order[1]);
  const double one = a[order[0]];
  const double two = (a[order[0]] + a[order[1]]) * M_SQRT1_2;
  const double three = (a[0] + a[1] + a[2]) * (1.0 / std::sqrt(3.0));
  const int count = three > std::max(one, two) ? 3 : (two > one ? 2 : 1);
  int component[3] = {0, 0, 0};
  for (int k = 0; k < count; ++k) component[order[k]] = normal[order[k]] < 0.0 ? -1 : 1;
  // The table's order: x, then y, then z from -1 to 1, without the zero vector (13).
  const int t = (component[0] + 1) * 9 + (component[1] + 1) * 3 + (component[2] + 1);
  return t < 13 ? t : t - 1;
}

}  // namespace

int normal_direction(const Eigen::Vector3d& normal, std::uint32_t* cone) {
  if (!cone) return nearest_direction(normal);
  int best = 0;
  double best_dot = -2.0;
  std::uint32_t within = 0;
  for (int i = 0; i < 26; ++i) {
    const double dot = directions()[std::size_t(i)].dot(normal);
    if (dot > best_dot) {
      best_dot = dot;
      best = i;
    }
    if (dot > 0.6428) within |= 1u << i;  // cos(50 degrees)
  }
  *cone = within | (1u << best);
  return best;
}

}  // namespace spectral_vs::detail
