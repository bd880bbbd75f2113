// align() on small random clouds with random settings inside their documented ranges.
// The input chooses the clouds' shapes (a blob, a box, a sphere, a plane, a line,
// coincident points, one point), sizes, offsets and noise, and every setting of
// AlignParams. No exception may escape for such input, and the result must be what
// docs/reliability.md promises: a finite rigid pose, fitness in [0, 1], finite history.

#include <spectral_vs/alignment/aligner.hpp>

#include "fuzz_support.hpp"

#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <exception>
#include <stdexcept>
#include <string>
#include <random>

namespace {

using namespace spectral_vs;

PointCloud random_cloud(FuzzedDataProvider& in) {
  const int shape = in.ConsumeIntegralInRange(0, 6);
  const int n = shape == 6 ? 1 : in.ConsumeIntegralInRange(1, 400);
  const double size = in.ConsumeFloatingPointInRange(0.005, 0.3);  // metres
  const Eigen::Vector3d offset(in.ConsumeFloatingPointInRange(-0.2, 0.2),
                               in.ConsumeFloatingPointInRange(-0.2, 0.2),
                               in.ConsumeFloatingPointInRange(-0.2, 0.2));
  const double noise = in.ConsumeBool() ? in.ConsumeFloatingPointInRange(0.0, 0.005) : 0.0;
  std::mt19937 rng(in.ConsumeIntegral<uint32_t>());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  Points p(n, 3), normals(n, 3);
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d x, normal;
    switch (shape) {
      case 0:  // a blob, normals anywhere
        x = Eigen::Vector3d(u(rng), u(rng), u(rng));
        normal = Eigen::Vector3d(g(rng), g(rng), g(rng));
        break;
      case 1: {  // a box's faces
        const int axis = std::uniform_int_distribution<int>(0, 2)(rng);
        x = Eigen::Vector3d(u(rng), 0.5 * u(rng), 0.3 * u(rng));
        x[axis] = x[axis] < 0 ? -1.0 : 1.0;
        normal = Eigen::Vector3d::Zero();
        normal[axis] = x[axis];
        break;
      }
      case 2:  // a sphere
        normal = Eigen::Vector3d(g(rng), g(rng), g(rng));
        x = normal.normalized();
        break;
      case 3:  // a plane
        x = Eigen::Vector3d(u(rng), u(rng), 0.0);
        normal = Eigen::Vector3d::UnitZ();
        break;
      case 4:  // a line
        x = Eigen::Vector3d(u(rng), 0.0, 0.0);
        normal = Eigen::Vector3d(0.0, g(rng), g(rng));
        break;
      default:  // coincident points, one point
        x = Eigen::Vector3d::Zero();
        normal = Eigen::Vector3d(0.3, -0.2, 1.0);
        break;
    }
    if (!(normal.norm() > 1e-6)) normal = Eigen::Vector3d::UnitX();
    p.row(i) =
        (offset + 0.5 * size * x + noise * Eigen::Vector3d(g(rng), g(rng), g(rng))).transpose();
    normals.row(i) = normal.normalized().transpose();
  }
  return PointCloud(p, normals);
}

Transform random_pose(FuzzedDataProvider& in) {
  Eigen::Quaterniond q(
      in.ConsumeFloatingPointInRange(-1.0, 1.0), in.ConsumeFloatingPointInRange(-1.0, 1.0),
      in.ConsumeFloatingPointInRange(-1.0, 1.0), in.ConsumeFloatingPointInRange(-1.0, 1.0));
  if (q.norm() < 1e-3) q = Eigen::Quaterniond::Identity();
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix();
  for (int k = 0; k < 3; ++k) T(k, 3) = in.ConsumeFloatingPointInRange(-0.1, 0.1);
  return T;
}

