// Stage of align_views(): preparation. Each view's dominant plane (a table top, a floor)
// weighed down, the crop of its spatial outliers, and its structure off the plane; the
// views as every later stage reads them (PreparedViews).

#include <spectral_vs/representation/dominant_plane.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/normal_directions.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/view_stages.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <cmath>

namespace spectral_vs::detail::views {

namespace {

// A view's dominant plane (a table top, a floor): the normals within kPlaneCone of its
// most common direction, when they are over kDominantShare of the view's. Measured on the
// simulated table, 92% of a view's normals are the table's: the EGI is then one peak
// that leaves the rotation about its normal unseen, and every pose that keeps the table
// on itself passes the support check.
constexpr double kPlaneCone = 20.0 * M_PI / 180.0;
constexpr double kDominantShare = 0.4;
// ... and only when the rest is at least this share: a view of little but the plane has
// no structure to weigh it against.
constexpr double kMinStructureShare = 0.005;
// The translation grids hold each view without its spatial outliers: the box between
// these per-axis quantiles, grown by this share of its diagonal.
constexpr double kCropQuantile = 0.05;
constexpr double kCropMargin = 0.05;

}  // namespace

PlaneBalance plane_balance(const Points& normals) {
  PlaneBalance balance;
  balance.on_plane.assign(std::size_t(normals.rows()), 0);
  if (normals.rows() == 0) return balance;
  std::array<int, 26> votes{};
  for (Eigen::Index i = 0; i < normals.rows(); ++i)
    ++votes[std::size_t(detail::normal_direction(normals.row(i).transpose()))];
  const int mode = int(std::max_element(votes.begin(), votes.end()) - votes.begin());
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    if (detail::normal_direction(normals.row(i).transpose()) == mode) axis += normals.row(i);
  }
  const double cos_cone = std::cos(kPlaneCone);
  for (int round = 0; round < 3; ++round) {  // the mean of the normals in the cone
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    axis.normalize();
    for (Eigen::Index i = 0; i < normals.rows(); ++i) {
      if (normals.row(i).dot(axis) > cos_cone) sum += normals.row(i);
    }
    if (sum.isZero()) return balance;
    axis = sum;
  }
  axis.normalize();
  Eigen::Index on = 0;
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    balance.on_plane[std::size_t(i)] = normals.row(i).dot(axis) > cos_cone;
    on += balance.on_plane[std::size_t(i)];
  }
  const Eigen::Index off = normals.rows() - on;
  if (double(on) <= kDominantShare * double(normals.rows()) ||
      double(off) < kMinStructureShare * double(normals.rows())) {
    std::fill(balance.on_plane.begin(), balance.on_plane.end(), 0);
    return balance;
  }
  balance.plane_weight = double(off) / double(on);
  return balance;
}

// The points (and normals) of `view` at the rows `kept`.
PointCloud subset(const PointCloud& view, const std::vector<Eigen::Index>& kept) {
  return PointCloud(detail::rows_of(view.points(), kept), detail::rows_of(view.normals(), kept));
}

// The view thinned by its balance: the points on its plane kept with the probability of
// their weight (deterministically, by a running sum), the others all.
PointCloud balanced(const PointCloud& view, const PlaneBalance& balance) {
  if (!balance.has_plane()) return view;
  std::vector<Eigen::Index> kept;
  double carried = 0.0;
  for (Eigen::Index i = 0; i < view.points().rows(); ++i) {
    if (balance.on_plane[std::size_t(i)]) {
      carried += balance.plane_weight;
      if (carried < 1.0) continue;
      carried -= 1.0;
    }
    kept.push_back(i);
  }
  return subset(view, kept);
}

