// Scene-to-scene registration as a pipeline of stages: scale, preparation, hypotheses
// (the SO(3) search of the views' EGIs, each rotation placed by phase correlation),
// verification (the support of the current view), refinement (Algorithm 1, the ICP).

#include <spectral_vs/alignment/view_aligner.hpp>

#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/algorithm1.hpp"
#include "alignment/align_detail.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/normal_directions.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/range_image.hpp"
#include "alignment/scale.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verdict_detail.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <optional>

namespace spectral_vs {

using detail::fail;
using detail::Pose;
using detail::SceneTranslation;

namespace {

using Clock = std::chrono::steady_clock;

// Reference points the support is checked on, at most: a hashed selection beyond it (the
// support of a pose is a share, which 4000 points measure to about 1%).
constexpr Eigen::Index kSupportPoints = 4000;
// Iterations of the EGI refinement of each rotation of the SO(3) search, before it is
// placed: the grid's nodes are pi / B apart (11 degrees at B = 16).
constexpr int kRotationRefineIterations = 20;
// The ICP's pose is kept unless it loses this much of the coarse score (as align()'s
// fitness rule): at a voxel's tolerance a precise pose scores about as a rough one, and
// the refined poses are compared precise.
constexpr double kIcpScoreLoss = 0.05;
// Translation room of Algorithm 1 around each hypothesis, in search voxels: the
// placement is within half a search voxel, the rotation within a few degrees.
constexpr double kRefinementRoom = 2.0;
// Translation room of the hypotheses' placement, in view extents (ViewScale::extent).
constexpr double kPlacementRoom = 1.0;
// Depth tolerances of the support check, in voxels: a hypothesis is a search voxel and a
// few degrees off, a refined pose (after the ICP) a small part of a voxel; checked that
// closely, a pose turned about a scene's dominant plane no longer passes for the right one.
constexpr double kCoarseTolerance = 1.0;
// The ICP of each hypothesis before it is checked: about this many reference points (the
// balanced view), this many Gauss-Newton steps at most.
constexpr Eigen::Index kCoarseIcpPoints = 500;
constexpr int kCoarseIcpIterations = 10;
constexpr double kFineTolerance = 0.25;

// The window search (after a missed search): cubic windows of the current view as large
// as the reference's typical size, centres kWindowStride of a side apart, each holding at
// least kWindowMinShare of the current's points; kWindowRotations SO(3) candidates per
// window, each placed within kWindowRoom of a side of where it starts (the reference's
// centroid on the window's).
constexpr double kWindowStride = 0.5;
constexpr double kWindowMinShare = 0.02;
constexpr int kWindowRotations = 2;
constexpr double kWindowRoom = 0.5;
// Best-supported window hypotheses refined: the views that set the window search off are
// those whose checked scores say least, and on the rendered iiwa pairs of seed 7 (tuning)
// a right window hypothesis came second or third of them; 5 won no more.
constexpr int kWindowRefinements = 3;

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

// The verdict: reference points it checks, at most (a stride over the prepared
// reference: the score is a share, which 8000 points measure to about 1%); hypotheses
// refined as candidate alternatives, of those whose coarse support is at least
// kAlternativeSupportShare of the best one's; the margin of score within which one is an
// alternative (as align()'s); the alternatives kept.
constexpr Eigen::Index kVerdictPoints = 8000;
constexpr int kAlternativeCandidates = 4;
constexpr double kAlternativeSupportShare = 0.5;
constexpr double kViewAlternativeMargin = 0.05;
constexpr std::size_t kMaxViewAlternatives = 3;
// Poses apart: over this rotation, or over a voxel between the reference's centroids.
constexpr double kApartRadians = 5.0 * M_PI / 180.0;

void check_params(const ViewAlignParams& p) {
  check_grid_limits(p.limits);
  if (!(p.voxel_size >= 0.0 && std::isfinite(p.voxel_size)))
    fail("voxel_size must be >= 0 metres (0: derived from the views), got ", p.voxel_size);
  if (!(p.search_voxel_size >= 0.0 && std::isfinite(p.search_voxel_size)))
    fail("search_voxel_size must be >= 0 metres (0: twice the voxel), got ", p.search_voxel_size);
  if (!(p.voxels_across >= 4.0 && std::isfinite(p.voxels_across)))
    fail("voxels_across must be finite and >= 4, got ", p.voxels_across);
  if (p.bandwidth < 2 || p.bandwidth > kMaxAlignBandwidth)
    fail("bandwidth must be in [2, ", kMaxAlignBandwidth, "], got ", p.bandwidth);
  if (p.hypotheses < 1) fail("hypotheses must be >= 1, got ", p.hypotheses);
  if (p.refinements < 1 || p.refinements > p.hypotheses)
    fail("refinements must be in [1, hypotheses = ", p.hypotheses, "], got ", p.refinements);
  if (p.refinement_iterations < 1 || p.refinement_iterations > kMaxAlignIterations)
    fail("refinement_iterations must be in [1, ", kMaxAlignIterations, "], got ",
         p.refinement_iterations);
  if (!p.sensor_origin.allFinite()) fail("sensor_origin must be finite");
  if (!(p.window_search_below >= 0.0 && p.window_search_below <= 1.0))
    fail("window_search_below must be in [0, 1] (a support score; 0: never), got ",
         p.window_search_below);
  if (!(p.max_seconds >= 0.0 && std::isfinite(p.max_seconds)))
    fail("max_seconds must be >= 0 seconds (0: no limit), got ", p.max_seconds);
  if (p.threads < 1 || p.threads > 256) fail("threads must be in [1, 256], got ", p.threads);
}

// The settings of align() that Algorithm 1 and the phase correlation read.
AlignParams loop_params(const ViewAlignParams& p, const ViewScale& scale) {
  AlignParams a;
  a.scene.voxel_size = scale.voxel_size;
  a.scene.bandwidth = p.bandwidth;
  a.threads = p.threads;
  a.scene.occupancy = p.occupancy;
  a.scene.egi_method = p.egi_method;
  a.limits = p.limits;
  a.max_seconds = p.max_seconds;
  return a;
}

// Stage: preparation. A view's dominant plane: which normals lie on it, and the weight
// that makes it weigh as much as the rest (the EGIs and the translation grids then see
// the structure that fixes the rotation about the plane's normal and the translation
// along it).
struct PlaneBalance {
  std::vector<char> on_plane;  // per point: its normal is within kPlaneCone of the plane's
  double plane_weight = 1.0;   // of each point on the plane; 1: no dominant plane
  bool has_plane() const { return plane_weight < 1.0; }
};

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

// Stage: verification. The reference at a pose against the current view's depth image.
class SupportCheck {
 public:
  /// `current`: the verification of the current view as prepared (its depth image),
  /// `reference`: what of the reference is checked.
  SupportCheck(const detail::Verifier& current, const PointCloud& reference) : current_(current) {
    const Eigen::Index count = reference.points().rows();
    const Eigen::Index stride = std::max<Eigen::Index>(1, count / kSupportPoints);
    std::vector<Eigen::Index> rows;
    for (Eigen::Index i = 0; i < count; i += stride) rows.push_back(i);
    points_ = detail::rows_of(reference.points(), rows);
    normals_ = detail::rows_of(reference.normals(), rows);
  }

