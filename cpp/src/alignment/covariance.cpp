// The verdict's covariance: the cluster-robust covariance of the point-to-plane fit of a
// pose (verdict.hpp, pose_covariance; docs/trust.md).
#include <spectral_vs/alignment/verdict.hpp>

#include "alignment/normal_directions.hpp"
#include "alignment/scale.hpp"
#include "alignment/verdict_detail.hpp"
#include "common/checks.hpp"

#include <Eigen/Eigenvalues>

#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <vector>

namespace spectral_vs {

namespace detail {

namespace {

// Residuals are grouped in cubic cells of this many pair distances (voxels): the
// normals are fitted over 2 voxels around each point and the grids sample the surface at
// a voxel, so neighbours within about 4 voxels share their errors, and such a cell is
// one observation rather than its many points.
constexpr double kClusterVoxels = 4.0;

struct PointToPlaneFit {
  PoseCovariance information = PoseCovariance::Zero();  // sum J J^T
  PoseCovariance meat = PoseCovariance::Zero();         // sum over cells of g g^T, g = sum J r
  double squared_sum = 0.0;
  int pairs = 0;
  int cells = 0;
};

// The cell of a pair: its scene point q's position across its normal n (q less its
// component along n), in cells of `cell` metres, and n's dominant signed axis. Not q
// itself: a cell's wall along a surface would split its points by the sign of their
// residuals, which then no longer average out within a cell.
std::array<std::int64_t, 4> cell_of(const Eigen::Vector3d& q, const Eigen::Vector3d& n,
                                    double cell) {
  const Eigen::Vector3d across = q - n.dot(q) * n;
  Eigen::Index axis = 0;
  n.cwiseAbs().maxCoeff(&axis);
  return {std::int64_t(std::floor(across.x() / cell)), std::int64_t(std::floor(across.y() / cell)),
          std::int64_t(std::floor(across.z() / cell)),
          std::int64_t(2 * axis + (n(axis) < 0.0 ? 1 : 0))};
}

PointToPlaneFit point_to_plane_fit(const PointCloud& model, const IcpScene& scene,
                                   const Transform& T, double max_distance) {
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  const Points& scene_points = scene.cloud().points();
  const Points& scene_normals = scene.cloud().normals();
  const double cell = kClusterVoxels * max_distance;
  std::map<std::array<std::int64_t, 4>, Eigen::Matrix<double, 6, 1>> gradients;
  PointToPlaneFit fit;
  for (Eigen::Index i = 0; i < model.points().rows(); ++i) {
    const Eigen::Vector3d p = R * model.points().row(i).transpose() + t;
    const Eigen::Vector3d n = R * model.normals().row(i).transpose();
    const Eigen::Index j = scene.nearest(p, n, max_distance, kAgreeingCosine);
    if (j < 0) continue;
    const Eigen::Vector3d normal = scene_normals.row(j).transpose();
    const double residual = normal.dot(p - scene_points.row(j).transpose());
    Eigen::Matrix<double, 6, 1> J;
    J << p.cross(normal), normal;
    fit.information.selfadjointView<Eigen::Lower>().rankUpdate(J);
    const std::array<std::int64_t, 4> key = cell_of(scene_points.row(j).transpose(), normal, cell);
    auto [entry, added] = gradients.try_emplace(key, Eigen::Matrix<double, 6, 1>::Zero());
    entry->second += J * residual;
    fit.squared_sum += residual * residual;
    ++fit.pairs;
  }
  fit.information = fit.information.selfadjointView<Eigen::Lower>();
  for (const auto& [key, g] : gradients) fit.meat.noalias() += g * g.transpose();
  fit.cells = int(gradients.size());
  return fit;
}

}  // namespace

PoseCovariance covariance_at(const PointCloud& model, const IcpScene& scene, const Transform& T,
                             double max_distance, double scene_extent, double inflation) {
  const PointToPlaneFit fit = point_to_plane_fit(model, scene, T, max_distance);
  // The prior: one standard deviation of pi radians and of the scene's size.
  const double size = std::max(scene_extent, max_distance);
  PoseCovariance prior = PoseCovariance::Zero();
  prior.diagonal() << Eigen::Vector3d::Constant(1.0 / (M_PI * M_PI)),
      Eigen::Vector3d::Constant(1.0 / (size * size));
  if (fit.pairs <= 6) return prior.inverse();
  // The residuals' variance, floored at a hundredth of the pairs' distance: an exact copy
  // (a zero residual) is not infinitely precise.
  const double floor_variance = std::pow(0.01 * max_distance, 2);
  // The cluster-robust (sandwich) covariance H^-1 M H^-1 on the directions the surfaces
  // constrain, M the cells' gradients' scatter (with the small-sample factor c / (c - 6)
  // when there are more cells than unknowns) plus the floor: its information there is
  // H (M + floor H)^-1 H, and the prior's alone elsewhere.
  const Eigen::SelfAdjointEigenSolver<PoseCovariance> directions(fit.information);
  const double largest = directions.eigenvalues().maxCoeff();
  const double small_sample = fit.cells > 6 ? double(fit.cells) / double(fit.cells - 6) : 1.0;
  PoseCovariance information = prior;
  std::vector<int> constrained;
  for (int i = 0; i < 6; ++i)
    if (directions.eigenvalues()(i) > 1e-9 * largest) constrained.push_back(i);
  const int rank = int(constrained.size());
  if (rank > 0) {
    Eigen::MatrixXd V(6, rank);
    Eigen::VectorXd lambda(rank);
    for (int c = 0; c < rank; ++c) {
      V.col(c) = directions.eigenvectors().col(constrained[std::size_t(c)]);
      lambda(c) = directions.eigenvalues()(constrained[std::size_t(c)]);
    }
    const Eigen::MatrixXd meat = small_sample * V.transpose() * fit.meat * V +
                                 Eigen::MatrixXd(floor_variance * lambda.asDiagonal());
    const Eigen::MatrixXd inner =
        lambda.asDiagonal() * meat.llt().solve(Eigen::MatrixXd(lambda.asDiagonal()));
    information += V * (0.5 * (inner + inner.transpose())) * V.transpose() / inflation;
  }
  const Eigen::SelfAdjointEigenSolver<PoseCovariance> solver(information);
  const Eigen::Matrix<double, 6, 1> inverse = solver.eigenvalues().cwiseInverse();
  return solver.eigenvectors() * inverse.asDiagonal() * solver.eigenvectors().transpose();
}

}  // namespace detail

PoseCovariance pose_covariance(const PointCloud& model, const PointCloud& scene,
                               const Transform& T_scene_model, double voxel_size) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  detail::require_positive_finite(voxel_size, "voxel_size");
  if (voxel_size > 1e6) detail::fail("voxel_size must be <= 1e6 m, got ", voxel_size);
  require_rigid_transform(T_scene_model, "T_scene_model");
  // The pairs' grid alone (as the verification's, without its visibility grid).
  const double pairs = kInlierVoxels * voxel_size;
  Eigen::AlignedBox3d around = bounding_box(scene);
  around.min().array() -= kVisibilityVoxels * voxel_size;
  around.max().array() += kVisibilityVoxels * voxel_size;
  return detail::covariance_at(model, detail::IcpScene(scene, around, pairs), T_scene_model, pairs,
                               detail::typical_size(scene.points()),
                               covariance_inflation(RegistrationKind::model_to_scene));
}

}  // namespace spectral_vs
