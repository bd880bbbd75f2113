// Runs the example program examples/align_files, built against the installed package,
// on two generated files and checks what it prints against the transform the files were
// made with. Usage: align_files_check ALIGN_FILES_EXECUTABLE WORK_DIR
//
// The model is a box with a ball on its top face, with outward normals; the scene is the
// same object moved 0.6 m in front of a sensor at the origin and seen from there: only
// the faces turned toward the sensor, with noise and without normals, as a depth camera
// gives it. The example must estimate the scene's normals toward the sensor, align, and
// print T_scene_model within 2 degrees and 4 mm (half a voxel) of the truth.
#include <spectral_vs/representation/cloud_io.hpp>

#include <Eigen/Geometry>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <string>

namespace {

using spectral_vs::Points;
using spectral_vs::Transform;

struct Run {
  int status = -1;  // exit status of the program, -1 if it did not exit normally
  std::string output;
};

// Runs a shell command; stdout and stderr are captured together.
Run run(const std::string& command) {
  Run result;
  std::FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return result;
  char buffer[4096];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) result.output.append(buffer, n);
  const int status = pclose(pipe);
  if (status != -1 && WIFEXITED(status)) result.status = WEXITSTATUS(status);
  return result;
}

std::string quoted(const std::string& text) { return "'" + text + "'"; }

// Surface samples of a 0.24 x 0.12 x 0.08 m box (in proportion to face areas) with a
// ball of radius 3 cm on its top face, and their outward normals.
void box_with_ball(std::mt19937& rng, Points& points, Points& normals) {
  const Eigen::Vector3d half(0.12, 0.06, 0.04);
  std::discrete_distribution<int> face(
      {half.y() * half.z(), half.x() * half.z(), half.x() * half.y()});
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> gaussian;
  const int box_samples = 8000, ball_samples = 3000;
  points.resize(box_samples + ball_samples, 3);
  normals.resize(box_samples + ball_samples, 3);
  Eigen::Index count = 0;
  for (int i = 0; i < box_samples; ++i, ++count) {
    const int axis = face(rng);
    Eigen::Vector3d u(uniform(rng), uniform(rng), uniform(rng));
    u[axis] = u[axis] < 0 ? -1.0 : 1.0;
    points.row(count) = half.cwiseProduct(u).transpose();
    normals.row(count) = Eigen::RowVector3d::Zero();
    normals(count, axis) = u[axis];
  }
  for (int i = 0; i < ball_samples; ++i) {
    const Eigen::Vector3d d =
        Eigen::Vector3d(gaussian(rng), gaussian(rng), gaussian(rng)).normalized();
    const Eigen::Vector3d p = Eigen::Vector3d(0.07, 0.0, 0.07) + 0.03 * d;
    if (p.z() <= half.z()) continue;  // inside the box
    points.row(count) = p.transpose();
    normals.row(count++) = d.transpose();
  }
  points.conservativeResize(count, Eigen::NoChange);
  normals.conservativeResize(count, Eigen::NoChange);
}

// The part of `T * (points, normals)` that a sensor at the origin sees: points whose
// normal faces it (exact for the box, conservative for the ball), with Gaussian noise.
Points visible_from_origin(const Points& points, const Points& normals, const Transform& T,
                           double sigma, std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, sigma);
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  Points out(points.rows(), 3);
  Eigen::Index count = 0;
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = R * points.row(i).transpose() + t;
    const Eigen::Vector3d n = R * normals.row(i).transpose();
    if (n.dot(-p.normalized()) < 0.05) continue;
    out.row(count++) = (p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))).transpose();
  }
  out.conservativeResize(count, Eigen::NoChange);
  return out;
}

// The 4 x 4 matrix printed after "T_scene_model:"; false if there is none.
bool parse_transform(const std::string& output, Transform& T) {
  const auto at = output.find("T_scene_model:");
  if (at == std::string::npos) return false;
  std::istringstream in(output.substr(at + std::string("T_scene_model:").size()));
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      if (!(in >> T(r, c))) return false;
  return true;
}

