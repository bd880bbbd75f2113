#pragma once
// Internal to align(), its second stage (beyond the paper, which starts Algorithm 1 from
// the identity): the rotations of the SO(3) search on the EGI correlation, each placed
// by phase correlation and ranked by fitness; the model's flat axis and the turns about
// it; the initial guess as one more hypothesis.

#include <spectral_vs/rotation/so3_correlation.hpp>

#include "alignment/stages.hpp"

#include <optional>
#include <vector>

namespace spectral_vs::detail {

/// The voxel of the global search's grid over the whole scene, metres: the alignment's
/// `voxel_size` doubled, coarser on a large scene (search.search_voxel_size, or derived).
double search_voxel_size(const PointCloud& scene, double reach, const GlobalSearchParams& search,
                         double voxel_size);

/// The best `search.hypotheses` rotations of the SO(3) search on the whole scene's EGI,
/// refined on the EGI correlation by `local.rotation_step`'s law, placed on the scene at
/// `search_voxel`, fittest first.
std::vector<Hypothesis> global_hypotheses(const Problem& problem, const GlobalSearchParams& search,
                                          const LocalParams& local, So3Correlation& correlation,
                                          const ShCoefficients& scene_coefficients,
                                          double search_voxel);

/// `per_part` distinct rotations (refined on the EGI correlation, at least
/// kDistinctRotationDeg apart) of the SO(3) search on each part's own EGI, placed in a
/// window around the part, fittest first. With `screen` (clutter), the search's maxima
/// are first placed coarsely on a sparse model and tried fittest first.
std::vector<Hypothesis> part_hypotheses(const Problem& problem, const LocalParams& local,
                                        const std::vector<std::vector<Eigen::Index>>& parts,
                                        int per_part, bool screen, WindowCache& windows);

/// The model at rotation R with its side facing the sensor at `centroid` (its centroid
/// there, without a sensor): where a part's hypotheses start from.
Pose facing_at_part(const Problem& problem, MovingModel& model, const Eigen::Matrix3d& R,
                    const Eigen::Vector3d& centroid);

/// The best-ranked hypotheses turned to the fittest of their turns about the model's
/// flat axis (problem.flat_axis), when it has one.
void turn_about_flat_axis(const Problem& problem, std::vector<Hypothesis>& hypotheses,
                          double tolerance);

/// The axis of the model's EGI along which the EGI correlation cannot tell poses apart,
/// if it has one (model frame).
std::optional<Eigen::Vector3d> flat_axis(const ShCoefficients& model_coefficients, int bandwidth);

/// The initial guess as a hypothesis; with a neighbourhood (search.guess_angle_deg,
/// guess_distance), the ones outside it dropped.
void seed_with_guess(const Problem& problem, const GlobalSearchParams& search,
                     const Transform& initial_guess, std::vector<Hypothesis>& hypotheses,
                     double tolerance);

}  // namespace spectral_vs::detail
