#include <spectral_vs/alignment/aligner.hpp>

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/rotation/so3_search.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "common/checks.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace spectral_vs {

using detail::fail;

namespace {

void check_params(const AlignParams& p) {
  detail::require_positive_finite(p.voxel_size, "voxel_size");
  if (p.bandwidth < 2 || p.bandwidth > kMaxBandwidth) {
    fail("bandwidth must be in [2, ", kMaxBandwidth, "], got ", p.bandwidth);
  }
  if (!(p.translation_gain > 0.0 && p.translation_gain <= 1.0)) {
    fail("translation_gain must be in (0, 1], got ", p.translation_gain);
  }
  detail::require_positive_finite(p.rotation_gain, "rotation_gain");
  if (p.rotation_step == RotationStep::newton && p.rotation_gain > 1.0) {
    fail("rotation_gain must be in (0, 1] with Newton steps, got ", p.rotation_gain);
  }
  detail::require_positive_finite(p.max_rotation_step, "max_rotation_step");
  detail::require_positive_finite(p.tolerance, "tolerance");
  if (p.max_iterations < 1) fail("max_iterations must be >= 1, got ", p.max_iterations);
  if (p.hypotheses < 1) fail("hypotheses must be >= 1, got ", p.hypotheses);
  if (p.threads < 1) fail("threads must be >= 1, got ", p.threads);
  require_rigid_transform(p.initial_guess, "initial_guess");
}

// The model's pose as a rotation about its centroid c and a translation of it:
// x_scene = R (x_model - c) + c + offset.
struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
};

// The cube around a centroid that holds a cloud whatever its rotation.
Eigen::AlignedBox3d rotation_hull(const Eigen::Vector3d& centre, double radius) {
  return {centre - Eigen::Vector3d::Constant(radius), centre + Eigen::Vector3d::Constant(radius)};
}

// Everything Algorithm 1 needs that does not change across iterations: the scene's
// spectrum and EGI coefficients, the model's centred points and EGI coefficients.
class Alignment {
public:
  /// `start` is where the model's centroid begins, scene coordinates.
  Alignment(const PointCloud& model, const PointCloud& scene, const AlignParams& params,
            const Eigen::Vector3d& start)
      : params_(params),
        centroid_(model.centroid()),
        centred_(model.points().rowwise() - centroid_.transpose()),
        model_coefficients_(egi_coefficients(model, params.bandwidth, params.egi_method)),
        scene_coefficients_(egi_coefficients(scene, params.bandwidth, params.egi_method)),
        correlation_(scene_coefficients_, model_coefficients_, params.bandwidth, true),
        spec_(grid_for(scene, start, reach(model), params)),
        phase_(spec_, phase_params(params)) {
    scene_grid_ = voxelize(scene, spec_, params.occupancy, params.limits);
    phase_.set_target(scene_grid_);
    scene_energy_ = grid_energy(scene_grid_);
    mark_scene_neighbourhood(scene);
  }

  Pose pose_of(const Transform& T_scene_model) const {
    Pose pose;
    pose.R = T_scene_model.topLeftCorner<3, 3>();
    pose.offset = T_scene_model.topRightCorner<3, 1>() + pose.R * centroid_ - centroid_;
    return pose;
  }

  Transform transform_of(const Pose& pose) const {
    Transform T = Transform::Identity();
    T.topLeftCorner<3, 3>() = pose.R;
    T.topRightCorner<3, 1>() = centroid_ + pose.offset - pose.R * centroid_;
    return T;
  }

  So3Correlation& correlation() { return correlation_; }
  const ShCoefficients& model_coefficients() const { return model_coefficients_; }
  const ShCoefficients& scene_coefficients() const { return scene_coefficients_; }

  // The translation step: the phase-correlation shift of the model at `pose` onto the scene.
  TranslationEstimate estimate_shift(const Pose& pose) {
    move_model(pose);
    voxelize_into(moved_, spec_, params_.occupancy, moving_, params_.limits);
    if (moving_.empty()) fail("initial_guess: the model falls outside the scene's grid");
    return phase_.estimate(moving_);
  }