  /// The support with depths within `tolerance` voxels.
  ViewSupport of(const Transform& T_current_reference, double tolerance) {
    const Eigen::Matrix3d R = T_current_reference.topLeftCorner<3, 3>();
    moved_.noalias() = points_ * R.transpose();
    moved_.rowwise() += T_current_reference.topRightCorner<3, 1>().transpose();
    turned_.noalias() = normals_ * R.transpose();
    const detail::ViewCheck check =
        current_.check(moved_, turned_, tolerance * current_.voxel_size(),
                       detail::RangeImage::Distance::along_normal);
    ViewSupport support;
    support.confirmed = check.confirmed;
    support.contradicted = check.contradicted;
    support.hidden = check.hidden;
    support.reference_pixels = check.confirmed + check.contradicted + check.hidden;
    support.fitness = check.fitness();
    support.overlap = double(check.supported_points) / double(points_.rows());
    support.score = support.fitness * support.overlap;
    return support;
  }

 private:
  const detail::Verifier& current_;
  Points points_, normals_, moved_, turned_;
};

struct Hypothesis {
  int index = 0;
  Pose pose;
  ViewSupport support;
};

// What the stages share: the prepared views and their EGI correlation.
struct Views {
  const PointCloud& reference;
  const PointCloud& current;
  const ViewAlignParams& params;
  const AlignParams& loop;  // Algorithm 1's settings at the views' scale
  const ViewScale& scale;
  detail::MovingModel& model;     // the reference, moved about its centroid
  const PointCloud& model_cloud;  // what it moves: the reference balanced
  const detail::SceneMap& map;    // the current view, for the translation grids
  const ShCoefficients& reference_coefficients;
  const ShCoefficients& current_coefficients;
  So3Correlation& correlation;
  const detail::Verifier& verifier;  // of poses against the current view
  SupportCheck& support;
  const detail::IcpScene& coarse_scene;  // the current view at a voxel, cells of a search voxel
  const detail::IcpScene& fine_scene;    // the current view, cells of a voxel
  Clock::time_point deadline;
};

bool expired(const Views& views) { return Clock::now() > views.deadline; }

// Best supported first; of equal scores, in their order.
void sort_by_support(std::vector<Hypothesis>& hypotheses) {
  std::stable_sort(
      hypotheses.begin(), hypotheses.end(),
      [](const Hypothesis& a, const Hypothesis& b) { return a.support.score > b.support.score; });
}

// A hypothesis' pose through the short ICP of the placement and its support at the coarse
// tolerance: what every checked hypothesis goes through.
void check_hypothesis(const Views& views, Hypothesis& hypothesis) {
  detail::IcpSettings coarse_icp;
  coarse_icp.max_distance = views.scale.search_voxel_size;
  coarse_icp.max_points = kCoarseIcpPoints;
  coarse_icp.max_iterations = kCoarseIcpIterations;
  coarse_icp.viewpoint = views.params.sensor_origin;
  // The EGI's maximum of two partial views lies up to 10-20 degrees from the truth: a
  // short ICP with pairs within a search voxel brings a right hypothesis close enough
  // for the support to recognise it.
  const detail::IcpOutcome icp = detail::refine_point_to_plane(
      views.model_cloud, views.coarse_scene, views.model.transform_of(hypothesis.pose), coarse_icp);
  if (icp.iterations > 0) hypothesis.pose = views.model.pose_of(icp.T_scene_model);
  hypothesis.support =
      views.support.of(views.model.transform_of(hypothesis.pose), kCoarseTolerance);
}

// The best rotations of one window's EGI against the reference's, each placed on a small
// grid around the window (the reference's centroid started on the window's) and checked.
void add_window_hypotheses(const Views& views, const PointCloud& window, double side,
                           int first_index, std::vector<Hypothesis>& out) {
  const ShCoefficients coefficients =
      egi_coefficients(window, views.params.bandwidth, views.params.egi_method);
  So3Correlation correlation(coefficients, views.reference_coefficients, views.params.bandwidth,
                             true);
  So3SearchParams search;
  search.candidates = kWindowRotations;
  search.threads = views.params.threads;
  RotationRefineParams refine;
  refine.max_iterations = kRotationRefineIterations;
  for (const auto& candidate :
       so3_search(coefficients, views.reference_coefficients, views.params.bandwidth, search)) {
    Hypothesis hypothesis;
    hypothesis.index = first_index + int(out.size());
    hypothesis.pose.R = refine_rotation(correlation, candidate.R, refine).R;
    hypothesis.pose.offset = window.centroid() - views.model.centroid();
    const Points& at_start = views.model.move(hypothesis.pose);
    const Eigen::AlignedBox3d start_box(at_start.colwise().minCoeff().transpose(),
                                        at_start.colwise().maxCoeff().transpose());
    SceneTranslation placement(views.map, start_box, kWindowRoom * side,
                               views.scale.search_voxel_size, views.params.occupancy,
                               detail::phase_params(views.loop), views.params.limits);
    hypothesis.pose.offset += placement.estimate(at_start).shift;
    check_hypothesis(views, hypothesis);
    out.push_back(hypothesis);
  }
}

// The current view's points binned once in cubic cells of a stride, so that finding a
// window's points costs about its points, not the view's (a current view 30 times the
// reference's size has 64^3 window centres).
class StrideCells {
 public:
  StrideCells(const Points& points, const Eigen::AlignedBox3d& around, double stride)
      : points_(points), origin_(around.min()), stride_(stride) {
    steps_ = ((around.sizes().array() / stride).floor().cast<int>() + 1).min(64);
    cells_.resize(std::size_t(steps_.prod()));
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      cells_[index(cell_of(points.row(i).transpose()))].push_back(i);
    }
  }

