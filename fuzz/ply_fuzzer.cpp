// The PLY reader on any bytes: ascii and binary (little and big endian) files, with and
// without normals (the seeds hold each). A bad file is std::invalid_argument; a file that
// loads gives finite points, unit normals and counts that add up.

#include <spectral_vs/representation/cloud_io.hpp>

#include "fuzz_support.hpp"

#include <stdexcept>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace spectral_vs;
  const std::string& path = fuzz::input_file(data, size, ".ply");
  try {
    CloudFileInfo info;
    const PointCloud cloud = load_cloud(path, &info);
    fuzz::check_cloud(cloud);
    fuzz::check(cloud.size() > 0, "load_cloud returned an empty cloud");
    fuzz::check(info.points_in_file == info.width * info.height,
                "points_in_file != width * height");
    fuzz::check(cloud.size() + info.non_finite_dropped == info.points_in_file,
                "kept + dropped points != points in the file");
    fuzz::check(info.had_normals == cloud.has_normals(), "had_normals disagrees with the cloud");
  } catch (const std::invalid_argument&) {
  }
  try {
    CloudFileInfo info;
    const Points points = load_points(path, &info);
    fuzz::check(std::size_t(points.rows()) == info.points_in_file, "load_points: row count");
    fuzz::check(points.array().isFinite().rowwise().all().any(), "load_points: no finite point");
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
