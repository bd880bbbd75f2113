// Stage of align_views(): hypotheses. The SO(3) search of the two views' EGIs, each
// rotation placed by phase correlation and checked against the current view; after a
// missed search, the same in windows of the current view.

#include <spectral_vs/rotation/so3_search.hpp>

#include "alignment/align_detail.hpp"
#include "alignment/scale.hpp"
#include "alignment/view_stages.hpp"

#include <cmath>

namespace spectral_vs::detail::views {

namespace {

// Iterations of the EGI refinement of each rotation of the SO(3) search, before it is
// placed: the grid's nodes are pi / B apart (11 degrees at B = 16).
constexpr int kRotationRefineIterations = 20;
// Translation room of the hypotheses' placement, in view extents (ViewScale::extent).
constexpr double kPlacementRoom = 1.0;
// The ICP of each hypothesis before it is checked: about this many reference points (the
// balanced view), this many Gauss-Newton steps at most.
constexpr Eigen::Index kCoarseIcpPoints = 500;
constexpr int kCoarseIcpIterations = 10;

// The window search (after a missed search): cubic windows of the current view as large
// as the reference's typical size, centres kWindowStride of a side apart, each holding at
// least kWindowMinShare of the current's points; kWindowRotations SO(3) candidates per
// window, each placed within kWindowRoom of a side of where it starts (the reference's
// centroid on the window's).
constexpr double kWindowStride = 0.5;
constexpr double kWindowMinShare = 0.02;
constexpr int kWindowRotations = 2;
constexpr double kWindowRoom = 0.5;

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
  hypothesis.fitness = hypothesis.support.score;
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
  // Each rotation's grid is around the model as it starts, turned: its own placement.
  const auto place = [&](const Points& at_start) {
    SceneTranslation placement(views.map, points_box(at_start), kWindowRoom * side,
                               views.scale.search_voxel_size, views.params.occupancy, views.phase,
                               views.params.limits);
    return placement.estimate(at_start).shift;
  };
  const int first = first_index + int(out.size());
  for (Hypothesis& hypothesis : placed_rotations(
           so3_search(coefficients, views.reference_coefficients, views.params.bandwidth, search),
           correlation, refine, views.model, window.centroid() - views.model.centroid(),
           views.deadline, place, [&](Hypothesis& h) { check_hypothesis(views, h); })) {
    hypothesis.index += first;
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

}  // namespace

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
  SceneTranslation placement(views.map, points_box(views.model.move(centred)),
                             kPlacementRoom * views.scale.extent, views.scale.search_voxel_size,
                             views.params.occupancy, views.phase, views.params.limits);
  RotationRefineParams refine;
  refine.max_iterations = kRotationRefineIterations;
  std::vector<Hypothesis> out = placed_rotations(
      candidates, views.correlation, refine, views.model, centred.offset, views.deadline,
      [&](const Points& at) { return placement.estimate(at).shift; },
      [&](Hypothesis& hypothesis) { check_hypothesis(views, hypothesis); });
  rank(out);
  return out;
}

}  // namespace spectral_vs::detail::views