  const Eigen::Array3i& steps() const { return steps_; }
  Eigen::Vector3d node(const Eigen::Array3i& n) const {
    return origin_ + stride_ * n.cast<double>().matrix();
  }

  // The rows inside `cube` (at most a stride from `n` on each axis), in the view's order.
  void rows_in(const Eigen::AlignedBox3d& cube, const Eigen::Array3i& n,
               std::vector<Eigen::Index>& rows) const {
    rows.clear();
    // The cube spans cells n - 1 and n on each axis; one more each way for rounding.
    const Eigen::Array3i low = (n - 2).max(0), high = (n + 1).min(steps_ - 1);
    for (int x = low.x(); x <= high.x(); ++x) {
      for (int y = low.y(); y <= high.y(); ++y) {
        for (int z = low.z(); z <= high.z(); ++z) {
          for (const Eigen::Index row : cells_[index({x, y, z})]) {
            if (cube.contains(points_.row(row).transpose())) rows.push_back(row);
          }
        }
      }
    }
    std::sort(rows.begin(), rows.end());
  }

 private:
  Eigen::Array3i cell_of(const Eigen::Vector3d& p) const {
    return ((p - origin_).array() / stride_).floor().cast<int>().max(0).min(steps_ - 1);
  }
  std::size_t index(const Eigen::Array3i& c) const {
    return (std::size_t(c.x()) * std::size_t(steps_.y()) + std::size_t(c.y())) *
               std::size_t(steps_.z()) +
           std::size_t(c.z());
  }

