#include "alignment/resting.hpp"

#include "alignment/hypotheses.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/support_plane.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace spectral_vs::detail {

namespace {

// Directions tried as a face's normal: a Fibonacci sphere, about 4.6 degrees apart.
constexpr int kDirections = 2000;
// A face is at least this share of the model's points ...
constexpr double kMinRestingShare = 0.02;
// ... whose normals are within this of the face's.
constexpr double kRestingNormalDeg = 15.0;
// Two faces are at least this far apart.
constexpr double kDistinctFaceDeg = 20.0;
// Turns about the plane's normal per resting face: every 15 degrees, the first
// refinement's reach.
constexpr int kRestingTurns = 24;
// Two resting poses of a part are at least this far apart in rotation.
constexpr double kDistinctRestingDeg = 10.0;
// A model's faces are sought on about kFacePoints of its points at most, and its resting
// poses scored on every kSparseStride-th point, about kScoredPoints at most: a room-sized
// model is not searched whole.
constexpr Eigen::Index kFacePoints = 5000;
constexpr Eigen::Index kScoredPoints = 1000;

constexpr double kRestingGap = 1.5;       // voxels
constexpr double kSupportedShare = 0.1;   // of the pose's lowest points
constexpr double kUpwardCosine = 0.7071;  // a scene normal within 45 degrees of up

Eigen::Vector3d fibonacci_direction(int i, int n) {
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  const double z = 1.0 - (2.0 * i + 1.0) / n;
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(golden * i), r * std::sin(golden * i), z};
}

struct Face {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  int points = 0;
};

// The points on the model's supporting plane of normal d (within `tolerance`) whose
// normals agree with it.
Face face_along(const PointCloud& model, const Eigen::Vector3d& d, double tolerance) {
  const Eigen::VectorXd height = model.points() * d;
  const double top = height.maxCoeff();
  const double agree = std::cos(kRestingNormalDeg * M_PI / 180.0);
  Face face;
  for (Eigen::Index i = 0; i < height.size(); ++i) {
    const Eigen::Vector3d n = model.normals().row(i).transpose();
    if (height(i) >= top - tolerance && n.dot(d) >= agree) {
      face.normal += n;
      ++face.points;
    }
  }
  if (face.points) face.normal.normalize();
  return face;
}

double lowest(const Points& points, const SupportPlane& plane) {
  return (points * plane.normal).minCoeff() - plane.offset;
}

// The model at rotation R, its side facing the sensor at `centroid`, its lowest point on
// the plane.
Pose resting_at(const Problem& problem, MovingModel& model, const Eigen::Matrix3d& R,
                const Eigen::Vector3d& centroid, const SupportPlane& plane) {
  Pose pose = facing_at_part(problem, model, R, centroid);
  pose.offset -= lowest(model.move(pose), plane) * plane.normal;
  return pose;
}

}  // namespace

std::vector<Eigen::Vector3d> resting_faces(const PointCloud& given, double tolerance) {
  const PointCloud model =
      every_nth(given, std::max<Eigen::Index>(1, given.points().rows() / kFacePoints));
  const Eigen::Index n = model.points().rows();
  if (n == 0) return {};
  std::vector<Face> found;
  for (int i = 0; i < kDirections; ++i) {
    // A direction a few degrees off a face's normal meets only a strip of it within the
    // tolerance: the face is counted again along the mean normal of that strip.
    Face face = face_along(model, fibonacci_direction(i, kDirections), tolerance);
    if (face.points == 0) continue;
    face = face_along(model, face.normal, tolerance);
    if (face.points >= kMinRestingShare * double(n)) found.push_back(face);
  }
  std::stable_sort(found.begin(), found.end(),
                   [](const Face& a, const Face& b) { return a.points > b.points; });
  const double distinct = std::cos(kDistinctFaceDeg * M_PI / 180.0);
  std::vector<Eigen::Vector3d> faces;
  for (const Face& face : found) {
    if (std::none_of(faces.begin(), faces.end(),
                     [&](const Eigen::Vector3d& f) { return f.dot(face.normal) > distinct; }))
      faces.push_back(face.normal);
  }
  return faces;
}

std::vector<Eigen::Matrix3d> resting_rotations(const Eigen::Vector3d& face,
                                               const Eigen::Vector3d& up, int turns) {
  const Eigen::Matrix3d onto = Eigen::Quaterniond::FromTwoVectors(face, -up).toRotationMatrix();
  std::vector<Eigen::Matrix3d> rotations;
  for (int k = 0; k < turns; ++k)
    rotations.push_back(Eigen::AngleAxisd(2.0 * M_PI * k / turns, up).toRotationMatrix() * onto);
  return rotations;
}