  // Runs Algorithm 1 from `pose` until the stop rule of eq. (17) or max_iterations.
  AlignResult run(Pose pose) {
    AlignResult result;
    const bool newton = params_.rotation_step == RotationStep::newton;
    for (int iteration = 0; iteration < params_.max_iterations; ++iteration) {
      const CorrelationValue c = correlation_.evaluate(pose.R, newton);
      pose.R = pose.R * exp_so3(rotation_step(c));

      const TranslationEstimate shift = estimate_shift(pose);
      const Eigen::Vector3d step = params_.translation_gain * shift.shift;
      pose.offset += step;

      AlignIteration record;
      record.translation_step = step.norm() / params_.voxel_size;
      record.rotation_gradient = c.gradient.norm();
      record.correlation = c.value;
      record.translation_peak = shift.peak;
      record.translation_cost =
          translation_cost(moving_, scene_grid_, Eigen::Vector3i::Zero(), scene_energy_);
      record.rotation_cost = rotation_cost(scene_coefficients_, model_coefficients_, pose.R,
                                           params_.bandwidth, true);
      record.T_scene_model = transform_of(pose);
      result.history.push_back(record);
      result.iterations = iteration + 1;
      if (record.translation_step + record.rotation_gradient < params_.tolerance) {
        result.converged = true;
        break;
      }
    }
    finish(pose, result);
    return result;
  }

  // Fraction of the model's occupied voxels at `pose` that land next to scene points.
  double fitness(const Pose& pose) {
    move_model(pose);
    std::size_t occupied = 0, supported = 0;
    marks_.assign(spec_.voxel_count(), 0);
    for (Eigen::Index i = 0; i < moved_.rows(); ++i) {
      const Eigen::Vector3i v = spec_.index_of(moved_.row(i).transpose());
      if (!spec_.contains(v)) {
        continue;
      }
      const std::size_t index = linear(v);
      if (marks_[index]) continue;
      marks_[index] = 1;
      ++occupied;
      supported += scene_near_[index];
    }
    return occupied ? double(supported) / double(occupied) : 0.0;
  }

  void finish(const Pose& pose, AlignResult& result) {
    result.T_scene_model = transform_of(pose);
    result.fitness = fitness(pose);
    result.correlation = correlation_.evaluate(pose.R).value;
    result.translation_peak = result.history.empty() ? 0.0 : result.history.back().translation_peak;
  }

private:
  static double reach(const PointCloud& model) {
    return (model.points().rowwise() - model.centroid().transpose()).rowwise().norm().maxCoeff();
  }

  // The grid holds the scene grown by the model's reach (the model's centroid may end
  // anywhere in the scene) and the model's rotation hull where it starts. Along each axis
  // it also has room for the model's hull plus the scene, so that no shift between them
  // wraps around.
  static GridSpec grid_for(const PointCloud& scene, const Eigen::Vector3d& start, double reach,
                           const AlignParams& params) {
    const Eigen::AlignedBox3d scene_box = bounding_box(scene);
    const Eigen::AlignedBox3d hull = rotation_hull(start, reach);
    GridSpec spec = make_grid_spec(hull, scene_box, params.voxel_size, params.limits);
    Eigen::AlignedBox3d cover = scene_box;
    cover.min().array() -= reach;
    cover.max().array() += reach;
    cover.extend(hull);
    const double r = params.voxel_size;
    const Eigen::Vector3d origin = ((cover.min() / r).array().floor() - 1.0).matrix() * r;
    for (int axis = 0; axis < 3; ++axis) {
      const int needed = static_cast<int>(std::ceil((cover.max()[axis] - origin[axis]) / r)) + 2;
      spec.dims[axis] = fft_friendly_size(std::max(spec.dims[axis], needed));
    }
    spec.origin = origin;
    if (spec.voxel_count() > params.limits.max_voxels) {
      fail("voxel_size: a translation grid of ", spec.dims.transpose(), " voxels at ", r,
           " m exceeds the limit of ", params.limits.max_voxels, " voxels (max_voxels)");
    }
    return spec;
  }

  static PhaseCorrelationParams phase_params(const AlignParams& params) {
    PhaseCorrelationParams p;
    p.subvoxel = params.subvoxel;
    p.threads = params.threads;
    return p;
  }