  const Points& points_;
  Eigen::Vector3d origin_;
  double stride_;
  Eigen::Array3i steps_;
  std::vector<std::vector<Eigen::Index>> cells_;
};

// Stage: window search. When the search's kept pose finds no support, the rotation is most
// often what it missed: the current view's EGI is the sum of the reference's part and of
// surfaces the reference never saw, and where that part is small the correlation's best
// rotations belong to the rest. Each window of the current view as large as the reference
// that holds enough of it has an EGI of its own; `windows` counts them.
std::vector<Hypothesis> window_hypotheses(const Views& views, int first_index, int& windows) {
  std::vector<Hypothesis> out;
  const PointCloud& current = views.map.cloud();
  const double side = detail::typical_size(views.model_cloud.points());
  if (!(side > 0.0)) return out;
  const StrideCells cells(current.points(), bounding_box(current), kWindowStride * side);
  const auto min_points = Eigen::Index(std::ceil(kWindowMinShare * double(current.size())));
  std::vector<Eigen::Index> inside;
  const Eigen::Array3i& steps = cells.steps();
  for (int i = 0; i < steps.x(); ++i) {
    for (int j = 0; j < steps.y(); ++j) {
      for (int k = 0; k < steps.z(); ++k) {
        if (expired(views)) return out;
        const Eigen::Vector3d centre = cells.node({i, j, k});
        const Eigen::AlignedBox3d cube(centre.array() - 0.5 * side, centre.array() + 0.5 * side);
        cells.rows_in(cube, {i, j, k}, inside);
        if (Eigen::Index(inside.size()) < min_points) continue;
        ++windows;
        add_window_hypotheses(views, subset(current, inside), side, first_index, out);
      }
    }
  }
  return out;
}

// Stage: hypotheses. The best rotations of the SO(3) search of the two EGIs, each refined
// on the correlation, then placed by phase correlation over both views (the reference's
// centroid started on the current's), and checked; best supported first.
std::vector<Hypothesis> hypotheses(const Views& views) {
  So3SearchParams search;
  search.candidates = views.params.hypotheses;
  search.threads = views.params.threads;
  const auto candidates = so3_search(views.current_coefficients, views.reference_coefficients,
                                     views.params.bandwidth, search);
  const Eigen::Vector3d start = views.map.cloud().centroid();
  // The reference's centroid started on the current's: the grid holds both views and
  // room for the shift of two views' centroids (which a rotation of the camera moves).
  Pose centred;
  centred.offset = start - views.model.centroid();
  const Points& at_start = views.model.move(centred);
  const Eigen::AlignedBox3d start_box(at_start.colwise().minCoeff().transpose(),
                                      at_start.colwise().maxCoeff().transpose());
  SceneTranslation placement(views.map, start_box, kPlacementRoom * views.scale.extent,
                             views.scale.search_voxel_size, views.params.occupancy,
                             detail::phase_params(views.loop), views.params.limits);
  RotationRefineParams refine;
  refine.max_iterations = kRotationRefineIterations;
  std::vector<Hypothesis> out;
  for (std::size_t h = 0; h < candidates.size(); ++h) {
    if (h > 0 && expired(views)) break;
    Hypothesis hypothesis;
    hypothesis.index = int(h);
    hypothesis.pose.R = refine_rotation(views.correlation, candidates[h].R, refine).R;
    hypothesis.pose.offset = centred.offset;
    hypothesis.pose.offset += placement.estimate(views.model.move(hypothesis.pose)).shift;
    check_hypothesis(views, hypothesis);
    out.push_back(hypothesis);
  }
  sort_by_support(out);
  return out;
}

// The point-to-plane ICP of a refined pose: pairs within a voxel, then within
// kIcpFineDistance of one; kept where it does not lower the support.
void refine_with_icp(const Views& views, ViewAlignResult& result) {
  detail::IcpSettings icp;
  icp.viewpoint = views.params.sensor_origin;
  const detail::IcpOutcome outcome = detail::refine_in_two_stages(
      views.reference, views.fine_scene, result.T_current_reference, views.scale.voxel_size, icp);
  const Transform& T = outcome.T_scene_model;
  const int iterations = outcome.iterations;
  if (iterations == 0) return;
  const ViewSupport icp_support = views.support.of(T, kCoarseTolerance);
  if (icp_support.score >= result.support.score - kIcpScoreLoss) {
    result.T_current_reference = T;
    result.support = icp_support;
    result.icp_iterations = iterations;
  }
}

// Stage: refinement. Algorithm 1 from a hypothesis on a grid bounded around it, then
// the point-to-plane ICP; each kept only where it does not lower the support.
ViewAlignResult refine(const Views& views, const Hypothesis& hypothesis) {
  ViewAlignResult result;
  result.hypothesis = hypothesis.index;
  result.T_current_reference = views.model.transform_of(hypothesis.pose);
  result.support = hypothesis.support;
  Pose pose = hypothesis.pose;
  const Points& at_start = views.model.move(pose);
  const Eigen::AlignedBox3d box(at_start.colwise().minCoeff().transpose(),
                                at_start.colwise().maxCoeff().transpose());
  // A hypothesis that moved the reference off the current view has nothing to refine on
  // (and its grid, spanning both, could be of any size).
  if (!box.intersects(bounding_box(views.map.cloud()))) return result;
  SceneTranslation grid(views.map, box, kRefinementRoom * views.scale.search_voxel_size,
                        views.scale.voxel_size, views.params.occupancy,
                        detail::phase_params(views.loop), views.params.limits);
  const detail::Algorithm1Problem loop{views.correlation,
                                       views.current_coefficients,
                                       views.reference_coefficients,
                                       views.model,
                                       views.loop,
                                       views.deadline,
                                       false};  // its history is not read
  detail::run_algorithm1(loop, pose, grid, views.params.refinement_iterations);
  const Transform refined = views.model.transform_of(pose);
  const ViewSupport refined_support = views.support.of(refined, kCoarseTolerance);
  if (refined_support.score >= result.support.score) {
    result.T_current_reference = refined;
    result.support = refined_support;
  }
  if (views.params.icp_refinement) refine_with_icp(views, result);
  result.support = views.support.of(result.T_current_reference, kFineTolerance);
  return result;
}

// Refines the first `count` of `ranked` (fewer if there are fewer), each kept in `kept`
// when there is none yet or it is better supported; false once the time ran out.
bool refine_into(const Views& views, const std::vector<Hypothesis>& ranked, int count,
                 std::optional<ViewAlignResult>& kept) {
  for (std::size_t i = 0; i < std::min(std::size_t(count), ranked.size()); ++i) {
    ViewAlignResult result = refine(views, ranked[i]);
    if (!kept || result.support.score > kept->support.score) kept = std::move(result);
    if (expired(views)) return false;
  }
  return true;
}

// Stage: the verdict. The reference (at most kVerdictPoints of it) verified against the
// current view from its sensor; the alternatives are the best-supported other hypotheses,
// refined by the ICP and scored alike.
class ViewVerdict {
 public:
  explicit ViewVerdict(const Views& views)
      : views_(views),
        sample_(every_nth(views.reference)),
        verifier_(views.verifier),
        centroid_(sample_.centroid()) {}