RestingCheck::RestingCheck(const PointCloud& scene, const SupportPlane& plane, double voxel_size)
    : scene_(scene), plane_(plane), voxel_size_(voxel_size) {}

const IcpScene* RestingCheck::upward() const {
  if (upward_built_) return upward_ ? &*upward_ : nullptr;
  upward_built_ = true;
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < scene_.points().rows(); ++i) {
    if (scene_.normals().row(i).dot(plane_.normal) >= kUpwardCosine) rows.push_back(i);
  }
  if (rows.empty()) return nullptr;
  upward_points_ = PointCloud(rows_of(scene_.points(), rows), rows_of(scene_.normals(), rows));
  Eigen::AlignedBox3d box = bounding_box(upward_points_);
  box.min().array() -= kRestingGap * voxel_size_;
  box.max().array() += kRestingGap * voxel_size_;
  upward_.emplace(upward_points_, box, kRestingGap * voxel_size_);
  return &*upward_;
}

bool RestingCheck::rests(const PointCloud& model, const Transform& T_scene_model) const {
  const Points moved = model.transformed(T_scene_model).points();
  const Eigen::VectorXd height = (moved * plane_.normal).array() - plane_.offset;
  const double low = height.minCoeff();
  const double gap = kRestingGap * voxel_size_;
  if (low < -gap) return false;
  if (low <= gap) return true;
  const IcpScene* upward = this->upward();
  if (!upward) return false;
  int bottom = 0, supported = 0;
  for (Eigen::Index i = 0; i < moved.rows(); ++i) {
    if (height(i) > low + voxel_size_) continue;
    ++bottom;
    const Eigen::Vector3d p = moved.row(i).transpose();
    const Eigen::Index j = upward->nearest(p, plane_.normal, gap, kUpwardCosine);
    if (j < 0) continue;
    const double below = upward->cloud().points().row(j).dot(plane_.normal) - plane_.offset;
    if (below <= low + 0.5 * voxel_size_) ++supported;
  }
  return supported >= kSupportedShare * bottom;
}

std::vector<Transform> resting_poses(const Problem& problem, const PointCloud& scene,
                                     const std::vector<std::vector<Eigen::Index>>& parts,
                                     const SupportPlane& plane, int per_part) {
  const double voxel = problem.scale.voxel_size;
  const PointCloud model = problem.model.cloud();
  const std::vector<Eigen::Vector3d> faces = resting_faces(model, 0.5 * voxel);
  const Eigen::Index stride =
      std::max<Eigen::Index>(kSparseStride, model.points().rows() / kScoredPoints);
  ScoredModel sparse(every_nth(model, stride));
  std::vector<std::pair<double, Transform>> poses;
  for (const auto& part : parts) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Index i : part) centroid += scene.points().row(i).transpose();
    centroid /= double(part.size());
    std::vector<std::pair<double, Eigen::Matrix3d>> scored;
    for (const Eigen::Vector3d& face : faces) {
      for (const Eigen::Matrix3d& R : resting_rotations(face, plane.normal, kRestingTurns)) {
        const Pose pose = resting_at(problem, sparse, R, centroid, plane);
        scored.emplace_back(sparse.fitness(problem.verifier, pose, voxel), R);
      }
    }
    std::stable_sort(scored.begin(), scored.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    std::vector<Eigen::Matrix3d> kept;
    for (const auto& [fitness, R] : scored) {
      if (int(kept.size()) == per_part) break;
      // C++17 lambdas cannot capture a structured binding: R by name.
      const Eigen::Matrix3d& rotation = R;
      const auto near = [&](const Eigen::Matrix3d& other) {
        return rotation_distance(other, rotation) * 180.0 / M_PI < kDistinctRestingDeg;
      };
      if (std::any_of(kept.begin(), kept.end(), near)) continue;
      kept.push_back(R);
      const Pose pose = resting_at(problem, problem.model, R, centroid, plane);
      poses.emplace_back(fitness, problem.model.transform_of(pose));
    }
  }
  std::stable_sort(poses.begin(), poses.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<Transform> transforms;
  for (const auto& [fitness, T] : poses) transforms.push_back(T);
  return transforms;
}

}  // namespace spectral_vs::detail
