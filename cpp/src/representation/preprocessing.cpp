#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>

#include "common/checks.hpp"

#include <pcl/features/normal_3d_omp.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

// PCL works in float, whose step is 8 microns at 100 m but 6 cm at a million metres.
// Clouds within kNearOrigin of the origin go in as they are; farther ones relative to their
// per-axis median, so that precision follows the cloud's size, not its distance from the
// origin. The median, not the centroid: one point 1e12 m away moved the centroid of a
// 115 k-point room view 8.6e6 m, where float's step is 1 m, and changed 57% of its other
// points' normals.
constexpr double kNearOrigin = 100.0;  // metres
// Points farther than this from that reference on an axis are not searched (they get no
// normal): the squared distances of float beyond it would overflow.
constexpr double kFloatReach = 1e18;  // metres
// PCL's search reserves k indices and distances per point: 2^30 neighbours took 4 GB and
// then std::bad_alloc, 2^24 took 258 MB for a cloud of 400 points. A plane fitted to more
// than a thousand neighbours is no local normal.
constexpr int kMaxNeighbors = 1024;

double median_of(std::vector<double>& values) {
  const auto k = std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[std::size_t(k)];
}

// The offset to subtract before PCL: zero when every point is near the origin or the
// per-axis median is, else that median.
Eigen::Vector3d float_offset(const PointCloud& cloud) {
  const Points& points = cloud.points();
  if (points.cwiseAbs().maxCoeff() <= kNearOrigin) return Eigen::Vector3d::Zero();
  std::vector<double> values(std::size_t(points.rows()));
  Eigen::Vector3d median;
  for (int axis = 0; axis < 3; ++axis) {
    for (Eigen::Index i = 0; i < points.rows(); ++i) values[std::size_t(i)] = points(i, axis);
    median[axis] = median_of(values);
  }
  return median.cwiseAbs().maxCoeff() <= kNearOrigin ? Eigen::Vector3d::Zero() : median;
}

// The rows of `searched` relative to `offset`, in float.
pcl::PointCloud<pcl::PointNormal>::Ptr to_pcl(const PointCloud& cloud,
                                              const std::vector<Eigen::Index>& searched,
                                              const Eigen::Vector3d& offset) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  out->resize(searched.size());
  for (std::size_t i = 0; i < searched.size(); ++i) {
    auto& p = (*out)[i];
    p.getVector3fMap() = (cloud.points().row(searched[i]).transpose() - offset).cast<float>();
    if (cloud.has_normals()) {
      p.getNormalVector3fMap() = cloud.normals().row(searched[i]).transpose().cast<float>();
    } else {
      p.getNormalVector3fMap().setZero();
    }
    p.curvature = 0.0f;
  }
  return out;
}

}  // namespace

// voxel_downsample is in voxel_downsample.cpp.

