#include "alignment/scene_map.hpp"

#include "common/checks.hpp"
#include "spectral_vs/representation/dominant_plane.hpp"

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

namespace {

// The 26 directions to the neighbours of a voxel, about 35-45 degrees apart.
const std::array<Eigen::Vector3d, 26>& directions() {
  static const std::array<Eigen::Vector3d, 26> table = [] {
    std::array<Eigen::Vector3d, 26> d;
    int n = 0;
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z) {
          if (x || y || z) d[n++] = Eigen::Vector3d(x, y, z).normalized();
        }
    return d;
  }();
  return table;
}

}  // namespace

namespace {

// The nearest of the 26 directions without trying each: the best direction with k
// non-zero components takes the signs of the normal's k largest components, and scores
// the sum of their magnitudes over sqrt(k).
int nearest_direction(const Eigen::Vector3d& normal) {
  const Eigen::Array3d a = normal.cwiseAbs();
  int order[3] = {0, 1, 2};
  if (a[order[0]] < a[order[1]]) std::swap(order[0], order[1]);
  if (a[order[1]] < a[order[2]]) std::swap(order[1], order[2]);
  if (a[order[0]] < a[order[1]]) std::swap(order[0], order[1]);
  const double one = a[order[0]];
  const double two = (a[order[0]] + a[order[1]]) * M_SQRT1_2;
  const double three = (a[0] + a[1] + a[2]) * (1.0 / std::sqrt(3.0));
  const int count = three > std::max(one, two) ? 3 : (two > one ? 2 : 1);
  int component[3] = {0, 0, 0};
  for (int k = 0; k < count; ++k) component[order[k]] = normal[order[k]] < 0.0 ? -1 : 1;
  // The table's order: x, then y, then z from -1 to 1, without the zero vector (13).
  const int t = (component[0] + 1) * 9 + (component[1] + 1) * 3 + (component[2] + 1);
  return t < 13 ? t : t - 1;
}

}  // namespace

Points rows_of(const Points& matrix, const std::vector<Eigen::Index>& rows) {
  Points selected(static_cast<Eigen::Index>(rows.size()), 3);
  for (std::size_t i = 0; i < rows.size(); ++i) selected.row(Eigen::Index(i)) = matrix.row(rows[i]);
  return selected;
}

PointCloud every_nth(const PointCloud& cloud, Eigen::Index stride) {
  const Eigen::Index n = (cloud.size() + stride - 1) / stride;
  Points points(n, 3), normals(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    points.row(i) = cloud.points().row(i * stride);
    normals.row(i) = cloud.normals().row(i * stride);
  }
  return PointCloud(points, normals);
}

std::uint64_t voxel_key(const Eigen::Array3i& voxel) {
  const Eigen::Array3i k = (voxel + (1 << 20)).max(0).min((1 << 21) - 1);
  return (std::uint64_t(k.x()) << 42) | (std::uint64_t(k.y()) << 21) | std::uint64_t(k.z());
}

int normal_direction(const Eigen::Vector3d& normal, std::uint32_t* cone) {
  if (!cone) return nearest_direction(normal);
  int best = 0;
  double best_dot = -2.0;
  std::uint32_t within = 0;
  for (int i = 0; i < 26; ++i) {
    const double dot = directions()[std::size_t(i)].dot(normal);
    if (dot > best_dot) {
      best_dot = dot;
      best = i;
    }
    if (dot > 0.6428) within |= 1u << i;  // cos(50 degrees)
  }
  *cone = within | (1u << best);
  return best;
}

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

Eigen::AlignedBox3d points_box(const Points& points) {
  return Eigen::AlignedBox3d(points.colwise().minCoeff().transpose(),
                             points.colwise().maxCoeff().transpose());
}

