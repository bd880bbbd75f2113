#include "alignment/scene_preparation.hpp"

#include "alignment/align_detail.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/support_plane.hpp"
#include "common/checks.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <numeric>

namespace spectral_vs {
namespace detail {

// A connected part of the scene that could be the object, or the part of it a view
// shows: at least kPartMinPoints points, no smaller than a quarter of the model's reach
// and no larger than two of its diameters (two objects touching).
constexpr std::size_t kPartMinPoints = 30;

// The support plane's band: kPlaneBand voxels, or kThinBand of the model's thickness
// (its extent along its thinnest principal axis) if that is less, but no less than
// kMinPlaneBand voxels (the scan's noise about the plane). A plate lying on the table
// (cases.THIN_OBJECTS: the jenga mesh cut to 120 x 90 x 9 mm, a tuning-side object) had
// its top face inside the 1.5-voxel band, taken for the table: 15 of 42 clutter scenes
// right (benchmarks/thin_objects.py), 42 with this band; on 14 of them a band of 4 mm
// gave 13, of 6 mm 11. Every tuning object is thick enough for its band to stay 1.5
// voxels (the thinnest, jenga, is 32 mm).
constexpr double kPlaneBand = 1.5;
constexpr double kThinBand = 0.4;
constexpr double kMinPlaneBand = 0.5;

double support_band(const Points& model_points, double voxel_size) {
  const Eigen::RowVector3d mean = model_points.colwise().mean();
  const Points centred = model_points.rowwise() - mean;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(centred.transpose() * centred);
  const Eigen::VectorXd along = centred * eigen.eigenvectors().col(0);  // thinnest axis
  const double thickness = along.maxCoeff() - along.minCoeff();
  return std::clamp(kThinBand * thickness, kMinPlaneBand * voxel_size, kPlaneBand * voxel_size);
}

std::vector<Eigen::Index> rows_above(const PointCloud& searched,
                                     const std::optional<SupportPlane>& plane, double band) {
  // Without the points near the plane (their normals tilted at the objects' feet) that
  // would join every object into one part, or below it.
  std::vector<Eigen::Index> above;
  for (Eigen::Index i = 0; i < searched.points().rows(); ++i) {
    if (!plane || searched.points().row(i).dot(plane->normal) - plane->offset > band)
      above.push_back(i);
  }
  return above;
}

std::vector<std::vector<Eigen::Index>> object_parts(
    const PointCloud& searched, const std::optional<detail::SupportPlane>& plane, double reach,
    double voxel_size, double band, int max_parts) {
  std::vector<Eigen::Index> above = rows_above(searched, plane, band);
  const Points points = detail::rows_of(searched.points(), above);
  const auto plausible = [&](const std::vector<Eigen::Index>& part) {
    Eigen::AlignedBox3d box;
    for (const Eigen::Index i : part) box.extend(searched.points().row(i).transpose());
    const double size = box.sizes().norm();
    return size >= 0.25 * reach && size <= 4.0 * reach;
  };
  std::vector<std::vector<Eigen::Index>> kept;
  for (auto& part : detail::connected_parts(points, kPartTolerance * voxel_size)) {
    if (part.size() < kPartMinPoints || kept.size() == std::size_t(max_parts)) break;
    for (Eigen::Index& i : part) i = above[std::size_t(i)];
    if (plausible(part)) kept.push_back(std::move(part));
  }
  // A view of one object that its depth edges cut in parts: the parts, and the whole.
  if (kept.size() != 1 && plausible(above)) kept.insert(kept.begin(), std::move(above));
  return kept;
}

// A single view without a support plane (the object alone, or the part of it a view
// shows): the whole view is the one part, placed from the model's side facing the sensor.
std::vector<Eigen::Index> whole_view(const PointCloud& searched) {
  std::vector<Eigen::Index> all(searched.size());
  std::iota(all.begin(), all.end(), Eigen::Index(0));
  return all;
}

// With guess_distance: the parts of the scene that the model could reach from the guess.
void keep_parts_near_guess(const Problem& problem, const GlobalSearchParams& search,
                           const Transform& initial_guess, const PointCloud& searched,
                           std::vector<std::vector<Eigen::Index>>& parts) {
  if (!(search.guess_distance > 0.0)) return;
  const Eigen::Vector3d centre = problem.model.centre(problem.model.pose_of(initial_guess));
  const double reach = search.guess_distance + problem.model.reach();
  const auto far = [&](const std::vector<Eigen::Index>& part) {
    for (const Eigen::Index i : part)
      if ((searched.points().row(i).transpose() - centre).norm() <= reach) return false;
    return true;
  };
  parts.erase(std::remove_if(parts.begin(), parts.end(), far), parts.end());
}

namespace {

// Pixels of the single-view detection, in tolerances at the scene's median distance: finer
// than the view check's half tolerance, so that a downsampled scan's far surfaces (several
// points per pixel of half a voxel, seen at a slant) are not taken for hidden ones, and
// coarse enough that the empty pixels between a full model's front points, filled from
// their neighbours, still hide its back.
constexpr double kDetectionPixel = 0.25;

// The share of the scene that a sensor at `origin` sees, on the range image `image` made
// from there.
double visible_share(const PointCloud& scene, const RangeImage& image, double tolerance) {
  const detail::ViewCheck seen =
      image.check(scene.points(), scene.normals(), tolerance, RangeImage::Distance::along_normal);
  return double(seen.surface_points) / double(scene.size());
}

// Where the sensor of the scene is, and whether the scene is one view from there.
struct SceneSensor {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  SceneView view = SceneView::automatic;
};

SceneSensor scene_sensor(const AlignParams& params) {
  return {params.scene.sensor_origin, params.scene.scene_view};
}

}  // namespace

std::optional<Eigen::Vector3d> declared_viewpoint(const AlignParams& params) {
  const SceneSensor sensor = scene_sensor(params);
  if (sensor.view != SceneView::single_view) return std::nullopt;
  return sensor.origin;
}

Eigen::Vector3d scene_sensor_origin(const AlignParams& params) {
  return scene_sensor(params).origin;
}

std::optional<Eigen::Vector3d> single_view_origin(const PointCloud& scene,
                                                  const AlignParams& params) {
  const SceneSensor sensor = scene_sensor(params);
  if (sensor.view == SceneView::all_sides) return std::nullopt;
  if (sensor.view == SceneView::automatic &&
      !detect_single_view(scene, sensor.origin, params.scene.voxel_size).single_view)
    return std::nullopt;
  return sensor.origin;
}

}  // namespace detail

SingleViewEvidence detect_single_view(const PointCloud& scene, const Eigen::Vector3d& sensor_origin,
                                      double tolerance) {
  require_non_empty(scene, "scene");
  require_normals(scene, "scene");
  if (!sensor_origin.allFinite()) detail::fail("sensor_origin must be finite");
  detail::require_positive_finite(tolerance, "tolerance");
  SingleViewEvidence evidence;
  try {
    const detail::RangeImage image(scene, sensor_origin, detail::kDetectionPixel * tolerance);
    evidence.visible = detail::visible_share(scene, image, tolerance);
  } catch (const std::invalid_argument&) {
    evidence.visible = 0.0;  // nothing in front of the origin, or the origin at the centroid
  }
  evidence.single_view = evidence.visible >= single_view_threshold;
  return evidence;
}

}  // namespace spectral_vs
