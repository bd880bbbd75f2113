#pragma once
// What the fuzz targets share: the input written to a file (the readers take paths) and
// a failure that libFuzzer records as a crash, with the reason printed.

#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/point_cloud.hpp>

#include <unistd.h>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

namespace spectral_vs::fuzz {

/// Prints why and aborts: libFuzzer saves the input as a crash.
[[noreturn]] inline void fail(const std::string& why) {
  std::fprintf(stderr, "fuzz target failed: %s\n", why.c_str());
  std::fflush(stderr);
  std::abort();
}

inline void check(bool ok, const std::string& why) {
  if (!ok) fail(why);
}

/// A file of this process (libFuzzer's -jobs run several) holding `data`, rewritten for
/// every input and removed at exit.
inline const std::string& input_file(const uint8_t* data, size_t size, const char* extension) {
  static const std::string path = (std::filesystem::temp_directory_path() /
                                   ("spectral_vs_fuzz_" + std::to_string(::getpid()) + extension))
                                      .string();
  static const bool registered = [] {
    std::atexit([] { std::remove(path.c_str()); });
    return true;
  }();
  (void)registered;
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

/// The documented state of every loaded cloud: finite points, unit normals if any.
inline void check_cloud(const PointCloud& cloud) {
  check(cloud.points().allFinite(), "a loaded cloud has a non-finite point");
  if (cloud.has_normals()) {
    check(cloud.normals().allFinite(), "a loaded cloud has a non-finite normal");
    for (Eigen::Index i = 0; i < cloud.normals().rows(); ++i) {
      const double norm = cloud.normals().row(i).norm();
      check(std::abs(norm - 1.0) < 1e-6, "a loaded normal is not unit length");
    }
  }
}

/// One input of a cloud reader's target (`extension` picks the reader): a bad file is
/// std::invalid_argument; a file that loads gives finite points, unit normals and counts
/// that add up, for load_cloud and load_points alike.
inline void check_reader(const uint8_t* data, size_t size, const char* extension) {
  const std::string& path = input_file(data, size, extension);
  try {
    CloudFileInfo info;
    const PointCloud cloud = load_cloud(path, &info);
    check_cloud(cloud);
    check(cloud.size() > 0, "load_cloud returned an empty cloud");
    check(info.points_in_file == info.width * info.height, "points_in_file != width * height");
    check(cloud.size() + info.non_finite_dropped == info.points_in_file,
          "kept + dropped points != points in the file");
    check(info.had_normals == cloud.has_normals(), "had_normals disagrees with the cloud");
  } catch (const std::invalid_argument&) {
  }
  try {
    CloudFileInfo info;
    const Points points = load_points(path, &info);
    check(std::size_t(points.rows()) == info.points_in_file, "load_points: row count");
    check(points.array().isFinite().rowwise().all().any(), "load_points: no finite point");
  } catch (const std::invalid_argument&) {
  }
}

}  // namespace spectral_vs::fuzz
