#include "alignment/point_sets.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_map>

namespace spectral_vs::detail {

Points rows_of(const Points& matrix, const std::vector<Eigen::Index>& rows) {
  Points selected(static_cast<Eigen::Index>(rows.size()), 3);
  for (std::size_t i = 0; i < rows.size(); ++i) selected.row(Eigen::Index(i)) = matrix.row(rows[i]);
  return selected;
}

PointCloud every_nth(const PointCloud& cloud, Eigen::Index stride) {
  const Eigen::Index n = (cloud.size() + stride - 1) / stride;
  Points points(n, 3), normals(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    points.row(i) = cloud.points().row(i * stride);
    normals.row(i) = cloud.normals().row(i * stride);
  }
  return PointCloud(points, normals);
}

std::uint64_t voxel_key(const Eigen::Array3i& voxel) {
  const Eigen::Array3i k = (voxel + (1 << 20)).max(0).min((1 << 21) - 1);
  return (std::uint64_t(k.x()) << 42) | (std::uint64_t(k.y()) << 21) | std::uint64_t(k.z());
}

Eigen::AlignedBox3d points_box(const Points& points) {
  return Eigen::AlignedBox3d(points.colwise().minCoeff().transpose(),
                             points.colwise().maxCoeff().transpose());
}

Points points_in_reach(const Points& scene, const Eigen::AlignedBox3d& model_box,
                       double max_translation) {
  const Eigen::Array3d low = model_box.min().array() - max_translation;
  const Eigen::Array3d high = model_box.max().array() + max_translation;
  std::vector<Eigen::Index> rows;
  rows.reserve(std::size_t(scene.rows()));
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    const Eigen::Array3d p = scene.row(i).transpose().array();
    if ((p >= low).all() && (p <= high).all()) rows.push_back(i);
  }
  if (rows.empty() || Eigen::Index(rows.size()) == scene.rows()) return scene;
  Points out(Eigen::Index(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) out.row(Eigen::Index(k)) = scene.row(rows[k]);
  return out;
}

namespace {

// Union-find over point indices, with path halving; the smaller index is the root, so
// the parts do not depend on the order of the unions.
struct DisjointSets {
  std::vector<Eigen::Index> parent;
  explicit DisjointSets(Eigen::Index n) : parent(std::size_t(n)) {
    std::iota(parent.begin(), parent.end(), 0);
  }
  Eigen::Index find(Eigen::Index i) {
    while (parent[std::size_t(i)] != i)
      i = parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
    return i;
  }
  void unite(Eigen::Index a, Eigen::Index b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
  }
};

}  // namespace

std::vector<std::vector<Eigen::Index>> connected_parts(const Points& points, double tolerance) {
  // Cells of diagonal `tolerance`: the points of one cell are all connected, so sets
  // join whole cells, and a pair of cells is searched for a close pair of points only
  // until the first one is found.
  const double edge = tolerance / std::sqrt(3.0);
  std::unordered_map<std::uint64_t, Eigen::Index> cell_index;
  std::vector<Eigen::Array3i> cells;
  std::vector<std::vector<Eigen::Index>> members;
  std::vector<Eigen::Index> cell_of_point(std::size_t(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Array3i c = (points.row(i).array() / edge).floor().cast<int>();
    const auto [it, added] = cell_index.try_emplace(voxel_key(c), Eigen::Index(cells.size()));
    if (added) {
      cells.push_back(c);
      members.emplace_back();
    }
    members[std::size_t(it->second)].push_back(i);
    cell_of_point[std::size_t(i)] = it->second;
  }
  const auto close = [&](Eigen::Index a, Eigen::Index b) {
    for (const Eigen::Index i : members[std::size_t(a)])
      for (const Eigen::Index j : members[std::size_t(b)])
        if ((points.row(i) - points.row(j)).squaredNorm() <= tolerance * tolerance) return true;
    return false;
  };
  DisjointSets sets(Eigen::Index(cells.size()));
  for (Eigen::Index a = 0; a < Eigen::Index(cells.size()); ++a) {
    for (int dx = -2; dx <= 2; ++dx)
      for (int dy = -2; dy <= 2; ++dy)
        for (int dz = -2; dz <= 2; ++dz) {
          const auto it =
              cell_index.find(voxel_key(cells[std::size_t(a)] + Eigen::Array3i(dx, dy, dz)));
          if (it == cell_index.end() || it->second <= a) continue;
          if (sets.find(a) != sets.find(it->second) && close(a, it->second))
            sets.unite(a, it->second);
        }
  }
  std::vector<std::vector<Eigen::Index>> parts;
  std::vector<Eigen::Index> part_of_root(cells.size(), -1);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    Eigen::Index& part = part_of_root[std::size_t(sets.find(cell_of_point[std::size_t(i)]))];
    if (part < 0) {
      part = Eigen::Index(parts.size());
      parts.emplace_back();
    }
    parts[std::size_t(part)].push_back(i);
  }
  std::stable_sort(parts.begin(), parts.end(),
                   [](const auto& a, const auto& b) { return a.size() > b.size(); });
  return parts;
}

}  // namespace spectral_vs::detail