  // The score of a pose (ViewAlignResult::score) and its verification.
  // Two checks multiplied: the reference's points against the current view (confirmed /
  // sqrt(visible x checked)), and its structure against the current's depth image (the
  // support's fitness at a quarter voxel). The first tells a pose that lays the
  // reference where the current saw surfaces; the second, one that only lays a plane
  // (a table, a floor) on a plane. On the calibration set the product ranked right and
  // wrong answers better (ROC AUC 0.997) than either alone (0.92, 0.98).
  double score(const Transform& T, double support_fitness,
               PoseVerification* verification = nullptr) const {
    const PoseVerification v = verifier_.verify(sample_, T);
    if (verification) *verification = v;
    if (v.visible == 0) return 0.0;
    return double(v.tight) / std::sqrt(double(v.visible) * double(sample_.points().rows())) *
           support_fitness;
  }

  void judge(ViewAlignResult& result, const std::vector<Hypothesis>& checked,
             bool timed_out) const {
    PoseVerification v;
    result.score = score(result.T_current_reference, result.support.fitness, &v);
    result.confidence = calibrated_confidence(result.score, RegistrationKind::view_to_view);
    result.inliers = v.inliers;
    result.inlier_fraction = v.inlier_fraction;
    result.inlier_rmse = v.inlier_rmse;
    result.inlier_distance = v.inlier_distance;
    result.covariance =
        detail::covariance_at(sample_, verifier_.fine_grid(), result.T_current_reference,
                              v.inlier_distance, detail::typical_size(views_.current.points()),
                              covariance_inflation(RegistrationKind::view_to_view));
    if (!timed_out) add_alternatives(result, checked);
    result.ambiguous = detail::mark_symmetric(
        result.alternatives, sample_, views_.scale.voxel_size, result.T_current_reference,
        [](const ViewAlternative& a) { return a.T_current_reference; });
    VerdictInputs inputs;
    inputs.confidence = result.confidence;
    inputs.ambiguous = result.ambiguous;
    inputs.supported = result.support.confirmed > 0 && v.tight > 0;
    inputs.timed_out = timed_out;
    inputs.scale_ok =
        voxel_in_range(views_.scale.voxel_size, detail::typical_size(views_.reference.points()));
    const detail::Conclusion c =
        detail::conclude(inputs, result.covariance,
                         result.T_current_reference.topLeftCorner<3, 3>() * centroid_ +
                             result.T_current_reference.topRightCorner<3, 1>());
    result.determined = c.determined;
    result.status = c.status;
    result.reliable = c.reliable;
    result.confidence = c.confidence;
  }

