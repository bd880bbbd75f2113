#pragma once
// Internal to the aligner: the optional last step, a point-to-plane ICP from the
// spectral result (AlignParams::refinement.icp_refinement).

#include <spectral_vs/representation/point_cloud.hpp>

#include "alignment/normal_directions.hpp"

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

namespace spectral_vs::detail {

/// Settings of `refine_point_to_plane`.
struct IcpSettings {
  double max_distance = 0.008;          ///< Pairs farther apart than this are not matched, metres.
  double min_cosine = kAgreeingCosine;  ///< Pairs whose normals disagree are not matched.
  int max_iterations = 30;              ///< Gauss-Newton steps at most.
  Eigen::Index max_points = 1500;       ///< About this many model points take part (a hashed
                                        ///< selection of one in rows / max_points), or all.
  std::optional<Eigen::Vector3d> viewpoint;  ///< Only the model points facing it take part.
};

/// Model points of the ICP after a step of Algorithm 1 without global search
/// (LocalParams::icp), about: from a tracking step already within a voxel, half of a servo
/// reference's 2.4 k points took 0.9 ms instead of 1.5 ms of a 320 x 240 step (iiwa, near
/// the goal). A kept ICP is checked by the fitness over all the model's points.
constexpr Eigen::Index kLocalIcpPoints = 1000;

/// The settings of the ICP after a step of Algorithm 1 without global search: about
/// kLocalIcpPoints model points, those facing `viewpoint` when the scene is a single view.
inline IcpSettings local_icp_settings(const std::optional<Eigen::Vector3d>& viewpoint) {
  IcpSettings settings;
  settings.viewpoint = viewpoint;
  settings.max_points = kLocalIcpPoints;
  return settings;
}

/// Outcome of `refine_point_to_plane`.
struct IcpOutcome {
  Transform T_scene_model = Transform::Identity();
  int iterations = 0;  ///< Gauss-Newton steps taken.
  int pairs = 0;       ///< Matched pairs at the last step.
};

/// The scene points inside a box, sorted into a dense grid of cells at least
/// `max_distance` wide (compressed rows: per cell, a range of point indices): a point's
/// nearest neighbour within that distance is in its own cell or one of the 26 around it.
/// Made once, it serves every ICP run on that scene with pairs within `max_distance`.
class IcpScene {
 public:
  IcpScene(const PointCloud& scene, const Eigen::AlignedBox3d& around, double max_distance);
  /// The nearest scene point within `max_distance` (at most the grid's) of p whose
  /// normal has a cosine of at least `min_cosine` with n; -1 if none.
  Eigen::Index nearest(const Eigen::Vector3d& p, const Eigen::Vector3d& n, double max_distance,
                       double min_cosine) const;
  const PointCloud& cloud() const { return scene_; }

 private:
  // Defined here so that the queries inline them.
  Eigen::Array3i cell_of(const Eigen::Vector3d& p) const {
    // Clamped into [-1, dims]: a point outside the box has no neighbours in it beyond.
    const Eigen::Array3d v = ((p - origin_) / cell_).array().floor();
    return v.max(-1.0).min(dims_.cast<double>()).cast<int>();
  }
  std::int64_t linear(const Eigen::Array3i& c) const {
    return (std::int64_t(c.x()) * dims_.y() + c.y()) * dims_.z() + c.z();
  }
  // The nearest point of a query so far (IcpScene::nearest searches the query's own
  // cell first, then the others in order).
  struct Nearest {
    double squared = 0.0;          // its squared distance; the largest allowed before one is found
    Eigen::Index row = -1;         // its row in the scene, -1: none yet
    bool in_own_cell = false;      // found in the query's own cell
    bool before_own_cell = false;  // searching a cell before the own one in that order
    bool beaten_by(double d) const {
      return d < squared || (before_own_cell && in_own_cell && d == squared);
    }
  };
  // Takes each point of `cell` nearer to p than `nearest` whose normal agrees.
  void closest_in(std::int64_t cell, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                  double min_cosine, bool own_cell, Nearest& nearest) const;

  const PointCloud& scene_;
  double cell_ = 0.0;
  Eigen::Vector3d origin_;
  Eigen::Array3i dims_;
  std::vector<std::size_t> start_;  // per cell, where its rows begin in rows_
  std::vector<Eigen::Index> rows_;
  // The points and normals at rows_, in that order: a query reads each cell's
  // contiguously rather than scattered over the scene.
  Points points_, normals_;
};

/// `refine_point_to_plane` on a scene prepared as an IcpScene (settings.max_distance at
/// most the distance it was made for).
IcpOutcome refine_point_to_plane(const PointCloud& model, const IcpScene& scene,
                                 const Transform& T_scene_model, const IcpSettings& settings);

/// Point-to-plane ICP from `T_scene_model`: each step pairs every model point with its
/// nearest scene point within settings.max_distance whose normal agrees, and takes the
/// Gauss-Newton step of the summed squared distances to the scene points' tangent planes
/// (rotation linearised about the pairs' centroid). Stops when a step moves less than
/// 1e-4 rad and 0.02 mm (a tenth of the accuracy it reaches: finer steps only follow pairs
/// switching back and forth), or with fewer than 6 pairs (the pose is then returned
/// unchanged).
IcpOutcome refine_point_to_plane(const PointCloud& model, const PointCloud& scene,
                                 const Transform& T_scene_model, const IcpSettings& settings);

// Pairs within a voxel first (the spectral result may be most of one off), then, for a
// densely sampled model, within this share of one, which leaves out pairs that only the
// noise brought near: on single views 0.34 to 0.22 degree and 0.29 to 0.13 mm at the
// median, against 0.25 and 0.6. On a sparse scan (one point per voxel) the nearest points
// are mostly farther than that, and the few pairs left turned the bunny scan 0.3 to 4
// degrees.
constexpr double kIcpFineDistance = 0.4;

// Both modes keep the ICP's pose unless its score (align's fitness, align_views' support
// score) falls more than this below the pose it started from: a slide off the object. At
// a voxel's tolerance a precise pose scores about as a rough one, so a small loss is no
// sign of a worse pose.
constexpr double kIcpScoreLoss = 0.05;

/// The one rule of both modes' ICP refinement: the ICP's pose, scored `icp_score`, replaces
/// one scored `start_score` (kIcpScoreLoss).
inline bool keeps_icp(double icp_score, double start_score) {
  return !(icp_score < start_score - kIcpScoreLoss);
}

/// The aligner's ICP: `refine_point_to_plane` with pairs within `voxel_size`, then, if
/// `fine`, from where it ended with pairs within kIcpFineDistance voxel; a stage that
/// takes no step ends it. `settings.max_distance` is set by the stage. The outcome's
/// iterations are both stages', its pairs the last stage's.
IcpOutcome refine_in_two_stages(const PointCloud& model, const IcpScene& scene,
                                const Transform& T_scene_model, double voxel_size,
                                IcpSettings settings, bool fine = true);
/// The same against a whole scene (an IcpScene around the model made per stage).
IcpOutcome refine_in_two_stages(const PointCloud& model, const PointCloud& scene,
                                const Transform& T_scene_model, double voxel_size,
                                IcpSettings settings, bool fine = true);

}  // namespace spectral_vs::detail