Points points_in_reach(const Points& scene, const Eigen::AlignedBox3d& model_box,
                       double max_translation) {
  const Eigen::Array3d low = model_box.min().array() - max_translation;
  const Eigen::Array3d high = model_box.max().array() + max_translation;
  std::vector<Eigen::Index> rows;
  rows.reserve(std::size_t(scene.rows()));
  for (Eigen::Index i = 0; i < scene.rows(); ++i) {
    const Eigen::Array3d p = scene.row(i).transpose().array();
    if ((p >= low).all() && (p <= high).all()) rows.push_back(i);
  }
  if (rows.empty() || Eigen::Index(rows.size()) == scene.rows()) return scene;
  Points out(Eigen::Index(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) out.row(Eigen::Index(k)) = scene.row(rows[k]);
  return out;
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

namespace {

// The support plane's detection: the most common normal direction to within 10 degrees,
// the plane's normals within 20 degrees of it, its offset voted in voxel bins, its points
// within 1.5 voxels of it and more than a fifth of the scene's.
PlaneDetectionParams support_plane_params(double voxel_size) {
  PlaneDetectionParams params;
  params.direction_cone = 10.0 * M_PI / 180.0;
  params.member_cone = 20.0 * M_PI / 180.0;
  params.offset_bin = voxel_size;
  params.band = 1.5 * voxel_size;
  params.min_share = 0.2;
  return params;
}

}  // namespace

std::optional<SupportPlane> support_plane(const PointCloud& scene, double voxel_size,
                                          double min_extent) {
  const std::optional<DominantPlane> plane =
      dominant_plane(scene, support_plane_params(voxel_size));
  if (!plane || plane->count == scene.size() || plane->extent < min_extent) return std::nullopt;
  // The vote's offset is a bin's edge, up to half a voxel off: the median of its points'
  // offsets is the plane's, so that a band under a thin object's height (support_band)
  // still holds the plane.
  const std::vector<char> on = plane_members(scene, *plane, support_plane_params(voxel_size));
  std::vector<double> offsets;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i)
    if (on[std::size_t(i)]) offsets.push_back(scene.points().row(i).dot(plane->normal));
  const auto middle = offsets.begin() + std::ptrdiff_t(offsets.size() / 2);
  std::nth_element(offsets.begin(), middle, offsets.end());
  return SupportPlane{plane->normal, *middle};
}

PointCloud without_support_plane(const PointCloud& scene, const SupportPlane& plane,
                                 double voxel_size, double band) {
  DominantPlane found;
  found.normal = plane.normal;
  found.offset = plane.offset;
  PlaneDetectionParams members = support_plane_params(voxel_size);
  members.band = band;
  const std::vector<char> on = plane_members(scene, found, members);
  const auto kept = Eigen::Index(std::count(on.begin(), on.end(), 0));
  Points kept_points(kept, 3), kept_normals(kept, 3);
  Eigen::Index row = 0;
  for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
    if (on[std::size_t(i)]) continue;
    kept_points.row(row) = scene.points().row(i);
    kept_normals.row(row++) = scene.normals().row(i);
  }
  return PointCloud(kept_points, kept_normals);
}

namespace {

// Union-find over point indices, with path halving; the smaller index is the root, so
// the parts do not depend on the order of the unions.
struct DisjointSets {
  std::vector<Eigen::Index> parent;
  explicit DisjointSets(Eigen::Index n) : parent(std::size_t(n)) {
    std::iota(parent.begin(), parent.end(), 0);
  }
  Eigen::Index find(Eigen::Index i) {
    while (parent[std::size_t(i)] != i)
      i = parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
    return i;
  }
  void unite(Eigen::Index a, Eigen::Index b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
  }
};

}  // namespace

std::vector<std::vector<Eigen::Index>> connected_parts(const Points& points, double tolerance) {
  // Cells of diagonal `tolerance`: the points of one cell are all connected, so sets
  // join whole cells, and a pair of cells is searched for a close pair of points only
  // until the first one is found.
  const double edge = tolerance / std::sqrt(3.0);
  std::unordered_map<std::uint64_t, Eigen::Index> cell_index;
  std::vector<Eigen::Array3i> cells;
  std::vector<std::vector<Eigen::Index>> members;
  std::vector<Eigen::Index> cell_of_point(std::size_t(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Array3i c = (points.row(i).array() / edge).floor().cast<int>();
    const auto [it, added] = cell_index.try_emplace(voxel_key(c), Eigen::Index(cells.size()));
    if (added) {
      cells.push_back(c);
      members.emplace_back();
    }
    members[std::size_t(it->second)].push_back(i);
    cell_of_point[std::size_t(i)] = it->second;
  }
  const auto close = [&](Eigen::Index a, Eigen::Index b) {
    for (const Eigen::Index i : members[std::size_t(a)])
      for (const Eigen::Index j : members[std::size_t(b)])
        if ((points.row(i) - points.row(j)).squaredNorm() <= tolerance * tolerance) return true;
    return false;
  };
  DisjointSets sets(Eigen::Index(cells.size()));
  for (Eigen::Index a = 0; a < Eigen::Index(cells.size()); ++a) {
    for (int dx = -2; dx <= 2; ++dx)
      for (int dy = -2; dy <= 2; ++dy)
        for (int dz = -2; dz <= 2; ++dz) {
          const auto it =
              cell_index.find(voxel_key(cells[std::size_t(a)] + Eigen::Array3i(dx, dy, dz)));
          if (it == cell_index.end() || it->second <= a) continue;
          if (sets.find(a) != sets.find(it->second) && close(a, it->second))
            sets.unite(a, it->second);
        }
  }
  std::vector<std::vector<Eigen::Index>> parts;
  std::vector<Eigen::Index> part_of_root(cells.size(), -1);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    Eigen::Index& part = part_of_root[std::size_t(sets.find(cell_of_point[std::size_t(i)]))];
    if (part < 0) {
      part = Eigen::Index(parts.size());
      parts.emplace_back();
    }
    parts[std::size_t(part)].push_back(i);
  }
  std::stable_sort(parts.begin(), parts.end(),
                   [](const auto& a, const auto& b) { return a.size() > b.size(); });
  return parts;
}

}  // namespace spectral_vs::detail