 private:
  // At most kVerdictPoints of the cloud, at a fixed stride.
  static PointCloud every_nth(const PointCloud& cloud) {
    const Eigen::Index count = cloud.points().rows();
    const Eigen::Index stride =
        std::max<Eigen::Index>(1, (count + kVerdictPoints - 1) / kVerdictPoints);
    std::vector<Eigen::Index> rows;
    for (Eigen::Index i = 0; i < count; i += stride) rows.push_back(i);
    return PointCloud(detail::rows_of(cloud.points(), rows),
                      detail::rows_of(cloud.normals(), rows));
  }

  // Whether T is apart from `other`: rotation over kApartRadians, or the reference's
  // centroid moved over a voxel.
  bool apart(const Transform& T, const Transform& other) const {
    const Eigen::Matrix3d R = T.topLeftCorner<3, 3>(), S = other.topLeftCorner<3, 3>();
    const Eigen::Vector3d a = R * centroid_ + T.topRightCorner<3, 1>();
    const Eigen::Vector3d b = S * centroid_ + other.topRightCorner<3, 1>();
    return rotation_distance(R, S) > kApartRadians || (a - b).norm() > views_.scale.voxel_size;
  }

  void add_alternatives(ViewAlignResult& result, const std::vector<Hypothesis>& checked) const {
    if (checked.empty()) return;
    const double floor = kAlternativeSupportShare * checked.front().support.score;
    int tried = 0;
    for (const Hypothesis& h : checked) {
      if (tried == kAlternativeCandidates || h.support.score < floor) break;
      const Transform start = views_.model.transform_of(h.pose);
      if (!apart(start, result.T_current_reference)) continue;
      ++tried;
      detail::IcpSettings icp;
      icp.viewpoint = views_.params.sensor_origin;
      const Transform T = detail::refine_in_two_stages(views_.reference, views_.fine_scene, start,
                                                       views_.scale.voxel_size, icp)
                              .T_scene_model;
      if (!apart(T, result.T_current_reference)) continue;
      const double s = score(T, views_.support.of(T, kFineTolerance).fitness);
      if (s < result.score - kViewAlternativeMargin) continue;
      const bool repeated =
          std::any_of(result.alternatives.begin(), result.alternatives.end(),
                      [&](const ViewAlternative& a) { return !apart(T, a.T_current_reference); });
      if (repeated) continue;
      ViewAlternative alternative;
      alternative.T_current_reference = T;
      alternative.score = s;
      alternative.confidence = calibrated_confidence(s, RegistrationKind::view_to_view);
      const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
      const Eigen::Matrix3d S = result.T_current_reference.topLeftCorner<3, 3>();
      alternative.rotation_apart = rotation_distance(R, S);
      alternative.translation_apart = ((R - S) * centroid_ + T.topRightCorner<3, 1>() -
                                       result.T_current_reference.topRightCorner<3, 1>())
                                          .norm();
      result.alternatives.push_back(alternative);
    }
    std::stable_sort(
        result.alternatives.begin(), result.alternatives.end(),
        [](const ViewAlternative& a, const ViewAlternative& b) { return a.score > b.score; });
    if (result.alternatives.size() > kMaxViewAlternatives)
      result.alternatives.resize(kMaxViewAlternatives);
  }