AlignParams random_params(FuzzedDataProvider& in) {
  AlignParams p;
  p.scene.voxel_size = in.ConsumeFloatingPointInRange(0.004, 0.03);
  p.scene.bandwidth = in.ConsumeIntegralInRange(2, 16);
  p.local.translation_gain = in.ConsumeFloatingPointInRange(0.05, 1.0);
  p.local.rotation_step = in.ConsumeBool() ? RotationStep::newton : RotationStep::gradient;
  p.local.rotation_gain = in.ConsumeFloatingPointInRange(
      0.05, p.local.rotation_step == RotationStep::newton ? 1.0 : 2.0);
  p.local.max_rotation_step = in.ConsumeFloatingPointInRange(0.01, 1.0);
  p.local.tolerance = in.ConsumeFloatingPointInRange(1e-4, 0.2);
  p.local.max_iterations = in.ConsumeIntegralInRange(1, 30);
  p.refinement.refinement_iterations = in.ConsumeIntegralInRange(1, 20);
  p.search.global_search = in.ConsumeBool();
  p.search.hypotheses = in.ConsumeIntegralInRange(1, 12);
  p.search.refinements = in.ConsumeIntegralInRange(1, p.search.hypotheses);
  if (in.ConsumeBool())
    p.search.search_voxel_size = in.ConsumeFloatingPointInRange(p.scene.voxel_size, 0.05);
  if (in.ConsumeBool()) p.search.window_margin = in.ConsumeFloatingPointInRange(0.001, 0.1);
  if (in.ConsumeBool()) p.local.max_translation = in.ConsumeFloatingPointInRange(0.001, 0.2);
  if (in.ConsumeBool()) {
    p.scene.sensor_origin = Eigen::Vector3d(in.ConsumeFloatingPointInRange(-1.0, 1.0),
                                            in.ConsumeFloatingPointInRange(-1.0, 1.0),
                                            in.ConsumeFloatingPointInRange(-1.0, 1.0));
    p.scene.scene_view = SceneView::single_view;
  }
  p.scene.suppress_support_plane = in.ConsumeBool();
  p.refinement.polish = in.ConsumeBool();
  p.refinement.icp_refinement = in.ConsumeBool();
  p.local.subvoxel = in.ConsumeBool();
  const Occupancy occupancies[] = {Occupancy::binary, Occupancy::count, Occupancy::trilinear};
  p.scene.occupancy = occupancies[in.ConsumeIntegralInRange(0, 2)];
  p.scene.egi_method = in.ConsumeBool() ? EgiMethod::projection : EgiMethod::histogram;
  p.threads = in.ConsumeIntegralInRange(1, 2);
  if (in.ConsumeBool()) p.initial_guess = random_pose(in);
  return p;
}

void check_result(const AlignResult& r) {
  using fuzz::check;
  const Transform& T = r.T_scene_model;
  check(T.allFinite(), "non-finite pose");
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  check((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6 &&
            std::abs(R.determinant() - 1.0) < 1e-6,
        "the pose is not a rotation");
  check(T.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)), "the pose's last row");
  check(r.fitness >= 0.0 && r.fitness <= 1.0, "fitness outside [0, 1]");
  check(std::isfinite(r.correlation), "non-finite correlation");
  check(std::isfinite(r.translation_peak), "non-finite translation peak");
  check(r.iterations >= 0, "negative iterations");
  for (const AlignIteration& it : r.history) {
    check(std::isfinite(it.translation_cost) && std::isfinite(it.rotation_cost) &&
              std::isfinite(it.translation_step) && std::isfinite(it.rotation_gradient) &&
              std::isfinite(it.correlation) && std::isfinite(it.translation_peak),
          "non-finite history entry");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  const PointCloud model = random_cloud(in);
  const bool moved_copy = in.ConsumeBool();
  const Transform motion = random_pose(in);
  const PointCloud scene = moved_copy ? model.transformed(motion) : random_cloud(in);
  const AlignParams params = random_params(in);
  try {
    check_result(align(model, scene, params));
  } catch (const std::invalid_argument& error) {
    // A guess that moves the model off the scene's grid is refused by contract, naming it.
    const std::string message = error.what();
    if (message.rfind("initial_guess:", 0) != 0)
      fuzz::fail(std::string("align threw for documented input: ") + message);
  } catch (const std::exception& error) {
    fuzz::fail(std::string("align threw for documented input: ") + error.what());
  }
  return 0;
}