  std::size_t linear(const Eigen::Vector3i& v) const {
    return (std::size_t(v.x()) * spec_.dims.y() + v.y()) * spec_.dims.z() + v.z();
  }

  void mark_scene_neighbourhood(const PointCloud& scene) {
    scene_near_.assign(spec_.voxel_count(), 0);
    for (Eigen::Index i = 0; i < scene.points().rows(); ++i) {
      const Eigen::Vector3i v = spec_.index_of(scene.points().row(i).transpose());
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            const Eigen::Vector3i n = v + Eigen::Vector3i(dx, dy, dz);
            if (spec_.contains(n)) scene_near_[linear(n)] = 1;
          }
    }
  }

  void move_model(const Pose& pose) {
    const Eigen::RowVector3d t = (centroid_ + pose.offset).transpose();
    moved_.noalias() = centred_ * pose.R.transpose();
    moved_.rowwise() += t;
  }

  Eigen::Vector3d rotation_step(const CorrelationValue& c) const {
    Eigen::Vector3d omega = params_.rotation_gain * c.gradient;
    if (params_.rotation_step == RotationStep::newton) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(c.hessian);
      if (eigen.eigenvalues().maxCoeff() < 0.0) {
        omega = -params_.rotation_gain * c.hessian.ldlt().solve(c.gradient);
      }
    }
    const double angle = omega.norm();
    if (angle > params_.max_rotation_step) omega *= params_.max_rotation_step / angle;
    return omega;
  }

  AlignParams params_;
  Eigen::Vector3d centroid_;
  Points centred_;
  ShCoefficients model_coefficients_;
  ShCoefficients scene_coefficients_;
  So3Correlation correlation_;
  GridSpec spec_;
  PhaseCorrelation phase_;
  VoxelGrid scene_grid_;
  double scene_energy_ = 0.0;  // sum of squares of scene_grid_, for J_t
  std::vector<std::uint8_t> scene_near_;
  std::vector<std::uint8_t> marks_;
  Points moved_;
  VoxelGrid moving_;
};

// Beyond the paper: the best rotations of the SO(3) search, each refined on the EGI
// correlation and placed by one global phase correlation, verified by their fitness;
// Algorithm 1 then polishes the best of them.
AlignResult align_from_global_search(Alignment& alignment, const Eigen::Vector3d& start_offset,
                                     const AlignParams& params) {
  So3SearchParams search;
  search.candidates = params.hypotheses;
  search.threads = params.threads;
  const auto candidates = so3_search(alignment.scene_coefficients(), alignment.model_coefficients(),
                                     params.bandwidth, search);
  RotationRefineParams refine;
  refine.newton = params.rotation_step == RotationStep::newton;
  int best = -1;
  double best_fitness = -1.0;
  Pose best_pose;
  for (std::size_t h = 0; h < candidates.size(); ++h) {
    Pose pose;
    pose.R = refine_rotation(alignment.correlation(), candidates[h].R, refine).R;
    pose.offset = start_offset;
    pose.offset += alignment.estimate_shift(pose).shift;
    const double fitness = alignment.fitness(pose);
    if (fitness > best_fitness) {
      best_fitness = fitness;
      best = static_cast<int>(h);
      best_pose = pose;
    }
  }
  AlignResult result = alignment.run(best_pose);
  result.hypothesis = best;
  return result;
}

}  // namespace

AlignResult align(const PointCloud& model, const PointCloud& scene, const AlignParams& params) {
  require_non_empty(model, "model");
  require_non_empty(scene, "scene");
  require_normals(model, "model");
  require_normals(scene, "scene");
  check_params(params);
  const Eigen::Vector3d model_centroid = model.centroid();
  if (params.global_search) {
    // The phase correlation finds the translation globally: start at the scene's centre.
    const Eigen::Vector3d start = scene.centroid();
    Alignment alignment(model, scene, params, start);
    return align_from_global_search(alignment, start - model_centroid, params);
  }
  const Transform& T = params.initial_guess;
  const Eigen::Vector3d start = T.topLeftCorner<3, 3>() * model_centroid + T.topRightCorner<3, 1>();
  Alignment alignment(model, scene, params, start);
  return alignment.run(alignment.pose_of(T));
}

}  // namespace spectral_vs
