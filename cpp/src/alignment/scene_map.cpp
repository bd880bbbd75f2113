#include "alignment/scene_map.hpp"

#include "alignment/point_sets.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <unordered_map>

namespace spectral_vs::detail {

namespace {

Eigen::AlignedBox3d cube(const Eigen::Vector3d& centre, double half_width) {
  return {centre - Eigen::Vector3d::Constant(half_width),
          centre + Eigen::Vector3d::Constant(half_width)};
}

void voxelize_subset(const PointCloud& cloud, const std::vector<Eigen::Index>& rows,
                     const GridSpec& spec, Occupancy occupancy, VoxelGrid& grid,
                     const GridLimits& limits) {
  voxelize_into(rows_of(cloud.points(), rows), spec, occupancy, grid, limits);
}

}  // namespace

// ceil(length / voxel_size) as an int, refused over the limit before the conversion,
// which is undefined beyond the range of int (a scene two million metres wide at 0.1 mm).
int voxels_along(double length, double voxel_size, const GridLimits& limits) {
  const double n = std::ceil(length / voxel_size);
  const double limit = std::min(double(limits.max_voxels), double(kMaxGridIndex) / 2);
  if (!(n <= limit)) {
    fail("voxel_size: ", length, " m is ", n, " voxels of ", voxel_size,
         " m along an axis, over the limit of ", limit, " voxels (max_voxels)");
  }
  return static_cast<int>(n);
}

GridSpec scene_map_spec(const PointCloud& evidence, double voxel_size, const GridLimits& limits) {
  const Eigen::AlignedBox3d box = bounding_box(evidence);
  GridSpec spec;
  spec.resolution = voxel_size;
  spec.origin = ((box.min() / voxel_size).array().floor() - 2.0).matrix() * voxel_size;
  for (int axis = 0; axis < 3; ++axis) {
    spec.dims[axis] = voxels_along(box.max()[axis] - spec.origin[axis], voxel_size, limits) + 3;
  }
  if (spec.voxel_count() > limits.max_voxels) {
    fail("voxel_size: the scene spans ", spec.dims.transpose(), " voxels at ", voxel_size,
         " m, which exceeds the limit of ", limits.max_voxels, " voxels (max_voxels)");
  }
  return spec;
}

std::vector<Eigen::Index> SceneMap::points_in(const Eigen::AlignedBox3d& box) const {
  std::vector<Eigen::Index> rows;
  const Points& p = scene_->points();
  for (Eigen::Index i = 0; i < p.rows(); ++i) {
    if (box.contains(p.row(i).transpose())) rows.push_back(i);
  }
  return rows;
}

namespace {

// Voxels of a window axis `length` metres long, with one voxel of room on each side so
// that a shift by the margin stays unaliased.
int window_voxels(double length, double voxel_size, const GridLimits& limits) {
  return fft_friendly_size(voxels_along(length, voxel_size, limits) + 3);
}

// The window's grid: per axis the cube's 2 half_width, or the scene's extent with the
// margin on each side where that is fewer voxels (`on_scene`).
GridSpec window_spec(double half_width, double margin, const Eigen::AlignedBox3d& scene_box,
                     double voxel_size, const GridLimits& limits, std::array<bool, 3>& on_scene) {
  GridSpec spec;
  spec.resolution = voxel_size;
  const int cube = window_voxels(2.0 * half_width, voxel_size, limits);
  for (int axis = 0; axis < 3; ++axis) {
    const int scene = window_voxels(scene_box.sizes()[axis] + 2.0 * margin, voxel_size, limits);
    on_scene[axis] = scene < cube;
    spec.dims[axis] = on_scene[axis] ? scene : cube;
  }
  if (spec.voxel_count() > limits.max_voxels) {
    fail("voxel_size: a window of ", spec.dims.transpose(), " voxels at ", voxel_size,
         " m exceeds the limit of ", limits.max_voxels, " voxels (max_voxels)");
  }
  return spec;
}

}  // namespace

TranslationWindow::TranslationWindow(const SceneMap& scene, double reach, double margin,
                                     const Eigen::Vector3d& centre, double voxel_size,
                                     Occupancy occupancy, const PhaseCorrelationParams& params,
                                     const GridLimits& limits)
    : scene_(&scene),
      occupancy_(occupancy),
      limits_(limits),
      half_width_(reach + margin),
      margin_(margin),
      max_shift_(Eigen::Vector3i::Constant(voxels_along(margin, voxel_size, limits))),
      scene_box_(bounding_box(scene.cloud())),
      spec_(window_spec(half_width_, margin, scene_box_, voxel_size, limits, on_scene_)),
      phase_(spec_, params) {
  place(centre);
}

void TranslationWindow::place(const Eigen::Vector3d& centre) {
  centre_ = centre;
  const double r = spec_.resolution;
  // Snapped to the voxel lattice: windows placed anywhere share voxel boundaries. On an
  // axis narrower in the scene, the window holds the scene's extent and the margin.
  for (int axis = 0; axis < 3; ++axis) {
    const double low =
        on_scene_[axis] ? scene_box_.min()[axis] - margin_ : centre[axis] - half_width_;
    spec_.origin[axis] = (std::floor(low / r) - 1.0) * r;
  }
  const std::vector<Eigen::Index> rows = scene_->points_in(cube(centre, half_width_));
  voxelize_subset(scene_->cloud(), rows, spec_, occupancy_, target_, limits_);
  target_energy_ = grid_energy(target_);
  if (!target_.empty()) phase_.set_target(target_);
}

void TranslationWindow::follow(const Eigen::Vector3d& centre) {
  if ((centre - centre_).cwiseAbs().maxCoeff() > 0.5 * margin_) place(centre);
}

TranslationEstimate TranslationWindow::estimate(const Points& moved) {
  voxelize_into(moved, spec_, occupancy_, moving_, limits_);
  // No scene in the window, or the model outside it: no translation evidence.
  if (target_.empty() || moving_.empty()) return {};
  return phase_.estimate(moving_, max_shift_);
}

double TranslationWindow::translation_cost() const {
  return spectral_vs::translation_cost(moving_, target_, Eigen::Vector3i::Zero(), target_energy_);
}

double TranslationWindow::overlap(const Points& moved) {
  voxelize_into(moved, spec_, occupancy_, moving_, limits_);
  if (target_.empty() || moving_.empty()) return 0.0;
  double cross = 0.0, energy = 0.0;
  const Eigen::Vector3i& lo = moving_.occupied_min;
  const Eigen::Vector3i& hi = moving_.occupied_max;
  for (int i = lo.x(); i <= hi.x(); ++i)
    for (int j = lo.y(); j <= hi.y(); ++j)
      for (int k = lo.z(); k <= hi.z(); ++k) {
        const double m = moving_.at(i, j, k);
        energy += m * m;
        cross += m * target_.at(i, j, k);
      }
  // Points outside a window that holds only the scene's extent on some axis meet no scene
  // at any shift; they still count, at the energy per point of those inside.
  const double inside = double(moved.rows()) - double(moving_.points_outside);
  if (inside > 0.0) energy *= double(moved.rows()) / inside;
  return energy > 0.0 ? cross / std::sqrt(energy * target_energy_) : 0.0;
}

namespace {

// The grid over `cover`, with a voxel of room on each side, in FFT-friendly sizes of at
// least `min_dims`.
GridSpec covering_spec(const Eigen::AlignedBox3d& cover, const Eigen::Vector3i& min_dims,
                       double voxel_size, const GridLimits& limits) {
  GridSpec spec;
  spec.resolution = voxel_size;
  const Eigen::Vector3d origin =
      ((cover.min() / voxel_size).array().floor() - 1.0).matrix() * voxel_size;
  for (int axis = 0; axis < 3; ++axis) {
    const int needed = voxels_along(cover.max()[axis] - origin[axis], voxel_size, limits) + 2;
    spec.dims[axis] = fft_friendly_size(std::max(min_dims[axis], needed));
  }
  spec.origin = origin;
  if (spec.voxel_count() > limits.max_voxels) {
    fail("voxel_size: a translation grid of ", spec.dims.transpose(), " voxels at ", voxel_size,
         " m exceeds the limit of ", limits.max_voxels, " voxels (max_voxels)");
  }
  return spec;
}

GridSpec scene_spec(const SceneMap& scene, const Eigen::Vector3d& start, double reach,
                    double voxel_size, const GridLimits& limits) {
  const Eigen::AlignedBox3d scene_box = bounding_box(scene.cloud());
  const Eigen::AlignedBox3d hull = cube(start, reach);
  const GridSpec minimum = make_grid_spec(hull, scene_box, voxel_size, limits);
  Eigen::AlignedBox3d cover = scene_box;
  cover.min().array() -= reach;
  cover.max().array() += reach;
  cover.extend(hull);
  return covering_spec(cover, minimum.dims, voxel_size, limits);
}

}  // namespace

GridSpec bounded_translation_spec(const Eigen::AlignedBox3d& scene_box,
                                  const Eigen::AlignedBox3d& model_box, double max_translation,
                                  double voxel_size, const GridLimits& limits) {
  // The grid is circular: max_translation of room once, past the far side, keeps every
  // shift of up to max_translation either way from wrapping one cloud onto the other.
  Eigen::AlignedBox3d cover = scene_box;
  cover.extend(model_box);
  cover.max().array() += max_translation;
  // Or the model's box with the room on both sides, which holds every shifted model
  // without wrapping at all; valid on an axis where the scene lies within it.
  Eigen::AlignedBox3d reach = model_box;
  reach.min().array() -= max_translation;
  reach.max().array() += max_translation;
  for (int axis = 0; axis < 3; ++axis) {
    const bool inside =
        scene_box.min()[axis] >= reach.min()[axis] && scene_box.max()[axis] <= reach.max()[axis];
    if (inside && reach.sizes()[axis] < cover.sizes()[axis]) {
      cover.min()[axis] = reach.min()[axis];
      cover.max()[axis] = reach.max()[axis];
    }
  }
  const int shifts = 2 * voxels_along(max_translation, voxel_size, limits) + 2;
  return covering_spec(cover, Eigen::Vector3i::Constant(shifts), voxel_size, limits);
}

SceneTranslation::SceneTranslation(const SceneMap& scene, const Eigen::Vector3d& start,
                                   double reach, double voxel_size, Occupancy occupancy,
                                   const PhaseCorrelationParams& params, const GridLimits& limits)
    : SceneTranslation(scene, scene_spec(scene, start, reach, voxel_size, limits), std::nullopt,
                       occupancy, params, limits) {}

SceneTranslation::SceneTranslation(const SceneMap& scene, const Eigen::AlignedBox3d& model_box,
                                   double max_translation, double voxel_size, Occupancy occupancy,
                                   const PhaseCorrelationParams& params, const GridLimits& limits)
    : SceneTranslation(points_in_reach(scene.cloud().points(), model_box, max_translation),
                       model_box, max_translation, voxel_size, occupancy, params, limits) {}

SceneTranslation::SceneTranslation(const Points& in_reach, const Eigen::AlignedBox3d& model_box,
                                   double max_translation, double voxel_size, Occupancy occupancy,
                                   const PhaseCorrelationParams& params, const GridLimits& limits)
    : occupancy_(occupancy),
      limits_(limits),
      spec_(bounded_translation_spec(points_box(in_reach), model_box, max_translation, voxel_size,
                                     limits)),
      phase_(spec_, params),
      max_shift_(Eigen::Vector3i::Constant(voxels_along(max_translation, voxel_size, limits))) {
  voxelize_into(in_reach, spec_, occupancy, target_, limits);
  phase_.set_target(target_);
}

SceneTranslation::SceneTranslation(const SceneMap& scene, const GridSpec& spec,
                                   const std::optional<Eigen::Vector3i>& max_shift,
                                   Occupancy occupancy, const PhaseCorrelationParams& params,
                                   const GridLimits& limits)
    : occupancy_(occupancy),
      limits_(limits),
      spec_(spec),
      phase_(spec_, params),
      max_shift_(max_shift) {
  target_ = voxelize(scene.cloud(), spec_, occupancy, limits);
  phase_.set_target(target_);
}

TranslationEstimate SceneTranslation::estimate(const Points& moved) {
  voxelize_into(moved, spec_, occupancy_, moving_, limits_);
  if (moving_.empty()) fail("initial_guess: the model falls outside the scene's grid");
  return max_shift_ ? phase_.estimate(moving_, *max_shift_) : phase_.estimate(moving_);
}

double SceneTranslation::translation_cost() const {
  if (!target_energy_) target_energy_ = grid_energy(target_);
  return spectral_vs::translation_cost(moving_, target_, Eigen::Vector3i::Zero(), *target_energy_);
}

}  // namespace spectral_vs::detail
