#include "alignment/icp_refinement.hpp"

#include "alignment/point_sets.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace spectral_vs::detail {

IcpScene::IcpScene(const PointCloud& scene, const Eigen::AlignedBox3d& around, double max_distance)
    : scene_(scene) {
  constexpr double kMaxCells = 4194304.0;  // 2^22: 32 MB of offsets at most
  const Eigen::Array3d extent = around.sizes().array();
  // From a millionth of the extent at least: 1.25 times the smallest denormal is itself,
  // and the loop below never ended for pose_covariance(voxel_size=5e-324).
  cell_ = std::max(max_distance, 1e-6 * extent.maxCoeff());
  origin_ = around.min();
  // Coarser cells for a large model (a flat one too): still at least max_distance wide.
  // Counted in double, so that no count overflows an int before it is checked.
  while (((extent / cell_).floor() + 1.0).prod() > kMaxCells) cell_ *= 1.25;
  dims_ = ((extent / cell_).floor() + 1.0).cast<int>();
  std::vector<std::pair<std::int64_t, Eigen::Index>> keyed;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
    const Eigen::Vector3d p = scene.points().row(i).transpose();
    if (around.contains(p)) keyed.emplace_back(linear(cell_of(p)), i);
  }
  std::sort(keyed.begin(), keyed.end());
  start_.assign(std::size_t(dims_.prod()) + 1, 0);
  rows_.reserve(keyed.size());
  for (const auto& [cell, row] : keyed) {
    ++start_[std::size_t(cell) + 1];
    rows_.push_back(row);
  }
  for (std::size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
  points_ = rows_of(scene.points(), rows_);
  normals_ = rows_of(scene.normals(), rows_);
}

inline void IcpScene::closest_in(std::int64_t cell, const Eigen::Vector3d& p,
                                 const Eigen::Vector3d& n, double min_cosine, bool own_cell,
                                 Nearest& nearest) const {
  for (std::size_t k = start_[std::size_t(cell)]; k < start_[std::size_t(cell) + 1]; ++k) {
    const double squared = (points_.row(Eigen::Index(k)).transpose() - p).squaredNorm();
    if (nearest.beaten_by(squared) && normals_.row(Eigen::Index(k)).dot(n) >= min_cosine) {
      nearest.squared = squared;
      nearest.row = rows_[k];
      nearest.in_own_cell = own_cell;
    }
  }
}

Eigen::Index IcpScene::nearest(const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                               double max_distance, double min_cosine) const {
  Nearest nearest;
  nearest.squared = max_distance * max_distance;
  const Eigen::Array3i c = cell_of(p);
  // Its own cell first: a pair found there prunes most of the 26 around it.
  const bool inside = (c >= 0).all() && (c < dims_).all();
  if (inside) closest_in(linear(c), p, n, min_cosine, true, nearest);
  // Per axis, the squared distance from p to the cells below, at and above its own (0 at
  // its own): a cell farther than the best pair so far cannot hold a nearer point, nor
  // can a row or a slab of cells farther than it. In the cells before the own one (in
  // the order of the loops) a point as near as one found there replaces it: of equally
  // near points the first in that order is taken, as when the own cell came in its turn.
  Eigen::Array<double, 3, 3> gap;  // gap(axis, d + 1)
  for (int axis = 0; axis < 3; ++axis) {
    const double low = origin_[axis] + double(c[axis]) * cell_;
    gap(axis, 0) = std::max(0.0, p[axis] - low);
    gap(axis, 1) = std::max({0.0, low - p[axis], p[axis] - (low + cell_)});
    gap(axis, 2) = std::max(0.0, low + cell_ - p[axis]);
    for (int d = 0; d < 3; ++d) gap(axis, d) *= gap(axis, d);
  }
  const Eigen::Array3i first = (c - 1).max(0), last = (c + 1).min(dims_ - 1);
  for (int x = first.x(); x <= last.x(); ++x) {
    const double gap_x = gap(0, x - c.x() + 1);
    nearest.before_own_cell = inside && x <= c.x();  // the slab of the own cell: in part
    if (!nearest.beaten_by(gap_x)) continue;
    for (int y = first.y(); y <= last.y(); ++y) {
      const double gap_xy = gap_x + gap(1, y - c.y() + 1);
      nearest.before_own_cell = inside && (x < c.x() || (x == c.x() && y <= c.y()));
      if (!nearest.beaten_by(gap_xy)) continue;
      const std::int64_t row = (std::int64_t(x) * dims_.y() + y) * dims_.z();
      for (int z = first.z(); z <= last.z(); ++z) {
        const bool own_row = inside && x == c.x() && y == c.y();
        if (own_row && z == c.z()) continue;  // searched first
        nearest.before_own_cell =
            inside && (x < c.x() || (x == c.x() && (y < c.y() || (own_row && z < c.z()))));
        if (!nearest.beaten_by(gap_xy + gap(2, z - c.z() + 1))) continue;
        closest_in(row + z, p, n, min_cosine, false, nearest);
      }
    }
  }
  return nearest.row;
}

