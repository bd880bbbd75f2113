// Aligns a model point cloud onto a scene point cloud read from files, through the
// installed spectral_vs library, and prints T_scene_model: the 4x4 transform that maps
// model coordinates into the scene.
//
// The steps are those of spectral_vs.align in Python: both clouds are voxel-downsampled
// to half the alignment voxel, clouds without normals get normals fitted over twice the
// voxel size and oriented toward the sensor (its origin, from which a single view is also
// detected), then Algorithm 1 runs with a global rotation
// search. The voxel, unless given, is derived from the clouds as align() derives it.
#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/rotation/so3.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

namespace {

// Exit status: 0 when the answer is reliable (its verdict: docs/trust.md); 3 when it is not
// (the result is still printed, with the verdict that says why); 1 for an error such as an
// unreadable file; 2 for a bad command line.
constexpr int kReliable = 0;
constexpr int kError = 1;
constexpr int kUsage = 2;
constexpr int kNotReliable = 3;

void print_usage(std::FILE* out) {
  std::fprintf(out,
               "usage: align_files MODEL SCENE [options]\n"
               "\n"
               "Aligns MODEL onto SCENE (.pcd or .ply files, metres) and prints T_scene_model,\n"
               "the 4x4 transform that maps model coordinates into the scene.\n"
               "\n"
               "options:\n"
               "  --voxel-size M      voxel edge of the translation grid, metres (default:\n"
               "                      derived from the model, alignment_voxel_size)\n"
               "  --sensor-origin X Y Z  the scene's sensor: estimated normals point toward it\n"
               "                      and a single view is detected from it, metres (default\n"
               "                      0 0 0; --viewpoint is a deprecated alias)\n"
               "  --local             no global rotation search: start from the identity\n"
               "  --max-iterations N  iterations of Algorithm 1 (default 100)\n"
               "  --threads N         threads for the FFTs and the rotation search (default 1)\n"
               "  -h, --help          show this message\n"
               "\n"
               "exit status: 0 reliable, 3 not reliable (printed with its verdict), 1 error,\n"
               "2 bad arguments\n");
}

struct Options {
  std::string model_path;
  std::string scene_path;
  spectral_vs::AlignParams params;
  Eigen::Vector3d sensor_origin = Eigen::Vector3d::Zero();
  bool voxel_given = false;
};

bool parse_double(const char* text, double& value) {
  char* end = nullptr;
  value = std::strtod(text, &end);
  return end != text && *end == '\0';
}

bool parse_int(const char* text, int& value) {
  char* end = nullptr;
  const long parsed = std::strtol(text, &end, 10);
  value = static_cast<int>(parsed);
  return end != text && *end == '\0' && parsed == value;
}

// False (after a message on stderr) when the command line is not valid. Values are only
// parsed here; their ranges are checked by the library, which names the offending one.
bool parse_options(int argc, char** argv, Options& options) {
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const int values_left = argc - 1 - i;
    bool ok = true;
    if (arg == "--voxel-size" && values_left >= 1) {
      ok = parse_double(argv[++i], options.params.scene.voxel_size);
      options.voxel_given = true;
    } else if ((arg == "--sensor-origin" || arg == "--viewpoint") && values_left >= 3) {
      if (arg == "--viewpoint")
        std::fprintf(stderr, "warning: --viewpoint is deprecated: use --sensor-origin\n");
      for (int k = 0; k < 3 && ok; ++k) ok = parse_double(argv[++i], options.sensor_origin[k]);
    } else if (arg == "--local") {
      options.params.search.global_search = false;
    } else if (arg == "--max-iterations" && values_left >= 1) {
      ok = parse_int(argv[++i], options.params.local.max_iterations);
    } else if (arg == "--threads" && values_left >= 1) {
      ok = parse_int(argv[++i], options.params.threads);
    } else if (arg.rfind("-", 0) == 0) {
      std::fprintf(stderr, "align_files: unknown option or missing value: %s\n", arg.c_str());
      return false;
    } else {
      files.push_back(arg);
    }
    if (!ok) {
      std::fprintf(stderr, "align_files: %s needs a number, got '%s'\n", arg.c_str(), argv[i]);
      return false;
    }
  }
  // Checked here because the clouds are downsampled with it before `align` sees it.
  if (options.voxel_given &&
      !(options.params.scene.voxel_size > 0.0 && std::isfinite(options.params.scene.voxel_size))) {
    std::fprintf(stderr, "align_files: --voxel-size must be a positive number of metres\n");
    return false;
  }
  if (files.size() != 2) {
    std::fprintf(stderr, "align_files: expected MODEL and SCENE, got %zu file(s)\n", files.size());
    return false;
  }
  options.model_path = files[0];
  options.scene_path = files[1];
  return true;
}