PointCloud estimate_normals(const PointCloud& cloud, const NormalEstimationParams& params) {
  require_non_empty(cloud, "cloud");
  if (params.k_neighbors < 0 || params.k_neighbors > kMaxNeighbors) {
    fail("k_neighbors must be in [0, ", kMaxNeighbors, "], got ", params.k_neighbors);
  }
  if (params.k_neighbors == 0) detail::require_positive_finite(params.radius, "radius");
  if (!params.viewpoint.allFinite()) fail("viewpoint must be finite");
  // PCL's OpenMP would try to start them all (100000 threads crashed the process).
  if (params.threads < 1 || params.threads > 256)
    fail("threads must be in [1, 256], got ", params.threads);

  const Eigen::Vector3d offset = float_offset(cloud);
  std::vector<Eigen::Index> searched;
  searched.reserve(cloud.size());
  for (Eigen::Index i = 0; i < Eigen::Index(cloud.size()); ++i) {
    if ((cloud.points().row(i).transpose() - offset).cwiseAbs().maxCoeff() < kFloatReach)
      searched.push_back(i);
  }
  const std::size_t unreachable = cloud.size() - searched.size();

  std::vector<Eigen::Vector3d> fitted(searched.size());
  std::vector<char> has_normal(searched.size(), 0);
  if (!searched.empty()) {
    auto input = to_pcl(cloud, searched, offset);
    pcl::NormalEstimationOMP<pcl::PointNormal, pcl::Normal> estimator(
        static_cast<unsigned int>(params.threads));
    estimator.setInputCloud(input);
    estimator.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointNormal>>());
    if (params.k_neighbors > 0) {
      estimator.setKSearch(params.k_neighbors);
    } else {
      estimator.setRadiusSearch(params.radius);
    }
    pcl::PointCloud<pcl::Normal> estimated;
    estimator.compute(estimated);
    for (std::size_t i = 0; i < searched.size(); ++i) {
      fitted[i] = estimated[i].getNormalVector3fMap().cast<double>();
      has_normal[i] = fitted[i].allFinite() && fitted[i].norm() >= 1e-6;
    }
  }
  std::vector<char> keep(cloud.size(), 0);
  for (std::size_t i = 0; i < searched.size(); ++i) keep[std::size_t(searched[i])] = has_normal[i];
  Eigen::Index kept = 0;
  for (const char k : keep) kept += k;
  if (kept == 0) {
    std::string unsearched;
    if (unreachable > 0) {
      unsearched = "; points 1e18 m or more from the others' median on an axis, not searched: " +
                   std::to_string(unreachable) + " of " + std::to_string(cloud.size());
    }
    fail("radius/k_neighbors: no point has enough neighbours for a normal (3 or more, not all ",
         "coincident or collinear); radius = ", params.radius,
         " m, k_neighbors = ", params.k_neighbors, unsearched);
  }

  // "outward" turns normals away from the centroid of the points that have one: a point
  // without neighbours (a far outlier) does not move it.
  const Eigen::Vector3d centre =
      std::size_t(kept) == cloud.size() ? cloud.centroid() : cloud.selected(keep).centroid();
  Points points(kept, 3);
  Points normals(kept, 3);
  Eigen::Index row = 0;
  for (std::size_t i = 0; i < searched.size(); ++i) {
    if (!has_normal[i]) continue;
    Eigen::Vector3d n = fitted[i];
    const Eigen::Vector3d p = cloud.points().row(searched[i]).transpose();
    const Eigen::Vector3d reference = params.orientation == NormalOrientation::toward_viewpoint
                                          ? Eigen::Vector3d(params.viewpoint - p)
                                          : Eigen::Vector3d(p - centre);
    if (n.dot(reference) < 0.0) n = -n;
    points.row(row) = p.transpose();
    normals.row(row) = n.normalized().transpose();
    ++row;
  }
  return PointCloud(std::move(points), std::move(normals));
}

namespace {

// Whether `point` lies strictly inside the cloud's bounding box.
bool inside_box(const PointCloud& cloud, const Eigen::Vector3d& point) {
  const Eigen::AlignedBox3d box = bounding_box(cloud);
  return (box.min().array() < point.array()).all() && (point.array() < box.max().array()).all();
}

// A step's error, said with the argument and the step it came from (`what`, made only
// then: the servo prepares every frame).
template <typename Step, typename What>
PointCloud step_of(Step step, const std::string& argument, What what) {
  try {
    return step();
  } catch (const std::invalid_argument& error) {
    std::ostringstream message;
    message << argument << ": " << what() << ": " << error.what();
    throw std::invalid_argument(message.str());
  }
}

}  // namespace

PointCloud prepare_cloud(const PointCloud& cloud, double voxel_size, bool downsample,
                         const Eigen::Vector3d& viewpoint, const std::string& argument) {
  if (cloud.size() == 0) fail(argument, " is empty: at least 1 finite point is needed");
  if (!(std::isfinite(voxel_size) && voxel_size > 0.0))
    fail("voxel_size must be finite and > 0 metres, got ", voxel_size);
  if (!viewpoint.allFinite()) fail(argument, ": the viewpoint must be finite");
  PointCloud prepared =
      downsample ? step_of([&] { return voxel_downsample(cloud, 0.5 * voxel_size); }, argument,
                           [&] {
                             std::ostringstream what;
                             what << "downsampling to half of voxel_size = " << voxel_size << " m";
                             return what.str();
                           })
                 : cloud;
  if (prepared.has_normals()) return prepared;
  NormalEstimationParams normals;
  normals.radius = 2.0 * voxel_size;
  normals.viewpoint = viewpoint;
  normals.orientation = inside_box(prepared, viewpoint) ? NormalOrientation::outward
                                                        : NormalOrientation::toward_viewpoint;
  return step_of(
      [&] { return estimate_normals(prepared, normals); }, argument,
      [&] {
        std::ostringstream what;
        what << "estimating normals over a radius of 2 x voxel_size = " << 2.0 * voxel_size << " m";
        return what.str();
      });
}

}  // namespace spectral_vs
