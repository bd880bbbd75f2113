#include <spectral_vs/representation/cloud_io.hpp>

#include "common/checks.hpp"

#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace spectral_vs {

using detail::fail;

namespace {

enum class Format { pcd, ply };

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

Format format_from_extension(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".pcd") return Format::pcd;
  if (ext == ".ply") return Format::ply;
  fail("path: unsupported extension '", ext, "' of ", path, " (supported: .pcd, .ply)");
}

// PCL's readers print to stderr and may misbehave on a file that is not a point
// cloud, so the header is checked here first.
void check_header(const std::string& path, Format format) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    fail("path: no such file: ", path);
  }
  std::ifstream file(path, std::ios::binary);
  if (!file) {
    fail("path: cannot open ", path);
  }
  std::string line;
  if (format == Format::ply) {
    std::getline(file, line);
    if (line.rfind("ply", 0) != 0) {
      fail("path: ", path, " is not a PLY file (first line is not 'ply')");
    }
    return;
  }
  for (int lines = 0; lines < 64 && std::getline(file, line); ++lines) {
    if (line.empty() || line[0] == '#') continue;
    if (line.rfind("VERSION", 0) == 0 || line.rfind("FIELDS", 0) == 0) return;
    break;
  }
  fail("path: ", path, " is not a PCD file (no VERSION or FIELDS header line)");
}

const pcl::PCLPointField* find_field(const pcl::PCLPointCloud2& cloud, const char* name) {
  for (const auto& field : cloud.fields) {
    if (field.name == name) return &field;
  }
  return nullptr;
}

double read_value(const std::uint8_t* at, std::uint8_t datatype) {
  auto read = [at](auto typed) {
    std::memcpy(&typed, at, sizeof(typed));
    return static_cast<double>(typed);
  };
  switch (datatype) {
    case pcl::PCLPointField::FLOAT32: return read(float{});
    case pcl::PCLPointField::FLOAT64: return read(double{});
    case pcl::PCLPointField::INT8: return read(std::int8_t{});
    case pcl::PCLPointField::UINT8: return read(std::uint8_t{});
    case pcl::PCLPointField::INT16: return read(std::int16_t{});
    case pcl::PCLPointField::UINT16: return read(std::uint16_t{});
    case pcl::PCLPointField::INT32: return read(std::int32_t{});
    case pcl::PCLPointField::UINT32: return read(std::uint32_t{});
    default: fail("point field of unsupported data type ", int(datatype));
  }
}

std::size_t field_size(std::uint8_t datatype) {
  switch (datatype) {
    case pcl::PCLPointField::FLOAT64: return 8;
    case pcl::PCLPointField::INT16:
    case pcl::PCLPointField::UINT16: return 2;
    case pcl::PCLPointField::INT8:
    case pcl::PCLPointField::UINT8: return 1;
    default: return 4;
  }
}

Points extract(const pcl::PCLPointCloud2& cloud, const pcl::PCLPointField* fields[3],
               const std::string& path) {
  const std::size_t rows = cloud.height;
  const std::size_t cols = cloud.width;
  for (int axis = 0; axis < 3; ++axis) {
    if (fields[axis]->offset + field_size(fields[axis]->datatype) > cloud.point_step) {
      fail("path: ", path, " has a field beyond the point size");
    }
  }
  if (cloud.row_step < cols * cloud.point_step || cloud.data.size() < rows * cloud.row_step) {
    fail("path: ", path, " is truncated: ", cloud.data.size(), " bytes of data for ", rows * cols,
         " points");
  }
  Points out(static_cast<Eigen::Index>(rows * cols), 3);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const std::uint8_t* point = cloud.data.data() + r * cloud.row_step + c * cloud.point_step;
      const auto index = static_cast<Eigen::Index>(r * cols + c);
      for (int axis = 0; axis < 3; ++axis) {
        out(index, axis) = read_value(point + fields[axis]->offset, fields[axis]->datatype);
      }
    }
  }
  return out;
}

}  // namespace

PointCloud load_cloud(const std::string& path, CloudFileInfo* info) {
  const Format format = format_from_extension(path);
  check_header(path, format);
  pcl::PCLPointCloud2 cloud;
  int status = -1;
  try {
    if (format == Format::pcd) {
      pcl::PCDReader reader;
      status = reader.read(path, cloud);
    } else {
      pcl::PLYReader reader;
      status = reader.read(path, cloud);
    }
  } catch (const std::exception& error) {
    fail("path: cannot read ", path, ": ", error.what());
  }
  if (status < 0) {
    fail("path: ", path, " could not be parsed as a point cloud");
  }
  const pcl::PCLPointField* xyz[3] = {find_field(cloud, "x"), find_field(cloud, "y"),
                                      find_field(cloud, "z")};
  if (!xyz[0] || !xyz[1] || !xyz[2]) {
    fail("path: ", path, " has no x, y, z fields");
  }
  Points points = extract(cloud, xyz, path);
  const pcl::PCLPointField* normal[3] = {find_field(cloud, "normal_x"),
                                         find_field(cloud, "normal_y"),
                                         find_field(cloud, "normal_z")};
  const bool had_normals = normal[0] && normal[1] && normal[2];
  Points normals = had_normals ? extract(cloud, normal, path) : Points();

  CloudFileInfo file_info;
  file_info.width = cloud.width;
  file_info.height = cloud.height;
  file_info.points_in_file = static_cast<std::size_t>(points.rows());
  file_info.had_normals = had_normals;
  file_info.non_finite_dropped = remove_non_finite(points, had_normals ? &normals : nullptr);
  if (points.rows() == 0) {
    fail("path: ", path, " holds no finite point (", file_info.points_in_file, " in the file)");
  }
  if (info) *info = file_info;
  return PointCloud(std::move(points), std::move(normals));
}

void save_cloud(const std::string& path, const PointCloud& cloud, PcdEncoding encoding) {
  const Format format = format_from_extension(path);
  require_non_empty(cloud, "cloud");
  pcl::PCLPointCloud2 message;
  if (cloud.has_normals()) {
    pcl::PointCloud<pcl::PointNormal> pcl_cloud;
    pcl_cloud.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      auto& p = pcl_cloud[i];
      p.getVector3fMap() = cloud.points().row(Eigen::Index(i)).transpose().cast<float>();
      p.getNormalVector3fMap() = cloud.normals().row(Eigen::Index(i)).transpose().cast<float>();
      p.curvature = 0.0f;
    }
    pcl::toPCLPointCloud2(pcl_cloud, message);
  } else {
    pcl::PointCloud<pcl::PointXYZ> pcl_cloud;
    pcl_cloud.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      pcl_cloud[i].getVector3fMap() = cloud.points().row(Eigen::Index(i)).transpose().cast<float>();
    }
    pcl::toPCLPointCloud2(pcl_cloud, message);
  }
  int status = -1;
  try {
    if (format == Format::ply) {
      pcl::PLYWriter writer;
      status = writer.writeBinary(path, message);
    } else {
      pcl::PCDWriter writer;
      switch (encoding) {
        case PcdEncoding::ascii: status = writer.writeASCII(path, message); break;
        case PcdEncoding::binary: status = writer.writeBinary(path, message); break;
        case PcdEncoding::binary_compressed:
          status = writer.writeBinaryCompressed(path, message);
          break;
      }
    }
  } catch (const std::exception& error) {
    fail("path: cannot write ", path, ": ", error.what());
  }
  if (status < 0) {
    fail("path: cannot write ", path);
  }
}

}  // namespace spectral_vs
