#include "alignment/icp_refinement.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace spectral_vs::detail {

namespace {

std::uint64_t cell_key(const Eigen::Array3i& c) {
  const Eigen::Array3i k = (c + (1 << 20)).max(0).min((1 << 21) - 1);
  return (std::uint64_t(k.x()) << 42) | (std::uint64_t(k.y()) << 21) | std::uint64_t(k.z());
}

// The scene points near the model, in cells of max_distance: a point's nearest neighbour
// within that distance is in its own cell or one of the 26 around it.
class NeighbourGrid {
 public:
  NeighbourGrid(const PointCloud& scene, const Eigen::AlignedBox3d& around, double cell)
      : scene_(scene), cell_(cell) {
    for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
      const Eigen::Vector3d p = scene.points().row(i).transpose();
      if (around.contains(p)) cells_[cell_key(cell_of(p))].push_back(i);
    }
  }

  // The nearest scene point within `max_distance` of p whose normal has a cosine of at
  // least `min_cosine` with n; -1 if none.
  Eigen::Index nearest(const Eigen::Vector3d& p, const Eigen::Vector3d& n, double max_distance,
                       double min_cosine) const {
    Eigen::Index best = -1;
    double best_squared = max_distance * max_distance;
    const Eigen::Array3i c = cell_of(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(cell_key(c + Eigen::Array3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const Eigen::Index i : it->second) {
            const double squared = (scene_.points().row(i).transpose() - p).squaredNorm();
            if (squared < best_squared && scene_.normals().row(i).dot(n) >= min_cosine) {
              best_squared = squared;
              best = i;
            }
          }
        }
    return best;
  }

 private:
  Eigen::Array3i cell_of(const Eigen::Vector3d& p) const {
    return (p.array() / cell_).floor().cast<int>();
  }

  const PointCloud& scene_;
  double cell_;
  std::unordered_map<std::uint64_t, std::vector<Eigen::Index>> cells_;
};

}  // namespace

IcpOutcome refine_point_to_plane(const PointCloud& model, const PointCloud& scene,
                                 const Transform& T_scene_model, const IcpSettings& settings) {
  IcpOutcome outcome;
  outcome.T_scene_model = T_scene_model;
  Eigen::Matrix3d R = T_scene_model.topLeftCorner<3, 3>();
  Eigen::Vector3d t = T_scene_model.topRightCorner<3, 1>();
  const Points moved_at_start = (model.points() * R.transpose()).rowwise() + t.transpose();
  Eigen::AlignedBox3d around(moved_at_start.colwise().minCoeff().transpose(),
                             moved_at_start.colwise().maxCoeff().transpose());
  // Room for the motion of the steps: a few max_distances.
  around.min().array() -= 4.0 * settings.max_distance;
  around.max().array() += 4.0 * settings.max_distance;
  const NeighbourGrid grid(scene, around, settings.max_distance);
  // About one model point in `share`: a couple of thousand pairs pin six degrees of
  // freedom. Chosen by a multiplicative hash of the index, not every k-th point, which
  // would alias with a cloud stored in a regular order (alternating parts, scan rows).
  const std::uint64_t share =
      std::uint64_t(std::max<Eigen::Index>(1, model.points().rows() / settings.max_points));
  const auto takes_part = [share](Eigen::Index i) {
    return share == 1 || ((std::uint64_t(i) * 0x9E3779B97F4A7C15ull) >> 40) % share == 0;
  };

  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    std::vector<std::pair<Eigen::Index, Eigen::Index>> pairs;  // (model row, scene row)
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (Eigen::Index i = 0; i < model.points().rows(); ++i) {
      if (!takes_part(i)) continue;
      const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
      const Eigen::Vector3d n = R * model.normals().row(i).transpose();
      if (settings.viewpoint && n.dot(*settings.viewpoint - p) <= 0.0) continue;
      const Eigen::Index j = grid.nearest(p, n, settings.max_distance, settings.min_cosine);
      if (j < 0) continue;
      pairs.emplace_back(i, j);
      centroid += p;
    }
    outcome.pairs = static_cast<int>(pairs.size());
    if (pairs.size() < 6) return outcome;
    centroid /= double(pairs.size());
    // Residual r = (p - q) . n_q; linearised in the rotation w about the centroid and the
    // translation u: r + ((p - c) x n_q) . w + n_q . u.
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (const auto& [i, j] : pairs) {
      const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
      const Eigen::Vector3d q = scene.points().row(j).transpose();
      const Eigen::Vector3d nq = scene.normals().row(j).transpose();
      Eigen::Matrix<double, 6, 1> J;
      J << (p - centroid).cross(nq), nq;
      const double r = (p - q).dot(nq);
      H.noalias() += J * J.transpose();
      g.noalias() += J * r;
    }
    const Eigen::Matrix<double, 6, 1> step = H.ldlt().solve(-g);
    if (!step.allFinite()) return outcome;
    const Eigen::Matrix3d turn = exp_so3(step.head<3>());
    // x -> turn (x - c) + c + u, applied after the current pose.
    t = turn * (t - centroid) + centroid + step.tail<3>();
    R = turn * R;
    outcome.iterations = iteration + 1;
    outcome.T_scene_model.topLeftCorner<3, 3>() = R;
    outcome.T_scene_model.topRightCorner<3, 1>() = t;
    if (step.head<3>().norm() < 1e-6 && step.tail<3>().norm() < 1e-6) break;
  }
  return outcome;
}

}  // namespace spectral_vs::detail