bool expect(bool condition, const char* what) {
  if (!condition) std::fprintf(stderr, "FAILED: %s\n", what);
  return condition;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: align_files_check ALIGN_FILES_EXECUTABLE WORK_DIR\n");
    return 2;
  }
  const std::string example = argv[1];
  const std::filesystem::path dir = argv[2];
  std::filesystem::create_directories(dir);
  const std::string model_path = (dir / "model.pcd").string();
  const std::string scene_path = (dir / "scene.pcd").string();

  // The model frame is the object's; the scene is a view of it 0.6 m from the sensor,
  // turned so that the ball faces the sensor.
  std::mt19937 rng(11);
  Points points, normals;
  box_with_ball(rng, points, normals);
  Transform T_true = Transform::Identity();
  T_true.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(150.0 * M_PI / 180.0, Eigen::Vector3d(0.3, -0.5, 0.8).normalized())
          .toRotationMatrix();
  T_true.topRightCorner<3, 1>() << 0.05, -0.03, 0.6;
  spectral_vs::save_cloud(model_path, spectral_vs::PointCloud(points, normals));
  spectral_vs::save_cloud(scene_path, spectral_vs::PointCloud(visible_from_origin(
                                          points, normals, T_true, 0.0005, rng)));

  bool ok = true;
  const Run usage = run(quoted(example));
  ok &= expect(usage.status == 2, "without arguments the exit status is 2");
  ok &= expect(usage.output.find("usage: align_files") != std::string::npos,
               "without arguments the usage is printed");

  const Run missing = run(quoted(example) + " " + quoted(model_path) + " no-such-file.pcd");
  ok &= expect(missing.status == 1, "a missing file gives exit status 1");
  ok &= expect(missing.output.find("no-such-file.pcd") != std::string::npos,
               "the error names the missing file");

  const Run aligned = run(quoted(example) + " " + quoted(model_path) + " " + quoted(scene_path));
  std::printf("%s", aligned.output.c_str());
  // This view hides what tells the object from it turned half a turn (at the derived
  // 13.5 mm voxel both fit it): the exit status follows the printed verdict.
  const bool reliable = aligned.output.find("verdict: reliable,") != std::string::npos;
  ok &= expect(aligned.status == (reliable ? 0 : 3), "the exit status follows the verdict");
  ok &= expect(aligned.output.find("normals estimated toward (0, 0, 0)") != std::string::npos,
               "the scene's normals are estimated toward the sensor");
  ok &= expect(aligned.output.find("verdict: ") != std::string::npos, "the verdict is printed");
  Transform T = Transform::Zero();
  if (expect(parse_transform(aligned.output, T), "T_scene_model is printed")) {
    const Eigen::Matrix3d dR = T_true.topLeftCorner<3, 3>().transpose() * T.topLeftCorner<3, 3>();
    const double degrees =
        std::acos(std::clamp((dR.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
    const double mm = 1000.0 * (T.topRightCorner<3, 1>() - T_true.topRightCorner<3, 1>()).norm();
    std::printf("error: %.2f degrees, %.2f mm\n", degrees, mm);
    ok &= expect(degrees < 2.0, "rotation error below 2 degrees");
    ok &= expect(mm < 4.0, "translation error below 4 mm");
  }
  // The sensor given by its option, and by the deprecated one, which warns: the same run.
  const std::string with_origin =
      quoted(example) + " " + quoted(model_path) + " " + quoted(scene_path);
  const Run given = run(with_origin + " --sensor-origin 0 0 0");
  Transform T_given = Transform::Zero(), T_default = Transform::Zero();
  ok &= expect(given.status == aligned.status && parse_transform(given.output, T_given) &&
                   parse_transform(aligned.output, T_default) && T_given == T_default,
               "--sensor-origin 0 0 0 gives the same T_scene_model as the default origin");
  const Run deprecated = run(with_origin + " --viewpoint 0 0 0");
  ok &= expect(deprecated.status == aligned.status &&
                   deprecated.output.find("--viewpoint is deprecated") != std::string::npos,
               "--viewpoint still works and says it is deprecated");
  // The whole object as the scene: nothing hidden, the answer is reliable (exit status 0).
  const std::string whole_path = (dir / "whole.pcd").string();
  spectral_vs::save_cloud(whole_path, spectral_vs::PointCloud(points, normals).transformed(T_true));
  const Run whole = run(quoted(example) + " " + quoted(model_path) + " " + quoted(whole_path));
  std::printf("%s", whole.output.c_str());
  Transform T_whole = Transform::Zero();
  ok &= expect(whole.status == 0 && whole.output.find("verdict: reliable,") != std::string::npos,
               "the whole object: reliable (exit status 0)");
  ok &= expect(parse_transform(whole.output, T_whole) &&
                   (T_whole.topRightCorner<3, 1>() - T_true.topRightCorner<3, 1>()).norm() < 0.004,
               "the whole object: within 4 mm");
  // The wrong scale (a voxel ten times the object, 1.5 m): the answer is printed with a
  // verdict that is not reliable, and the exit status is 3.
  const Run coarse = run(with_origin + " --voxel-size 1.5");
  ok &= expect(coarse.status == 3, "a voxel ten times the object: not reliable (exit status 3)");
  ok &= expect(coarse.output.find("(not reliable)") != std::string::npos &&
                   coarse.output.find("T_scene_model:") != std::string::npos,
               "an unreliable answer is printed and says it is not reliable");
  return ok ? 0 : 1;
}