// A cloud ready for `align`: downsampled to half a voxel, with normals.
spectral_vs::PointCloud prepared(const spectral_vs::PointCloud& raw,
                                 const spectral_vs::CloudFileInfo& info, const std::string& path,
                                 const Options& options, const char* role) {
  const double voxel_size = options.params.scene.voxel_size;
  const spectral_vs::PointCloud downsampled = spectral_vs::voxel_downsample(raw, voxel_size / 2);
  std::printf("%s %s: %zu points (%zu non-finite dropped), %zu after downsampling to %.1f mm, ",
              role, path.c_str(), raw.size(), info.non_finite_dropped, downsampled.size(),
              500.0 * voxel_size);
  if (downsampled.has_normals()) {
    std::printf("normals from the file\n");
    return downsampled;
  }
  std::printf("normals estimated toward (%g, %g, %g)\n", options.sensor_origin.x(),
              options.sensor_origin.y(), options.sensor_origin.z());
  spectral_vs::NormalEstimationParams normals;
  normals.radius = 2 * voxel_size;
  normals.viewpoint = options.sensor_origin;
  normals.orientation = spectral_vs::NormalOrientation::toward_viewpoint;
  normals.threads = options.params.threads;
  return spectral_vs::estimate_normals(downsampled, normals);
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      print_usage(stdout);
      return 0;
    }
  }
  Options options;
  if (!parse_options(argc, argv, options)) {
    print_usage(stderr);
    return kUsage;
  }

  try {
    spectral_vs::CloudFileInfo model_info, scene_info;
    const spectral_vs::PointCloud raw_model =
        spectral_vs::load_cloud(options.model_path, &model_info);
    const spectral_vs::PointCloud raw_scene =
        spectral_vs::load_cloud(options.scene_path, &scene_info);
    options.params.scene.sensor_origin = options.sensor_origin;
    if (!options.voxel_given)
      options.params.scene.voxel_size = spectral_vs::alignment_voxel_size(raw_model, raw_scene);
    const spectral_vs::PointCloud model =
        prepared(raw_model, model_info, options.model_path, options, "model");
    const spectral_vs::PointCloud scene =
        prepared(raw_scene, scene_info, options.scene_path, options, "scene");

    const auto start = std::chrono::steady_clock::now();
    const spectral_vs::AlignResult result = spectral_vs::align(model, scene, options.params);
    const std::chrono::duration<double, std::milli> elapsed =
        std::chrono::steady_clock::now() - start;

    std::printf("T_scene_model:\n");
    for (int r = 0; r < 4; ++r) {
      const auto& T = result.T_scene_model;
      std::printf("  %10.6f %10.6f %10.6f %10.6f\n", T(r, 0), T(r, 1), T(r, 2), T(r, 3));
    }
    // The one field to act on: reliable (confident, and no other pose fits as well).
    std::printf("verdict: %s, confidence %.3f%s\n", spectral_vs::verdict_name(result.status),
                result.confidence, result.reliable ? "" : " (not reliable)");
    for (const spectral_vs::AlignAlternative& other : result.alternatives) {
      const double turn = spectral_vs::rotation_distance(
          other.T_scene_model.topLeftCorner<3, 3>(), result.T_scene_model.topLeftCorner<3, 3>());
      std::printf("  another pose fits: %.1f deg away, confidence %.3f%s\n", turn * 180.0 / M_PI,
                  other.confidence,
                  other.symmetric ? " (the same up to the model's symmetry)" : "");
    }
    std::printf("converged: %s, iterations: %d\n", result.converged ? "yes" : "no",
                result.iterations);
    std::printf("fitness: %.3f\n", result.fitness);
    std::printf("voxel: %.1f mm, single view: %s\n", 1000.0 * result.voxel_size,
                result.single_view ? "yes" : "no");
    std::printf("time: %.1f ms\n", elapsed.count());
    return result.reliable ? kReliable : kNotReliable;
  } catch (const std::exception& error) {
    // The library reports bad input (a missing file, an empty cloud, a parameter out of
    // range) as std::invalid_argument with a message naming the argument.
    std::fprintf(stderr, "align_files: %s\n", error.what());
    return kError;
  }
}
