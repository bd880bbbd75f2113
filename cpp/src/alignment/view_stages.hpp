#pragma once
// Internal to align_views(): what its stages pass between them (docs/views.md). The
// stages, in the order align_views() runs them:
//   view_preparation  each view's dominant plane balanced, the crop, the structure;
//   view_hypotheses   the SO(3) search of the two EGIs, each rotation placed by phase
//                     correlation and checked; the window search after a missed one;
//   refinement        align()'s (refinement.hpp), configured in view_aligner.cpp: Algorithm
//                     1 on a grid bounded around a hypothesis, then the ICP;
//   view_verification the returned pose's score and its alternatives, then the verdict
//                     of both modes (judge_pose, verdict_detail.hpp).

#include <spectral_vs/alignment/view_aligner.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/hypothesis.hpp"
#include "alignment/icp_refinement.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/range_image.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verifier.hpp"

#include <algorithm>
#include <chrono>
#include <optional>
#include <vector>

namespace spectral_vs::detail::views {

using Clock = std::chrono::steady_clock;

// Reference points the support is checked on, at most: a hashed selection beyond it (the
// support of a pose is a share, which 4000 points measure to about 1%).
constexpr Eigen::Index kSupportPoints = 4000;
// Depth tolerances of the support check, in voxels: a hypothesis is a search voxel and a
// few degrees off, a refined pose (after the ICP) a small part of a voxel; checked that
// closely, a pose turned about a scene's dominant plane no longer passes for the right one.
constexpr double kCoarseTolerance = 1.0;
// ... and of a refined pose, after the ICP.
constexpr double kFineTolerance = 0.25;

// Stage: preparation. A view's dominant plane: which normals lie on it, and the weight
// that makes it weigh as much as the rest (the EGIs and the translation grids then see
// the structure that fixes the rotation about the plane's normal and the translation
// along it).
struct PlaneBalance {
  std::vector<char> on_plane;  // per point: its normal is within kPlaneCone of the plane's
  double plane_weight = 1.0;   // of each point on the plane; 1: no dominant plane
  bool has_plane() const { return plane_weight < 1.0; }
};

PlaneBalance plane_balance(const Points& normals);
/// The rows `kept` of a view, points and normals.
PointCloud subset(const PointCloud& view, const std::vector<Eigen::Index>& kept);
/// The view with its dominant plane thinned to the weight of one more direction.
PointCloud balanced(const PointCloud& view, const PlaneBalance& balance);
/// The view without its spatial outliers (for the translation grids).
PointCloud cropped(const PointCloud& view);
/// The view's points off its dominant plane (all of it without one).
PointCloud structure(const PointCloud& view, const PlaneBalance& balance);
/// The view as the stages take it: prepare_cloud's, downsampled to half a voxel unless told
/// not to.
PointCloud prepared(const PointCloud& view, const ViewAlignParams& params, double voxel_size);

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

using detail::Hypothesis;  // fitness: its support's score
using detail::rank;

// What the stages share: the prepared views and their EGI correlation.
struct Views {
  const PointCloud& reference;
  const PointCloud& current;
  const ViewAlignParams& params;
  const LocalParams& local;             // Algorithm 1's settings: align()'s defaults
  const PhaseCorrelationParams& phase;  // the translation grids': threads, limits
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

inline bool expired(const Views& views) { return Clock::now() > views.deadline; }

// Stage: preparation, whole (view_preparation.cpp): the two views as every later stage
// reads them, made once per call; views() refers to its members.
class PreparedViews {
 public:
  PreparedViews(const PointCloud& reference_view, const PointCloud& current_view,
                const ViewAlignParams& params, const ViewScale& scale, Clock::time_point started);
  PreparedViews(const PreparedViews&) = delete;
  PreparedViews& operator=(const PreparedViews&) = delete;

  Views views();

 private:
  const ViewAlignParams& params_;
  const ViewScale scale_;
  const LocalParams local_{};
  const PhaseCorrelationParams phase_;
  const PointCloud reference_, current_;
  const PlaneBalance reference_balance_;
  const PointCloud reference_balanced_, current_balanced_;
  detail::MovingModel model_;
  const detail::SceneMap map_;
  const ShCoefficients reference_coefficients_, current_coefficients_;
  So3Correlation correlation_;
  const detail::Verifier verifier_;
  SupportCheck support_;
  // The ICP's neighbour grids, made once: cells as wide as the pairs' distance (wider
  // cells hold more points to try per query), the hypotheses' on the view at a voxel.
  const Eigen::AlignedBox3d around_;
  const PointCloud current_coarse_;
  const detail::IcpScene coarse_scene_, fine_scene_;
  const Clock::time_point deadline_;
};

// Stage: hypotheses (view_hypotheses.cpp): the search's, best supported first.
std::vector<Hypothesis> hypotheses(const Views& views);
// The window search after a missed search; `windows` counts the windows searched.
std::vector<Hypothesis> window_hypotheses(const Views& views, int first_index, int& windows);

// Stage: refinement (view_aligner.cpp, the one of refinement.hpp): one hypothesis refined.
ViewAlignResult refine(const Views& views, const Hypothesis& hypothesis);
// Refines the first `count` of `ranked` (fewer if there are fewer), each kept in `kept`
// when there is none yet or it is better supported; false once the time ran out.
bool refine_into(const Views& views, const std::vector<Hypothesis>& ranked, int count,
                 std::optional<ViewAlignResult>& kept);

// Stage: verification and verdict (view_verification.cpp): `result`'s score and
// verification, its alternatives among `checked` (none when `timed_out`), then the one
// verdict of both modes (covariance, symmetric alternatives, status).
void judge(const Views& views, ViewAlignResult& result, const std::vector<Hypothesis>& checked,
           bool timed_out);

}  // namespace spectral_vs::detail::views
