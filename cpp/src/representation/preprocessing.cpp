#include <spectral_vs/representation/preprocessing.hpp>

#include "common/checks.hpp"

#include <pcl/features/normal_3d_omp.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <cmath>
#include <limits>

namespace spectral_vs {

using detail::fail;

namespace {

// PCL works in float, whose step is 8 microns at 100 m but 6 cm at a million metres.
// Clouds within kNearOrigin of the origin go in as they are; farther ones relative to a
// point near them, so that precision follows the cloud's size, not its distance from the
// origin.
constexpr double kNearOrigin = 100.0;  // metres

// The offset to subtract before PCL: zero near the origin, else the centroid, snapped to
// a multiple of `snap` metres when snap > 0 (so that voxel boundaries stay in place).
Eigen::Vector3d float_offset(const PointCloud& cloud, double snap) {
  if (cloud.points().cwiseAbs().maxCoeff() <= kNearOrigin) return Eigen::Vector3d::Zero();
  const Eigen::Vector3d centroid = cloud.centroid();
  return snap > 0.0 ? Eigen::Vector3d((centroid / snap).array().round().matrix() * snap) : centroid;
}

pcl::PointCloud<pcl::PointNormal>::Ptr to_pcl(const PointCloud& cloud,
                                              const Eigen::Vector3d& offset) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  out->resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    auto& p = (*out)[i];
    p.getVector3fMap() = (cloud.points().row(Eigen::Index(i)).transpose() - offset).cast<float>();
    if (cloud.has_normals()) {
      p.getNormalVector3fMap() = cloud.normals().row(Eigen::Index(i)).transpose().cast<float>();
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
  if (params.k_neighbors < 0) fail("k_neighbors must be >= 0, got ", params.k_neighbors);
  if (params.k_neighbors == 0) detail::require_positive_finite(params.radius, "radius");
  if (!params.viewpoint.allFinite()) fail("viewpoint must be finite");
  // PCL's OpenMP would try to start them all (100000 threads crashed the process).
  if (params.threads < 1 || params.threads > 256)
    fail("threads must be in [1, 256], got ", params.threads);

  const Eigen::Vector3d centroid = cloud.centroid();
  auto input = to_pcl(cloud, float_offset(cloud, 0.0));
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

  Points points(static_cast<Eigen::Index>(cloud.size()), 3);
  Points normals(points.rows(), 3);
  Eigen::Index kept = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    Eigen::Vector3d n = estimated[i].getNormalVector3fMap().cast<double>();
    if (!n.allFinite() || n.norm() < 1e-6) continue;
    const Eigen::Vector3d p = cloud.points().row(Eigen::Index(i)).transpose();
    const Eigen::Vector3d reference = params.orientation == NormalOrientation::toward_viewpoint
                                          ? Eigen::Vector3d(params.viewpoint - p)
                                          : Eigen::Vector3d(p - centroid);
    if (n.dot(reference) < 0.0) n = -n;
    points.row(kept) = p.transpose();
    normals.row(kept) = n.normalized().transpose();
    ++kept;
  }
  if (kept == 0) {
    fail(
        "radius/k_neighbors: no point has enough neighbours for a normal (3 or more, not all "
        "coincident or collinear); radius = ",
        params.radius, " m, k_neighbors = ", params.k_neighbors);
  }
  points.conservativeResize(kept, Eigen::NoChange);
  normals.conservativeResize(kept, Eigen::NoChange);
  return PointCloud(std::move(points), std::move(normals));
}

}  // namespace spectral_vs