  const Views& views_;
  PointCloud sample_;
  const detail::Verifier& verifier_;
  Eigen::Vector3d centroid_;
};

PointCloud prepared(const PointCloud& view, const ViewAlignParams& params, double voxel_size) {
  return params.downsample ? voxel_downsample(view, 0.5 * voxel_size) : view;
}

// The scale of view_scale, or the settings' where given.
ViewScale scale_of(const PointCloud& reference, const PointCloud& current,
                   const ViewAlignParams& params) {
  ViewScale scale = view_scale(reference, current, params.voxels_across);
  if (params.voxel_size > 0.0) {
    scale.voxel_size = params.voxel_size;
    scale.search_voxel_size = 2.0 * params.voxel_size;
  }
  if (params.search_voxel_size > 0.0) scale.search_voxel_size = params.search_voxel_size;
  return scale;
}

void check_views(const PointCloud& reference, const PointCloud& current,
                 const ViewAlignParams& params) {
  require_non_empty(reference, "reference");
  require_non_empty(current, "current");
  require_normals(reference, "reference");
  require_normals(current, "current");
  check_params(params);
}

}  // namespace

ViewSupport view_support(const PointCloud& reference_view, const PointCloud& current_view,
                         const Transform& T_current_reference, const ViewAlignParams& params) {
  check_views(reference_view, current_view, params);
  require_rigid_transform(T_current_reference, "T_current_reference");
  const ViewScale scale = scale_of(reference_view, current_view, params);
  const PointCloud current = prepared(current_view, params, scale.voxel_size);
  const PointCloud reference = prepared(reference_view, params, scale.voxel_size);
  const detail::Verifier verifier(current, scale.voxel_size, params.sensor_origin);
  SupportCheck support(verifier, structure(reference, plane_balance(reference.normals())));
  return support.of(T_current_reference, kFineTolerance);
}

