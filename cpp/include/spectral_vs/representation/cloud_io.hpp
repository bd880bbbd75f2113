#pragma once
/// @file cloud_io.hpp
/// Reading and writing point clouds in PCD and PLY through PCL.

#include <spectral_vs/representation/point_cloud.hpp>

#include <cstddef>
#include <string>

namespace spectral_vs {

/// What a file held before it became a `PointCloud`.
struct CloudFileInfo {
  std::size_t width = 0;               ///< Columns of an organized cloud (points if unorganized).
  std::size_t height = 0;              ///< Rows of an organized cloud (1 if unorganized).
  std::size_t points_in_file = 0;      ///< width * height.
  std::size_t non_finite_dropped = 0;  ///< Points dropped for NaN/inf coordinates or normals.
  bool had_normals = false;            ///< The file has normal_x/normal_y/normal_z fields.
};

/// Encoding used by `save_cloud` for PCD files (PLY is always written binary).
enum class PcdEncoding { ascii, binary, binary_compressed };

/// Loads a `.pcd` or `.ply` file. Organized clouds are flattened; points with a
/// non-finite coordinate (or normal) are dropped and counted in `info`.
/// @throws std::invalid_argument if the file is missing, is not a point cloud, has
///         no x/y/z fields, or holds no finite point.
PointCloud load_cloud(const std::string& path, CloudFileInfo* info = nullptr);

/// The points of a `.pcd` or `.ply` file in the file's order, non-finite ones kept (NaN
/// where a depth camera had no return): row `v * info.width + u` of an organized cloud is
/// its pixel (row v, column u). Normals are not read; `info.non_finite_dropped` is 0.
/// @throws std::invalid_argument as `load_cloud`.
Points load_points(const std::string& path, CloudFileInfo* info = nullptr);

/// Saves to `.pcd` or `.ply` (chosen by extension) as float32 fields x y z
/// [normal_x normal_y normal_z]: the layout other point cloud tools read.
/// @throws std::invalid_argument for an unknown extension or an unwritable path.
void save_cloud(const std::string& path, const PointCloud& cloud,
                PcdEncoding encoding = PcdEncoding::binary_compressed);

}  // namespace spectral_vs