// The view without its outliers in space: the points inside its box from the
// kCropQuantile-th to the (1 - kCropQuantile)-th quantile per axis, grown by kCropMargin
// of that box's diagonal. A depth camera's few far returns (a floor behind the table, a
// window) would otherwise set the size of every translation grid.
PointCloud cropped(const PointCloud& view) {
  const Points& points = view.points();
  Eigen::AlignedBox3d box;
  std::vector<double> values(std::size_t(points.rows()));
  for (int axis = 0; axis < 3; ++axis) {
    for (Eigen::Index i = 0; i < points.rows(); ++i) values[std::size_t(i)] = points(i, axis);
    const auto at = [&](double q) {
      const auto k = std::ptrdiff_t(std::floor(q * double(values.size() - 1)));
      std::nth_element(values.begin(), values.begin() + k, values.end());
      return values[std::size_t(k)];
    };
    box.min()[axis] = at(kCropQuantile);
    box.max()[axis] = at(1.0 - kCropQuantile);
  }
  const double margin = kCropMargin * box.sizes().norm();
  box.min().array() -= margin;
  box.max().array() += margin;
  std::vector<Eigen::Index> kept;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    if (box.contains(points.row(i).transpose())) kept.push_back(i);
  }
  // Per-axis quantiles of a few points can leave a box that holds few of them.
  if (2 * kept.size() < std::size_t(points.rows())) return view;
  if (Eigen::Index(kept.size()) == points.rows()) return view;
  return subset(view, kept);
}

// The points of the view off its dominant plane (all without one): the structure whose
// support tells a right pose from one that only lays the plane onto itself.
PointCloud structure(const PointCloud& view, const PlaneBalance& balance) {
  if (!balance.has_plane()) return view;
  std::vector<Eigen::Index> kept;
  for (Eigen::Index i = 0; i < view.points().rows(); ++i) {
    if (!balance.on_plane[std::size_t(i)]) kept.push_back(i);
  }
  return subset(view, kept);
}

PointCloud prepared(const PointCloud& view, const ViewAlignParams& params, double voxel_size) {
  // Both views arrive with normals (check_views): the one preparation only downsamples.
  return prepare_cloud(view, voxel_size, params.downsample, params.sensor_origin, "view");
}

namespace {

// The box of the current view grown by two search voxels: the ICP's grids' extent.
Eigen::AlignedBox3d icp_box(const PointCloud& current, const ViewScale& scale) {
  Eigen::AlignedBox3d around = bounding_box(current);
  around.min().array() -= 2.0 * scale.search_voxel_size;
  around.max().array() += 2.0 * scale.search_voxel_size;
  return around;
}

}  // namespace

PreparedViews::PreparedViews(const PointCloud& reference_view, const PointCloud& current_view,
                             const ViewAlignParams& params, const ViewScale& scale,
                             Clock::time_point started)
    : params_(params),
      scale_(scale),
      phase_(detail::phase_params(local_, params.threads, params.limits)),
      reference_(prepared(reference_view, params, scale.voxel_size)),
      current_(prepared(current_view, params, scale.voxel_size)),
      reference_balance_(plane_balance(reference_.normals())),
      reference_balanced_(cropped(balanced(reference_, reference_balance_))),
      current_balanced_(cropped(balanced(current_, plane_balance(current_.normals())))),
      model_(reference_balanced_),
      map_(current_balanced_),
      reference_coefficients_(
          egi_coefficients(reference_balanced_, params.bandwidth, params.egi_method)),
      current_coefficients_(
          egi_coefficients(current_balanced_, params.bandwidth, params.egi_method)),
      correlation_(current_coefficients_, reference_coefficients_, params.bandwidth, true),
      verifier_(current_, scale.voxel_size, params.sensor_origin),
      support_(verifier_, structure(reference_, reference_balance_)),
      around_(icp_box(current_, scale)),
      current_coarse_(voxel_downsample(current_, scale.voxel_size)),
      coarse_scene_(current_coarse_, around_, scale.search_voxel_size),
      fine_scene_(current_, around_, scale.voxel_size),
      deadline_(detail::deadline_of(params.max_seconds, started)) {}

Views PreparedViews::views() {
  return Views{reference_,
               current_,
               params_,
               local_,
               phase_,
               scale_,
               model_,
               reference_balanced_,
               map_,
               reference_coefficients_,
               current_coefficients_,
               correlation_,
               verifier_,
               support_,
               coarse_scene_,
               fine_scene_,
               deadline_};
}

}  // namespace spectral_vs::detail::views