ViewAlignResult align_views(const PointCloud& reference_view, const PointCloud& current_view,
                            const ViewAlignParams& params, const std::optional<Transform>& prior) {
  check_views(reference_view, current_view, params);
  if (prior) require_rigid_transform(*prior, "prior");
  const Clock::time_point started = Clock::now();
  const ViewScale scale = scale_of(reference_view, current_view, params);
  const AlignParams loop = loop_params(params, scale);

  // Stage: preparation.
  const PointCloud reference = prepared(reference_view, params, scale.voxel_size);
  const PointCloud current = prepared(current_view, params, scale.voxel_size);
  const PlaneBalance reference_balance = plane_balance(reference.normals());
  const PointCloud reference_balanced = cropped(balanced(reference, reference_balance));
  const PointCloud current_balanced = cropped(balanced(current, plane_balance(current.normals())));
  detail::MovingModel model(reference_balanced);
  const detail::SceneMap map(current_balanced);
  const ShCoefficients reference_coefficients =
      egi_coefficients(reference_balanced, params.bandwidth, params.egi_method);
  const ShCoefficients current_coefficients =
      egi_coefficients(current_balanced, params.bandwidth, params.egi_method);
  So3Correlation correlation(current_coefficients, reference_coefficients, params.bandwidth, true);
  const detail::Verifier verifier(current, scale.voxel_size, params.sensor_origin);
  SupportCheck support(verifier, structure(reference, reference_balance));
  // The ICP's neighbour grids, made once: cells as wide as the pairs' distance (wider
  // cells hold more points to try per query), the hypotheses' on the view at a voxel.
  Eigen::AlignedBox3d around = bounding_box(current);
  around.min().array() -= 2.0 * scale.search_voxel_size;
  around.max().array() += 2.0 * scale.search_voxel_size;
  const PointCloud current_coarse = voxel_downsample(current, scale.voxel_size);
  const detail::IcpScene coarse_scene(current_coarse, around, scale.search_voxel_size);
  const detail::IcpScene fine_scene(current, around, scale.voxel_size);
  const Views views{reference,
                    current,
                    params,
                    loop,
                    scale,
                    model,
                    reference_balanced,
                    map,
                    reference_coefficients,
                    current_coefficients,
                    correlation,
                    verifier,
                    support,
                    coarse_scene,
                    fine_scene,
                    detail::deadline_of(loop, started)};

  const std::vector<Hypothesis> ranked = hypotheses(views);
  std::optional<ViewAlignResult> kept;
  bool in_time = true;
  if (prior) {
    // The prior first: a searched pose must be better supported to replace it.
    Hypothesis given;
    given.index = -1;
    given.pose = model.pose_of(*prior);
    given.support = support.of(*prior, kCoarseTolerance);
    kept = refine(views, given);
    in_time = !expired(views);
  }
  if (in_time) in_time = refine_into(views, ranked, params.refinements, kept);
  std::vector<Hypothesis> checked = ranked;
  int windows_checked = 0;
  if (in_time && kept && kept->support.score < params.window_search_below) {
    std::vector<Hypothesis> windows = window_hypotheses(views, int(ranked.size()), windows_checked);
    sort_by_support(windows);
    in_time = !expired(views) && refine_into(views, windows, kWindowRefinements, kept);
    checked.insert(checked.end(), windows.begin(), windows.end());
    sort_by_support(checked);
  }
  ViewAlignResult best = kept ? std::move(*kept) : ViewAlignResult();
  // Timed out only when the deadline was hit: a search may find fewer rotations than it
  // asked for (a view of few distinct normals).
  best.converged = in_time;
  best.scale = scale;
  best.windows = windows_checked;
  best.correlation =
      correlation.evaluate(Eigen::Matrix3d(best.T_current_reference.topLeftCorner<3, 3>())).value;
  for (const Hypothesis& h : checked) {
    best.hypotheses.emplace_back(model.transform_of(h.pose), h.support);
  }
  ViewVerdict(views).judge(best, checked, !in_time);
  return best;
}

}  // namespace spectral_vs