namespace {

// About one model row in `share` = rows / max_points: a couple of thousand pairs pin six
// degrees of freedom. Chosen by a multiplicative hash of the index, not every k-th row,
// which would alias with a cloud stored in a regular order (alternating parts, scan rows).
std::vector<Eigen::Index> sampled_rows(Eigen::Index rows, Eigen::Index max_points) {
  const std::uint64_t share = std::uint64_t(std::max<Eigen::Index>(1, rows / max_points));
  std::vector<Eigen::Index> sampled;
  for (Eigen::Index i = 0; i < rows; ++i) {
    if (share == 1 || ((std::uint64_t(i) * 0x9E3779B97F4A7C15ull) >> 40) % share == 0)
      sampled.push_back(i);
  }
  return sampled;
}

}  // namespace

IcpOutcome refine_point_to_plane(const PointCloud& model, const PointCloud& scene,
                                 const Transform& T_scene_model, const IcpSettings& settings) {
  const Eigen::Matrix3d R = T_scene_model.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T_scene_model.topRightCorner<3, 1>();
  const Points moved_at_start = (model.points() * R.transpose()).rowwise() + t.transpose();
  Eigen::AlignedBox3d around = points_box(moved_at_start);
  // Room for the motion of the steps: a few max_distances.
  around.min().array() -= 4.0 * settings.max_distance;
  around.max().array() += 4.0 * settings.max_distance;
  return refine_point_to_plane(model, IcpScene(scene, around, settings.max_distance), T_scene_model,
                               settings);
}

IcpOutcome refine_point_to_plane(const PointCloud& model, const IcpScene& grid,
                                 const Transform& T_scene_model, const IcpSettings& settings) {
  const PointCloud& scene = grid.cloud();
  IcpOutcome outcome;
  outcome.T_scene_model = T_scene_model;
  Eigen::Matrix3d R = T_scene_model.topLeftCorner<3, 3>();
  Eigen::Vector3d t = T_scene_model.topRightCorner<3, 1>();
  const std::vector<Eigen::Index> sampled =
      sampled_rows(model.points().rows(), settings.max_points);
  struct Pair {
    Eigen::Index scene_row;
    Eigen::Vector3d moved;  // the model point at the step's pose
  };
  std::vector<Pair> pairs;
  pairs.reserve(sampled.size());
  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    pairs.clear();
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Index i : sampled) {
      const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
      const Eigen::Vector3d n = R * model.normals().row(i).transpose();
      if (settings.viewpoint && n.dot(*settings.viewpoint - p) <= 0.0) continue;
      const Eigen::Index j = grid.nearest(p, n, settings.max_distance, settings.min_cosine);
      if (j < 0) continue;
      pairs.push_back({j, p});
      centroid += p;
    }
    outcome.pairs = static_cast<int>(pairs.size());
    if (pairs.size() < 6) return outcome;
    centroid /= double(pairs.size());
    // Residual r = (p - q) . n_q; linearised in the rotation w about the centroid and the
    // translation u: r + ((p - c) x n_q) . w + n_q . u.
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (const Pair& pair : pairs) {
      const Eigen::Vector3d& p = pair.moved;
      const Eigen::Vector3d q = scene.points().row(pair.scene_row).transpose();
      const Eigen::Vector3d nq = scene.normals().row(pair.scene_row).transpose();
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
    if (step.head<3>().norm() < 1e-4 && step.tail<3>().norm() < 2e-5) break;
  }
  return outcome;
}

namespace {

template <class Scene>
IcpOutcome two_stages(const PointCloud& model, const Scene& scene, const Transform& T_scene_model,
                      double voxel_size, IcpSettings settings, bool fine) {
  IcpOutcome outcome;
  outcome.T_scene_model = T_scene_model;
  for (int stage = 0; stage < (fine ? 2 : 1); ++stage) {
    settings.max_distance = (stage == 0 ? 1.0 : kIcpFineDistance) * voxel_size;
    const IcpOutcome step = refine_point_to_plane(model, scene, outcome.T_scene_model, settings);
    outcome.pairs = step.pairs;
    if (step.iterations == 0) break;
    outcome.T_scene_model = step.T_scene_model;
    outcome.iterations += step.iterations;
  }
  return outcome;
}

}  // namespace

IcpOutcome refine_in_two_stages(const PointCloud& model, const IcpScene& scene,
                                const Transform& T_scene_model, double voxel_size,
                                IcpSettings settings, bool fine) {
  return two_stages(model, scene, T_scene_model, voxel_size, std::move(settings), fine);
}

IcpOutcome refine_in_two_stages(const PointCloud& model, const PointCloud& scene,
                                const Transform& T_scene_model, double voxel_size,
                                IcpSettings settings, bool fine) {
  return two_stages(model, scene, T_scene_model, voxel_size, std::move(settings), fine);
}

}  // namespace spectral_vs::detail
