// Adversarial input to every public entry point of the C++ API, as one table. Each row
// names a call and its documented behaviour (docs/reliability.md): either
// std::invalid_argument with a message naming the argument or the limit (the fragment
// of the row), or a normal return whose result the row checks (finite, converged = false,
// ...). A row is one line to add; the table runs again under the sanitizers
// (make test-sanitize), where a read out of bounds or an undefined conversion aborts.
#include <spectral_vs/alignment/aligner.hpp>
#include <spectral_vs/kinematics/kinematics.hpp>
#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/egi.hpp>
#include <spectral_vs/representation/organized.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>
#include <spectral_vs/rotation/egi_coefficients.hpp>
#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_search.hpp>
#include <spectral_vs/rotation/spherical_harmonics.hpp>
#include <spectral_vs/rotation/wigner.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace spectral_vs {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// --- Inputs -------------------------------------------------------------------------

// The asymmetric 0.25 m box-and-sphere object, 2000 points with normals.
const PointCloud& object() {
  static const PointCloud cloud = [] {
    std::mt19937 rng(7);
    return test::box_and_sphere(2000, rng);
  }();
  return cloud;
}

Transform pose(double angle_deg, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  Transform T = Transform::Identity();
  T.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(angle_deg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = t;
  return T;
}

PointCloud repeated(const Eigen::RowVector3d& point, const Eigen::RowVector3d& normal, int count) {
  return PointCloud(Points(point.replicate(count, 1)), Points(normal.replicate(count, 1)));
}

PointCloud collinear(int count) {
  Points p = Points::Zero(count, 3);
  for (int i = 0; i < count; ++i) p(i, 0) = 0.001 * i;
  return PointCloud(p);
}

PointCloud coplanar(int count, bool with_normals) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  Points p(count, 3), n(count, 3);
  for (int i = 0; i < count; ++i) {
    p.row(i) << u(rng), u(rng), 0.0;
    n.row(i) << 0.0, 0.0, 1.0;
  }
  return with_normals ? PointCloud(p, n) : PointCloud(p);
}

Points rows(std::initializer_list<Eigen::RowVector3d> list);

Points three_points() { return rows({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}); }

Points rows(std::initializer_list<Eigen::RowVector3d> list) {
  Points out(Eigen::Index(list.size()), 3);
  Eigen::Index i = 0;
  for (const auto& row : list) out.row(i++) = row;
  return out;
}

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("spectral_vs_adversarial_" + name)).string();
}

constexpr const char* kPlyHead = "ply\nformat ascii 1.0\n";

std::string write_file(const std::string& name, const std::string& bytes) {
  const std::string path = temp_path(name);
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

// A valid file of `object()` in the given encoding, as bytes.
std::string saved(const std::string& name, PcdEncoding encoding = PcdEncoding::binary) {
  const std::string path = temp_path(name);
  save_cloud(path, object(), encoding);
  return read_bytes(path);
}

const char* kHeader =
    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
    "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n";

// An ASCII PLY of 3 vertices on a 2 x 2 lattice whose range_grid lines are `grid`.
std::string organized_ply(const std::string& grid) {
  return "ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\nelement vertex 3\n"
         "property float x\nproperty float y\nproperty float z\nelement range_grid 4\n"
         "property list uchar int vertex_indices\nend_header\n0 0 1\n0.1 0 1\n0 0.1 1\n" +
         grid;
}

std::string urdf_text() { return read_bytes(SPECTRAL_VS_TEST_URDF); }

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

Kinematics arm() { return Kinematics(SPECTRAL_VS_TEST_URDF, "base_link", "tool"); }

AlignParams fast() {
  AlignParams p;
  p.search.hypotheses = 4;
  p.search.refinements = 1;
  return p;
}

AlignParams with(std::function<void(AlignParams&)> change) {
  AlignParams p = fast();
  change(p);
  return p;
}

VoxelGrid grid_of(const PointCloud& cloud, const GridSpec& spec) { return voxelize(cloud, spec); }

GridSpec spec_of(int n, double resolution = 0.01) {
  GridSpec spec;
  spec.origin = Eigen::Vector3d::Constant(-0.5 * n * resolution);
  spec.resolution = resolution;
  spec.dims = Eigen::Vector3i::Constant(n);
  return spec;
}

ShCoefficients coefficients(int bandwidth) { return egi_coefficients(object(), bandwidth); }

// --- Checks of a normal return --------------------------------------------------------

void expect_finite(const AlignResult& r) {
  EXPECT_TRUE(r.T_scene_model.allFinite());
  EXPECT_TRUE(std::isfinite(r.fitness) && r.fitness >= 0.0 && r.fitness <= 1.0) << r.fitness;
  EXPECT_TRUE(std::isfinite(r.correlation));
  for (const auto& i : r.history) EXPECT_TRUE(i.T_scene_model.allFinite());
}

// A degenerate input has a defined answer, and its verdict says it is not to be acted on.
void expect_unreliable(const AlignResult& r) {
  expect_finite(r);
  EXPECT_FALSE(r.reliable) << verdict_name(r.status);
}

double rotation_error_deg(const Transform& a, const Transform& b) {
  return rotation_distance(a.topLeftCorner<3, 3>(), b.topLeftCorner<3, 3>()) * 180.0 / M_PI;
}

// --- The table ------------------------------------------------------------------------

struct Case {
  std::string name;            // letters, digits and underscores (a test name)
  std::function<void()> call;  // the call, with its checks when it returns
  std::string error;           // non-empty: std::invalid_argument whose message has this
};

std::vector<Case> cases() {
  std::vector<Case> c = {
      // PointCloud construction: the invariant "finite points, unit normals" holds.
      {"cloud_nan_point",
       [] {
         PointCloud(rows({{0, 0, 0}, {kNaN, 0, 0}}));
       },
       "points: row 1 is not finite"},
      {"cloud_inf_point",
       [] {
         PointCloud(rows({{kInf, 0, 0}}));
       },
       "points: row 0 is not finite"},
      {"cloud_nan_normal",
       [] {
         PointCloud(three_points(), rows({{0, 0, 1}, {0, kNaN, 1}, {0, 0, 1}}));
       },
       "normals: row 1 is not finite or has zero length"},
      {"cloud_zero_normal",
       [] {
         PointCloud(three_points(), rows({{0, 0, 1}, {0, 0, 0}, {0, 0, 1}}));
       },
       "normals: row 1 is not finite or has zero length"},
      {"cloud_normal_rows",
       [] {
         PointCloud(three_points(), rows({{0, 0, 1}}));
       },
       "normals: expected 3 rows"},
      {"cloud_transformed_nan", [] { object().transformed(Transform::Constant(kNaN)); },
       "T_target_source"},
      {"cloud_empty_centroid", [] { PointCloud().centroid(); }, "cloud is empty"},
      {"remove_non_finite_rows",
       [] {
         Points p = rows({{0, 0, 0}, {kNaN, 0, 0}, {1, 1, 1}});
         Points n = rows({{0, 0, 1}, {0, 0, 1}, {0, 0, 0}});
         EXPECT_EQ(remove_non_finite(p, &n), 2u);
         EXPECT_EQ(p.rows(), 1);
       },
       ""},
      {"rigid_reflection",
       [] {
         require_rigid_transform(Eigen::Vector4d(1, 1, -1, 1).asDiagonal().toDenseMatrix(), "T");
       },
       "T is not a rigid transform"},

      // Files.
      {"load_missing", [] { load_cloud(temp_path("missing.pcd")); }, "no such file"},
      {"load_folder", [] { load_cloud(std::filesystem::temp_directory_path().string() + "/"); },
       "extension"},
      {"load_unknown_extension", [] { load_cloud(write_file("cloud.xyz", "0 0 0\n")); },
       "unsupported extension"},
      {"load_empty_pcd", [] { load_cloud(write_file("empty.pcd", "")); }, "is not a PCD file"},
      {"load_empty_ply", [] { load_cloud(write_file("empty.ply", "")); }, "is not a PLY file"},
      {"load_text_as_pcd", [] { load_cloud(write_file("text.pcd", "hello\nworld\n")); },
       "is not a PCD file"},
      {"load_header_only", [] { load_cloud(write_file("header_only.pcd", std::string(kHeader))); },
       "is truncated: 0 of 2 points"},
      {"load_ascii_words",
       [] { load_cloud(write_file("words.pcd", std::string(kHeader) + "a b c\n1 2 3\n")); },
       "is not a decimal number"},
      // PCL reads a prefix of an ASCII value it cannot parse and wraps one out of range.
      {"load_ascii_hexadecimal_float",
       [] { load_cloud(write_file("hex.pcd", std::string(kHeader) + "0x1p3 2 3\n1 2 3\n")); },
       "line 11: point 0, field 'x' (TYPE F SIZE 4): '0x1p3' is not a decimal number"},
      {"load_ascii_exponent_in_integer_field",
       [] {
         const std::string header = replaced(kHeader, "TYPE F F F", "TYPE I F F");
         load_cloud(write_file("exponent.pcd", header + "1e3 2 3\n1 2 3\n"));
       },
       "'1e3' is not an integer"},
      {"load_ascii_unsigned_overflow",
       [] {
         const std::string header =
             replaced(replaced(kHeader, "TYPE F F F", "TYPE U F F"), "SIZE 4 4 4", "SIZE 2 4 4");
         load_cloud(write_file("wrap.pcd", header + "1 2 3\n70000 2 3\n"));
       },
       "'70000' is outside [0, 65535] of a 2-byte unsigned integer"},
      {"load_ascii_white_space_line",
       [] { load_cloud(write_file("blank.pcd", std::string(kHeader) + "1 2 3\n \n1 2 3\n")); },
       "line 12: point 1 has 0 values"},
      {"load_ascii_short_line",
       [] { load_cloud(write_file("short.pcd", std::string(kHeader) + "1 2\n1 2 3\n")); },
       "has 2 values"},
      {"load_ascii_invalid_utf8",
       [] {
         try {
           load_cloud(write_file("utf8.pcd", std::string(kHeader) + "1 2 \xff\xfe\n1 2 3\n"));
         } catch (const std::invalid_argument& e) {
           for (const char ch : std::string(e.what())) EXPECT_TRUE(ch >= 32 && ch < 127) << int(ch);
           throw;
         }
       },
       "'?"
       "?' is not a decimal number"},  // split: "??'" would be a trigraph
      // Found by fuzz/pcd_fuzzer: PCL's header reader reads on past DATA and took binary
      // data spelling "COLUMNS" for a FIELDS line, then crashed reading the data.
      {"load_binary_data_spelling_a_header_line",
       [] {
         std::string data = "COLUMNS\xca\xb6\xca\xff\xff\xff\xff\xff";
         data.resize(2 * 12, '\0');
         load_cloud(
             write_file("columns.pcd", replaced(kHeader, "DATA ascii", "DATA binary") + data));
       },
       "the data after the DATA line begins with 'COLUMNS"},
      {"load_binary_data_after_an_empty_line_spelling_a_header_line",
       [] {
         std::string data = "\nPOINTS 9\n";
         data.resize(2 * 12, '\0');
         load_cloud(
             write_file("points.pcd", replaced(kHeader, "DATA ascii", "DATA binary") + data));
       },
       "the data after the DATA line begins with 'POINTS'"},
      {"load_width_height_mismatch",
       [] {
         load_cloud(
             write_file("wh.pcd", replaced(kHeader, "HEIGHT 1", "HEIGHT 2") + "1 2 3\n1 2 3\n"));
       },
       "WIDTH x HEIGHT = 2 x 2 but POINTS = 2"},
      {"load_negative_width",
       [] { load_cloud(write_file("neg.pcd", replaced(kHeader, "WIDTH 2", "WIDTH -2"))); },
       "WIDTH must be a count"},
      {"load_bad_field_size",
       [] { load_cloud(write_file("size.pcd", replaced(kHeader, "SIZE 4 4 4", "SIZE 3 4 4"))); },
       "has TYPE 'F' and SIZE '3'"},
      {"load_huge_count",
       [] {
         load_cloud(
             write_file("count.pcd", replaced(kHeader, "COUNT 1 1 1", "COUNT 1 1 100000000")));
       },
       "has COUNT"},
      {"load_unknown_header_line",
       [] {
         load_cloud(write_file("line.pcd", replaced(kHeader, "VERSION 0.7\n", "VERSION 0\n7\n")));
       },
       "unknown header line '7'"},
      {"load_no_data_line",
       [] { load_cloud(write_file("nodata.pcd", "VERSION 0.7\nFIELDS x y z\n")); },
       "the header ends without a DATA line"},
      {"load_no_xyz",
       [] {
         load_cloud(write_file(
             "abc.pcd", replaced(kHeader, "FIELDS x y z", "FIELDS a b c") + "1 2 3\n1 2 3\n"));
       },
       "has no x, y, z fields"},
      {"load_all_nan",
       [] { load_cloud(write_file("nan.pcd", std::string(kHeader) + "nan nan nan\ninf 0 0\n")); },
       "holds no finite point (2 in the file)"},
      {"load_some_nan",
       [] {
         CloudFileInfo info;
         const PointCloud cloud = load_cloud(
             write_file("somenan.pcd", std::string(kHeader) + "nan 0 0\n1 2 3\n"), &info);
         EXPECT_EQ(cloud.size(), 1u);
         EXPECT_EQ(info.non_finite_dropped, 1u);
       },
       ""},
      {"load_truncated_binary",
       [] {
         const std::string bytes = saved("b.pcd");
         load_cloud(write_file("trunc_b.pcd", bytes.substr(0, bytes.size() / 2)));
       },
       "is truncated"},
      {"load_truncated_compressed",
       [] {
         const std::string bytes = saved("c.pcd", PcdEncoding::binary_compressed);
         load_cloud(write_file("trunc_c.pcd", bytes.substr(0, bytes.size() / 2)));
       },
       "is truncated"},
      {"load_inflated_compressed_count",  // crashed PCL's reader before the check
       [] {
         std::string bytes = saved("c2.pcd", PcdEncoding::binary_compressed);
         bytes = replaced(replaced(bytes, "WIDTH 2000", "WIDTH 2000000"), "POINTS 2000",
                          "POINTS 2000000");
         load_cloud(write_file("inflated.pcd", bytes));
       },
       "the compressed block holds"},
      {"load_garbage_after_version",  // crashed PCL's reader before the check
       [] {
         std::string bytes = "VERSION 0.7\n";
         for (int i = 0; i < 512; ++i) bytes += char((i * 7919) % 251 + 1);
         load_cloud(write_file("garbage.pcd", bytes));
       },
       "is not a valid PCD file"},
      {"load_truncated_ply",
       [] {
         save_cloud(temp_path("p.ply"), object());
         const std::string bytes = read_bytes(temp_path("p.ply"));
         load_cloud(write_file("trunc.ply", bytes.substr(0, bytes.size() / 2)));
       },
       "is truncated"},
      {"load_ply_garbage",
       [] { load_cloud(write_file("garbage.ply", "ply\nformat what\n\x01\x02")); },
       "the format must be ascii"},
      {"load_ply_vertex_list",  // aborted the process in PCL's reader (fuzz/ply_fuzzer)
       [] {
         load_cloud(write_file("vertex_list.ply", std::string(kPlyHead) +
                                                      "element vertex 2\nproperty float x\n"
                                                      "property float y\nproperty float z\n"
                                                      "property list uchar int ids\n"
                                                      "end_header\n0 0 0 0\n1 0 0 2 0 1\n"));
       },
       "is a list"},
      {"load_ply_colours_out_of_order",
       [] {
         load_cloud(
             write_file("colours.ply", std::string(kPlyHead) +
                                           "element vertex 1\nproperty float x\n"
                                           "property float y\nproperty float z\n"
                                           "property uchar green\nproperty uchar red\n"
                                           "property uchar blue\nend_header\n0 0 0 1 2 3\n"));
       },
       "vertex colours must be"},
      {"load_ply_alpha_alone",
       [] {
         load_cloud(write_file("alpha.ply", std::string(kPlyHead) +
                                                "element vertex 1\nproperty float x\n"
                                                "property float y\nproperty float z\n"
                                                "property uchar alpha\nend_header\n0 0 0 1\n"));
       },
       "vertex colours must be"},
      // PCL copies a cell's point from the vertex its range_grid list names, unchecked:
      // -1 read before its buffer (SIGSEGV, found by fuzz/ply_fuzzer).
      {"load_ply_range_grid_negative_index",
       [] { load_cloud(write_file("grid_negative.ply", organized_ply("1 0\n1 -1\n0\n1 2\n"))); },
       "range_grid cell 1 names vertex '-1', not one of the 3 vertices"},
      {"load_ply_range_grid_index_past_the_vertices",
       [] { load_cloud(write_file("grid_past.ply", organized_ply("1 0\n1 1\n0\n1 3\n"))); },
       "range_grid cell 3 names vertex '3', not one of the 3 vertices"},
      {"load_ply_binary_range_grid_index_past_the_vertices",
       [] {
         std::string body;
         const auto put_int = [&body](std::int32_t value) {  // big-endian
           for (int shift = 24; shift >= 0; shift -= 8)
             body.push_back(char((value >> shift) & 0xff));
         };
         for (int v = 0; v < 3; ++v) {
           for (int k = 0; k < 3; ++k) put_int(0);  // float zeros
         }
         body += '\x01';
         put_int(7);
         body += std::string(3, '\x00');  // three empty cells
         load_cloud(write_file("grid_binary.ply",
                               "ply\nformat binary_big_endian 1.0\nobj_info num_cols 2\n"
                               "obj_info num_rows 2\nelement vertex 3\nproperty float x\n"
                               "property float y\nproperty float z\nelement range_grid 4\n"
                               "property list uchar int vertex_indices\nend_header\n" +
                                   body));
       },
       "range_grid cell 0 names vertex '7', not one of the 3 vertices"},
      {"load_ply_small_obj_info",
       [] {
         load_cloud(write_file("obj_info.ply", std::string(kPlyHead) +
                                                   "obj_info num_cols 2\nobj_info num_rows 1\n"
                                                   "element vertex 3\nproperty float x\n"
                                                   "property float y\nproperty float z\n"
                                                   "end_header\n0 0 0\n1 0 0\n0 1 0\n"));
       },
       "obj_info gives 2 x 1 points, fewer than the 3 vertices"},
      {"load_ply_inflated_count",
       [] {
         load_cloud(write_file("inflated.ply", std::string(kPlyHead) +
                                                   "element vertex 2000000000\nproperty float x\n"
                                                   "property float y\nproperty float z\n"
                                                   "end_header\n0 0 0\n"));
       },
       "is truncated"},
      {"load_ply_camera_viewport_mismatch",
       [] {
         load_cloud(write_file("camera.ply", std::string(kPlyHead) +
                                                 "element vertex 3\nproperty float x\n"
                                                 "property float y\nproperty float z\n"
                                                 "element camera 1\nproperty int viewportx\n"
                                                 "property int viewporty\nend_header\n"
                                                 "0 0 0\n1 0 0\n0 1 0\n2 1\n"));
       },
       "gives 2 x 1 points for 3 vertices"},
      {"load_ply_no_vertices_tall_viewport",  // 0 x 2e9 points (fuzz/ply_fuzzer)
       [] {
         load_cloud(write_file("tall.ply", std::string(kPlyHead) +
                                               "element vertex 0\nproperty float x\n"
                                               "property float y\nproperty float z\n"
                                               "element camera 1\nproperty int viewporty\n"
                                               "end_header\n2000000000\n"));
       },
       "holds no finite point (0 in the file)"},
      {"load_ply_duplicate_property",
       [] {
         load_cloud(write_file("twice.ply", std::string(kPlyHead) +
                                                "element vertex 1\nproperty float x\n"
                                                "property float x\nproperty float z\n"
                                                "end_header\n0 0 0\n"));
       },
       "appears twice"},
      {"save_empty", [] { save_cloud(temp_path("empty_out.pcd"), PointCloud()); },
       "cloud is empty"},
      {"save_bad_extension", [] { save_cloud(temp_path("out.txt"), object()); },
       "unsupported extension"},
      {"save_unwritable", [] { save_cloud(temp_path("no_such_folder/out.pcd"), object()); },
       "cannot write"},

      // Preprocessing.
      {"downsample_empty", [] { voxel_downsample(PointCloud(), 0.01); }, "cloud is empty"},
      {"downsample_zero", [] { voxel_downsample(object(), 0.0); },
       "voxel_size must be finite and > 0"},
      {"downsample_nan", [] { voxel_downsample(object(), kNaN); },
       "voxel_size must be finite and > 0"},
      {"downsample_inf", [] { voxel_downsample(object(), kInf); },
       "voxel_size must be finite and > 0"},
      {"downsample_tiny", [] { voxel_downsample(object(), 1e-300); }, "is too small"},
      {"downsample_huge", [] { voxel_downsample(object(), 1e7); }, "voxel_size must be <= 1e+06"},
      {"downsample_one_point",
       [] {
         EXPECT_EQ(voxel_downsample(PointCloud(rows({{1, 2, 3}})), 0.01).size(), 1u);
       },
       ""},
      {"downsample_identical",
       [] {
         EXPECT_EQ(voxel_downsample(repeated({1, 2, 3}, {0, 0, 1}, 50), 0.01).size(), 1u);
       },
       ""},
      {"downsample_opposite_normals_cancel",  // documented: the voxel is dropped
       [] {
         const PointCloud pair(rows({{0.001, 0.001, 0.001}, {0.002, 0.002, 0.002}}),
                               rows({{0, 0, 1}, {0, 0, -1}}));
         EXPECT_EQ(voxel_downsample(pair, 0.01).size(), 0u);
       },
       ""},
      {"downsample_far_from_origin_keeps_precision",  // PCL's floats: 6 cm steps at 1e6 m
       [] {
         const Eigen::Vector3d far(1e6, -2e6, 5e5);
         const PointCloud reduced =
             voxel_downsample(object().transformed(test::translation(far)), 0.004);
         const PointCloud near = voxel_downsample(object(), 0.004);  // the same voxels, near 0
         EXPECT_NEAR(double(reduced.size()), double(near.size()), 2.0);
         EXPECT_LT((reduced.centroid() - far - near.centroid()).norm(), 1e-4);
         EXPECT_LT((bounding_box(reduced).sizes() - bounding_box(near).sizes()).norm(), 1e-4);
       },
       ""},
      {"normals_empty", [] { estimate_normals(PointCloud()); }, "cloud is empty"},
      {"normals_radius_nan",
       [] {
         NormalEstimationParams p;
         p.radius = kNaN;
         estimate_normals(object(), p);
       },
       "radius must be finite and > 0"},
      {"normals_negative_k",
       [] {
         NormalEstimationParams p;
         p.k_neighbors = -1;
         estimate_normals(object(), p);
       },
       "k_neighbors must be in [0, 1024]"},
      {"normals_no_threads",
       [] {
         NormalEstimationParams p;
         p.threads = 0;
         estimate_normals(object(), p);
       },
       "threads must be in [1, 256]"},
      {"normals_many_threads",  // PCL's OpenMP crashed the process starting 100000 threads
       [] {
         NormalEstimationParams p;
         p.threads = 100000;
         estimate_normals(object(), p);
       },
       "threads must be in [1, 256]"},
      {"normals_nan_viewpoint",
       [] {
         NormalEstimationParams p;
         p.viewpoint.x() = kNaN;
         estimate_normals(object(), p);
       },
       "viewpoint must be finite"},
      {"normals_one_point",
       [] {
         estimate_normals(PointCloud(rows({{0, 0, 0}})));
       },
       "no point has enough neighbours"},
      {"normals_identical_points",
       [] { estimate_normals(PointCloud(Points(Eigen::RowVector3d(1, 2, 3).replicate(50, 1)))); },
       "no point has enough neighbours"},
      {"normals_collinear", [] { estimate_normals(collinear(100)); },
       "no point has enough neighbours"},
      {"normals_coplanar_face_viewpoint",
       [] {
         NormalEstimationParams p;
         p.viewpoint = Eigen::Vector3d(0, 0, 1);
         const PointCloud out = estimate_normals(coplanar(500, false), p);
         EXPECT_GT(out.size(), 400u);
         EXPECT_GT(out.normals().col(2).minCoeff(), 0.999);
       },
       ""},
      {"normals_far_from_origin_stay_exact",
       [] {
         const PointCloud plane =
             coplanar(500, false).transformed(test::translation({1e6, 1e6, 1e6}));
         NormalEstimationParams p;
         p.viewpoint = Eigen::Vector3d(1e6, 1e6, 1e6 + 1.0);
         const PointCloud out = estimate_normals(plane, p);
         EXPECT_GT(out.normals().col(2).minCoeff(), 0.999);
       },
       ""},

      // Voxel grids.
      {"grid_zero_resolution",
       [] { make_grid_spec(bounding_box(object()), bounding_box(object()), 0.0); }, "resolution"},
      {"grid_empty_box",
       [] { make_grid_spec(Eigen::AlignedBox3d(), bounding_box(object()), 0.01); },
       "bounding box must be finite and non-empty"},
      {"grid_nan_box",
       [] {
         make_grid_spec(
             Eigen::AlignedBox3d(Eigen::Vector3d::Constant(kNaN), Eigen::Vector3d::Ones()),
             bounding_box(object()), 0.01);
       },
       "bounding box must be finite"},
      {"grid_tiny_resolution",
       [] { make_grid_spec(bounding_box(object()), bounding_box(object()), 1e-6); }, "max_voxels"},
      {"grid_limit_raised_past_int",  // per axis, still bounded by kMaxGridIndex
       [] {
         GridLimits unlimited{std::numeric_limits<std::size_t>::max()};
         make_grid_spec(bounding_box(object()), bounding_box(object()), 1e-10, unlimited);
       },
       "max_voxels"},
      {"voxelize_empty", [] { voxelize(PointCloud(), spec_of(8)); }, "cloud is empty"},
      {"voxelize_zero_dims", [] { voxelize(object(), GridSpec{}); }, "grid dims must be >= 1"},
      {"voxelize_over_limit", [] { voxelize(object(), spec_of(1024)); }, "max_voxels"},
      {"voxelize_far_points_are_outside",
       [] {
         const VoxelGrid grid =
             voxelize(PointCloud(rows({{1e6, 0, 0}, {-1e300, 1e300, 0}, {0, 0, 0}})), spec_of(8));
         EXPECT_EQ(grid.points_outside, 2u);
       },
       ""},
      {"index_of_far_and_nan_is_clamped",
       [] {
         const GridSpec spec = spec_of(8, 1e-9);
         EXPECT_EQ(spec.index_of({1e300, -1e300, kNaN}),
                   Eigen::Vector3i(kMaxGridIndex, -kMaxGridIndex, -kMaxGridIndex));
       },
       ""},
      {"fft_size_too_large", [] { fft_friendly_size(kMaxGridIndex + 1); }, "n must be <="},
      {"fft_size_negative", [] { fft_friendly_size(-5); }, "n must be >= 1, got -5"},
      {"fft_size_zero", [] { fft_friendly_size(0); }, "n must be >= 1, got 0"},
      {"urdf_nested_too_deep",
       [] {
         std::string xml = "<robot name='r'>";
         for (int i = 0; i < 100000; ++i) xml += "<a>";
         for (int i = 0; i < 100000; ++i) xml += "</a>";
         Kinematics::from_urdf_string(xml + "</robot>", "a", "b");
       },
       "nested deeper than 256 levels"},
      {"organized_huge_normal_step",
       [] {
         const DepthImage depth = DepthImage::Constant(48, 64, 1.0);
         OrganizedNormalParams params;
         params.normal_step = std::numeric_limits<int>::max();
         organized_cloud(depth, {500.0, 500.0, 32.0, 24.0}, params);
       },
       "normal_step must be <= the image's larger side, 64 pixels"},
      {"organized_huge_window",
       [] {
         const DepthImage depth = DepthImage::Constant(48, 64, 1.0);
         OrganizedNormalParams params;
         params.window = (1 << 27) + 1;
         organized_cloud(depth, {500.0, 500.0, 32.0, 24.0}, params);
       },
       "window must be <= twice the image's larger side plus one, 129 pixels"},
      {"organized_image_over_the_cap",
       [] {
         // Refused before a pixel is read: the map's few real pixels are never touched.
         const std::vector<double> few(16, 1.0);
         const Eigen::Map<const DepthImage> depth(few.data(), 1, Eigen::Index(kMaxDepthPixels) + 1);
         organized_cloud(depth, {500.0, 500.0, 32.0, 24.0});
       },
       "over the 67108864 that a cloud is made of"},

      // EGI and spherical harmonics.
      {"egi_bandwidth_zero", [] { egi_histogram(object().normals(), 0); },
       "bandwidth must be in [1, 128]"},
      {"egi_bandwidth_large", [] { egi_histogram(object().normals(), 129); },
       "bandwidth must be in [1, 128]"},
      {"egi_no_normals", [] { egi_histogram(Points(), 4); }, "normals is empty"},
      {"egi_negative_weight",
       [] {
         const Eigen::VectorXd weights = Eigen::VectorXd::Constant(1, -1.0);
         egi_histogram(rows({{0, 0, 1}}), 4, &weights);
       },
       "weights: entry 0 must be finite and >= 0"},
      {"so3_exp_huge_vector",
       [] {
         const Eigen::Matrix3d R = exp_so3(Eigen::Vector3d(1e200, 0.0, 0.0));
         EXPECT_TRUE(R.allFinite());
         EXPECT_LT((R * R.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-9);
       },
       ""},
      {"egi_nan_normal",
       [] {
         egi_histogram(rows({{kNaN, 0, 1}}), 4);
       },
       "normals: row 0"},
      {"egi_zero_normal",
       [] {
         egi_histogram(rows({{0, 0, 0}}), 4);
       },
       "normals: row 0"},
      {"egi_weights_length",
       [] {
         const Eigen::VectorXd w = Eigen::VectorXd::Ones(3);
         egi_histogram(object().normals(), 4, &w);
       },
       "weights: expected 2000 entries"},
      {"egi_cell_bandwidth_zero",
       [] {
         egi_cell({0, 0, 1}, 0);
       },
       "bandwidth"},  // was a division by 0
      {"egi_cell_nan",
       [] {
         egi_cell({kNaN, 0, 1}, 8);
       },
       "normal must be finite and non-zero"},
      {"egi_coefficients_nan",
       [] {
         egi_coefficients(rows({{kNaN, 0, 1}}), 4);
       },
       "normal"},
      {"egi_coefficients_no_normals",
       [] {
         egi_coefficients(PointCloud(rows({{0, 0, 0}})), 4);
       },
       "no normals"},
      {"smooth_negative",
       [] {
         ShCoefficients c = ShCoefficients::Ones(16);
         smooth_coefficients(c, 4, -1.0);
       },
       "sigma"},
      {"smooth_wrong_size",
       [] {
         ShCoefficients c = ShCoefficients::Ones(15);
         smooth_coefficients(c, 4, 0.1);
       },
       "coefficients"},
      {"harmonics_zero_direction",
       [] {
         Eigen::VectorXd out(16);
         real_spherical_harmonics(Eigen::Vector3d::Zero(), 3, out);
       },
       "unit_direction must be finite and non-zero"},
      {"harmonics_lmax",
       [] {
         Eigen::VectorXd out(1);
         real_spherical_harmonics(Eigen::Vector3d::UnitZ(), -1, out);
       },
       "lmax"},
      {"harmonics_out_size",
       [] {
         Eigen::VectorXd out(3);
         real_spherical_harmonics(Eigen::Vector3d::UnitZ(), 3, out);
       },
       "out"},
      {"sht_bandwidth", [] { SphericalHarmonicTransform(0); }, "bandwidth"},
      {"sht_nan_samples",
       [] { SphericalHarmonicTransform(4).forward(SphereGrid::Constant(8, 8, kNaN)); },
       "samples has non-finite"},
      {"sht_wrong_shape", [] { SphericalHarmonicTransform(4).forward(SphereGrid::Zero(8, 7)); },
       "samples: expected a 8 x 8 grid"},

      // Rotation.
      {"wigner_reflection", [] { wigner_real(-Eigen::Matrix3d::Identity(), 3); }, "R"},
      {"wigner_nan", [] { wigner_real(Eigen::Matrix3d::Constant(kNaN), 3); }, "R"},
      {"wigner_lmax", [] { wigner_real(Eigen::Matrix3d::Identity(), 128); }, "lmax"},
      {"correlation_sizes", [] { So3Correlation(coefficients(4), coefficients(5), 4); },
       "model_coefficients: expected"},
      {"correlation_nan",
       [] {
         ShCoefficients t = coefficients(4);
         t[3] = kNaN;
         So3Correlation(t, coefficients(4), 4);
       },
       "target_coefficients has non-finite"},
      {"correlation_uniform_egi",
       [] {
         ShCoefficients flat = ShCoefficients::Zero(16);
         flat[0] = 1.0;
         So3Correlation(flat, coefficients(4), 4);
       },
       "a uniform EGI"},
      {"correlation_at_non_rotation",
       [] {
         So3Correlation c(coefficients(4), coefficients(4), 4);
         c.evaluate(2.0 * Eigen::Matrix3d::Identity());
       },
       "R"},
      {"search_no_candidates",
       [] {
         So3SearchParams p;
         p.candidates = 0;
         so3_search(coefficients(4), coefficients(4), 4, p);
       },
       "candidates"},
      {"search_many_threads",
       [] {  // clamped to the work
         So3SearchParams p;
         p.threads = 256;
         EXPECT_FALSE(so3_search(coefficients(4), coefficients(4), 4, p).empty());
       },
       ""},
      {"search_too_many_threads",
       [] {
         So3SearchParams p;
         p.threads = 10000;
         so3_search(coefficients(4), coefficients(4), 4, p);
       },
       "params.threads must be in [1, 256]"},
      {"refine_bad_start",
       [] {
         So3Correlation c(coefficients(4), coefficients(4), 4);
         refine_rotation(c, Eigen::Matrix3d::Zero());
       },
       "R0"},

      // Translation.
      {"phase_zero_dims", [] { PhaseCorrelation(GridSpec{}); }, "spec.dims must be >= 1"},
      {"phase_band",
       [] {
         PhaseCorrelationParams p;
         p.subvoxel_band = 0.6;
         PhaseCorrelation(spec_of(8), p);
       },
       "subvoxel_band"},
      {"phase_threads",
       [] {
         PhaseCorrelationParams p;
         p.threads = 100000;
         PhaseCorrelation(spec_of(8), p);
       },
       "threads must be in [1, 256]"},
      {"phase_over_limit_before_allocating",  // 2048^3 voxels: 170 GB of buffers
       [] { PhaseCorrelation(spec_of(2048)); }, "GridLimits::max_voxels"},
      {"phase_no_target",
       [] {
         PhaseCorrelation pc(spec_of(64));
         pc.estimate(grid_of(object(), spec_of(64)));
       },
       "set_target() must be called"},
      {"phase_empty_target",
       [] {
         PhaseCorrelation pc(spec_of(8));
         VoxelGrid empty;
         empty.spec = spec_of(8);
         empty.values.assign(512, 0.0f);
         pc.set_target(empty);
       },
       "target is empty"},
      {"phase_spec_mismatch",
       [] {
         PhaseCorrelation pc(spec_of(64));
         pc.set_target(grid_of(object(), spec_of(32, 0.02)));
       },
       "target: grid of"},
      {"phase_negative_max_shift",
       [] {
         PhaseCorrelation pc(spec_of(64));
         const VoxelGrid g = grid_of(object(), spec_of(64));
         pc.set_target(g);
         pc.estimate(g, Eigen::Vector3i(-1, 0, 0));
       },
       "max_shift_voxels must be >= 0"},
      {"phase_single_voxel_shift_is_exact",
       [] {
         GridSpec spec = spec_of(16, 1.0);
         spec.origin.setZero();
         const VoxelGrid a = voxelize(PointCloud(rows({{3.5, 4.5, 5.5}})), spec);
         const VoxelGrid b = voxelize(PointCloud(rows({{5.5, 3.5, 9.5}})), spec);
         const TranslationEstimate e = phase_correlation(a, b);
         EXPECT_EQ(e.peak_voxels, Eigen::Vector3i(2, -1, 4));
         EXPECT_TRUE(e.shift.allFinite());
       },
       ""},
      {"translation_cost_mismatch",
       [] {
         translation_cost(grid_of(object(), spec_of(64)), grid_of(object(), spec_of(32, 0.02)),
                          Eigen::Vector3i::Zero());
       },
       "dims differ"},

      // Alignment: errors.
      {"align_empty_model", [] { align(PointCloud(), object()); }, "model is empty"},
      {"align_empty_scene", [] { align(object(), PointCloud()); }, "scene is empty"},
      {"align_no_normals", [] { align(PointCloud(object().points()), object()); },
       "model has no normals"},
      {"align_voxel_nan",
       [] { align(object(), object(), with([](AlignParams& p) { p.scene.voxel_size = kNaN; })); },
       "voxel_size must be >= 0 metres"},
      {"align_voxel_negative",
       [] { align(object(), object(), with([](AlignParams& p) { p.scene.voxel_size = -0.01; })); },
       "voxel_size must be >= 0 metres"},
      {"align_budget_past_2_32",  // a budget no machine holds gave std::bad_alloc
       [] {
         align(object(), object(),
               with([](AlignParams& p) { p.limits.max_voxels = std::size_t{1} << 33; }));
       },
       "max_voxels must be <= 2^32"},
      {"phase_correlation_budget_past_2_32",
       [] {
         PhaseCorrelationParams params;
         params.limits.max_voxels = std::size_t{1} << 33;
         PhaseCorrelation(spec_of(8), params);
       },
       "max_voxels must be <= 2^32"},
      {"align_bandwidth",
       [] { align(object(), object(), with([](AlignParams& p) { p.scene.bandwidth = 65; })); },
       "bandwidth must be in [2, 64]"},
      {"align_gain",
       [] {
         align(object(), object(), with([](AlignParams& p) { p.local.translation_gain = 2.0; }));
       },
       "translation_gain"},
      {"align_rotation_gain_inf",
       [] {
         align(object(), object(), with([](AlignParams& p) { p.local.rotation_gain = kInf; }));
       },
       "rotation_gain"},
      {"align_iterations",
       [] { align(object(), object(), with([](AlignParams& p) { p.local.max_iterations = 0; })); },
       "max_iterations"},
      {"align_refinements",
       [] { align(object(), object(), with([](AlignParams& p) { p.search.refinements = 9; })); },
       "refinements"},
      {"align_search_voxel",
       [] {
         align(object(), object(), with([](AlignParams& p) { p.search.search_voxel_size = -1.0; }));
       },
       "search_voxel_size"},
      {"align_window_margin",
       [] {
         align(object(), object(), with([](AlignParams& p) { p.search.window_margin = kNaN; }));
       },
       "window_margin"},
      {"align_threads",
       [] { align(object(), object(), with([](AlignParams& p) { p.threads = 100000; })); },
       "threads must be in [1, 256]"},
      {"align_max_seconds_negative",
       [] { align(object(), object(), with([](AlignParams& p) { p.max_seconds = -1.0; })); },
       "max_seconds"},
      {"align_max_seconds_inf",
       [] { align(object(), object(), with([](AlignParams& p) { p.max_seconds = kInf; })); },
       "max_seconds"},
      {"align_guess_not_rigid",
       [] { align(object(), object(), with([](AlignParams& p) { p.initial_guess(0, 0) = 2.0; })); },
       "initial_guess is not a rigid transform"},
      {"align_guess_nan",
       [] {
         align(object(), object(), with([](AlignParams& p) { p.initial_guess(0, 3) = kNaN; }));
       },
       "initial_guess has non-finite entries"},
      {"align_viewpoint_nan",
       [] {
         align(object(), object(),
               with([](AlignParams& p) { p.scene.sensor_origin = Eigen::Vector3d(kNaN, 0, 0); }));
       },
       "sensor_origin must be finite"},
      {"align_tiny_voxel",
       [] { align(object(), object(), with([](AlignParams& p) { p.scene.voxel_size = 1e-5; })); },
       "max_voxels"},
      {"align_memory_limit",
       [] { align(object(), object(), with([](AlignParams& p) { p.limits.max_voxels = 1000; })); },
       "max_voxels"},
      {"align_scene_spanning_two_million_metres",  // voxel counts beyond the range of int
       [] {
         const PointCloud far(rows({{-1e6, 0, 0}, {1e6, 0, 0}, {0, 0, 0}}),
                              rows({{0, 0, 1}, {0, 1, 0}, {1, 0, 0}}));
         align(object(), far, with([](AlignParams& p) { p.scene.voxel_size = 1e-4; }));
       },
       "max_voxels"},

      // Alignment: degenerate clouds give a finite result that does not claim convergence.
      {"align_one_point_model",
       [] {
         expect_unreliable(
             align(PointCloud(rows({{0, 0, 0}}), rows({{0, 0, 1}})), object(), fast()));
       },
       ""},
      {"align_identical_points_model",
       [] {
         expect_unreliable(align(repeated({0.1, 0, 0}, {0, 0, 1}, 100), object(), fast()));
       },
       ""},
      {"align_one_point_scene",
       [] {
         expect_unreliable(
             align(object(), PointCloud(rows({{0, 0, 0}}), rows({{0, 0, 1}})), fast()));
       },
       ""},
      {"align_coplanar_onto_itself",  // a plane's pose about its normal is unobservable
       [] {
         const PointCloud plane = coplanar(2000, true);
         const AlignResult r = align(plane, plane, fast());
         expect_finite(r);
         EXPECT_NEAR(std::abs(r.T_scene_model(2, 2)), 1.0, 1e-3);  // the normal maps onto +-z
       },
       ""},
      {"align_max_seconds_stops_global_search",
       [] {
         const AlignResult r =
             align(object(), object().transformed(pose(60, {1, 2, 3}, {0.05, 0, 0})),
                   with([](AlignParams& p) { p.max_seconds = 1e-9; }));
         expect_unreliable(r);
         EXPECT_EQ(r.stop_reason, AlignStopReason::max_seconds);
         EXPECT_EQ(r.iterations, 1);
       },
       ""},
      {"align_max_seconds_stops_paper_mode",
       [] {
         const AlignResult r =
             align(object(), object().transformed(pose(10, {1, 2, 3}, {0.01, 0, 0})),
                   with([](AlignParams& p) {
                     p.search.global_search = false;
                     p.max_seconds = 1e-9;
                   }));
         expect_unreliable(r);
         EXPECT_EQ(r.stop_reason, AlignStopReason::max_seconds);
         EXPECT_EQ(r.iterations, 1);
       },
       ""},
      {"align_max_iterations_reason",
       [] {
         const AlignResult r =
             align(object(), object().transformed(pose(10, {1, 2, 3}, {0.01, 0, 0})),
                   with([](AlignParams& p) {
                     p.search.global_search = false;
                     p.local.max_iterations = 1;
                   }));
         expect_unreliable(r);
         EXPECT_EQ(r.stop_reason, AlignStopReason::max_iterations);
       },
       ""},
      {"align_far_from_origin",
       [] {  // 1e6 m away: the same answer as near the origin
         const Transform far = test::translation({1e6, -1e6, 1e6});
         const Transform truth = pose(40, {1, -1, 2}, {0.03, 0.02, -0.01});
         const AlignResult r = align(object().transformed(far), object().transformed(far * truth),
                                     with([](AlignParams& p) { p.search.hypotheses = 32; }));
         expect_finite(r);
         EXPECT_LT(rotation_error_deg(r.T_scene_model, far * truth * far.inverse()), 1.0);
       },
       ""},

      // Kinematics.
      {"urdf_missing_file", [] { Kinematics(temp_path("missing.urdf"), "a", "b"); },
       "urdf_path: no such file"},
      {"urdf_not_xml", [] { Kinematics::from_urdf_string("not a robot", "a", "b"); },
       "not a valid URDF"},
      {"urdf_truncated",
       [] {
         const std::string text = urdf_text();
         Kinematics::from_urdf_string(text.substr(0, text.size() / 2), "base_link", "tool");
       },
       "not a valid URDF"},
      {"urdf_missing_parent_link",
       [] {
         Kinematics::from_urdf_string(replaced(urdf_text(), "<link name=\"link3\"/>", ""),
                                      "base_link", "tool");
       },
       "not a valid URDF"},
      {"urdf_missing_tip", [] { Kinematics(SPECTRAL_VS_TEST_URDF, "base_link", "no_link"); },
       "tip_link: no link named 'no_link'"},
      {"urdf_missing_base", [] { Kinematics(SPECTRAL_VS_TEST_URDF, "no_link", "tool"); },
       "base_link: no link named 'no_link'"},
      {"urdf_tip_above_base", [] { Kinematics(SPECTRAL_VS_TEST_URDF, "link4", "link1"); },
       "is not below"},
      {"urdf_no_joint", [] { Kinematics(SPECTRAL_VS_TEST_URDF, "link2", "link2"); },
       "no movable joint"},
      {"urdf_zero_axis",  // was NaN poses and Jacobians
       [] {
         Kinematics::from_urdf_string(
             replaced(urdf_text(), "<axis xyz=\"0 1 0\"/>", "<axis xyz=\"0 0 0\"/>"), "base_link",
             "tool");
       },
       "has a zero or non-finite axis"},
      {"urdf_loop_of_links",  // was an endless walk up the loop, then std::bad_alloc
       [] {
         const std::string loop =
             replaced(urdf_text(), "<parent link=\"base_link\"/>\n    <child link=\"link1\"/>",
                      "<parent link=\"link6\"/>\n    <child link=\"link1\"/>");
         Kinematics::from_urdf_string(loop, "base_link", "link6");
       },
       "form a loop"},
      {"urdf_camera_not_rigid",
       [] { Kinematics(SPECTRAL_VS_TEST_URDF, "base_link", "tool", Transform::Constant(1.0)); },
       "T_tip_camera"},
      {"kinematics_q_size", [] { arm().forward(Eigen::VectorXd::Zero(2)); },
       "q: expected 6 joint positions"},
      {"kinematics_q_nan", [] { arm().jacobian(Eigen::VectorXd::Constant(6, kNaN)); },
       "q has non-finite"},
      {"kinematics_q_huge",
       [] { EXPECT_TRUE(arm().forward(Eigen::VectorXd::Constant(6, 1e300)).allFinite()); }, ""},
      {"command_twist_nan",
       [] { arm().joint_velocities(Eigen::VectorXd::Zero(6), Twist::Constant(kNaN)); },
       "camera_twist has non-finite"},
      {"command_twist_huge_stays_within_limits",
       [] {
         const Kinematics k = arm();
         const VelocityCommand cmd =
             k.joint_velocities(Eigen::VectorXd::Zero(6), Twist::Constant(1e300));
         EXPECT_TRUE(cmd.q_dot.allFinite());
         EXPECT_TRUE((cmd.q_dot.array().abs() <= k.velocity_limits().array() + 1e-12).all());
       },
       ""},
      {"command_dt_zero",
       [] {
         VelocityCommandParams p;
         p.dt = 0.0;
         arm().joint_velocities(Eigen::VectorXd::Zero(6), Twist::Zero(), p);
       },
       "dt"},
      {"command_speed_nan",
       [] {
         VelocityCommandParams p;
         p.max_joint_speed = kNaN;
         arm().joint_velocities(Eigen::VectorXd::Zero(6), Twist::Zero(), p);
       },
       "max_joint_speed"},
      {"lstsq_empty", [] { damped_least_squares(Eigen::MatrixXd(), Eigen::VectorXd()); },
       "J is empty"},
      {"lstsq_nan",
       [] {
         damped_least_squares(Eigen::MatrixXd::Constant(2, 2, kNaN), Eigen::VectorXd::Zero(2));
       },
       "J has non-finite"},
      {"lstsq_zero_matrix",
       [] {
         const DampedSolution s =
             damped_least_squares(Eigen::MatrixXd::Zero(6, 3), Eigen::VectorXd::Ones(6));
         EXPECT_TRUE(s.x.isZero());
       },
       ""},
  };
  return c;
}

class Adversarial : public ::testing::TestWithParam<Case> {};

TEST_P(Adversarial, HasItsDocumentedBehaviour) {
  const Case& c = GetParam();
  if (c.error.empty()) {
    EXPECT_NO_THROW(c.call());
    return;
  }
  try {
    c.call();
    ADD_FAILURE() << "expected std::invalid_argument containing \"" << c.error << "\"";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(c.error), std::string::npos)
        << "message: " << error.what() << "\nexpected to contain: " << c.error;
  }
}

INSTANTIATE_TEST_SUITE_P(Table, Adversarial, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<Case>& info) {
                           return info.param.name;
                         });

// Alignments on threads of their own give, bit for bit, what they give one after the
// other; under the sanitizers this also checks the shared caches (FFT plans, Wigner
// tables) for races that corrupt memory. Bandwidths 9 and 7 are used by no other test of
// this program, so the threads also race to make them first.
TEST(Threads, ParallelAlignmentsEqualSequentialOnes) {
  struct Job {
    PointCloud scene;
    AlignParams params;
    AlignResult result;
  };
  std::vector<Job> jobs;
  for (int i = 0; i < 4; ++i) {
    AlignParams p = fast();
    p.scene.bandwidth = i % 2 ? 9 : 7;
    p.search.global_search = i != 3;
    p.threads = i == 1 ? 2 : 1;
    const Transform T =
        pose(i == 3 ? 12.0 : 50.0 + 40.0 * i, {1.0 + i, -1.0, 0.5}, {0.02 * i, 0.01, 0.0});
    jobs.push_back({object().transformed(T), p, {}});
  }
  std::vector<std::thread> threads;
  for (auto& job : jobs) {
    threads.emplace_back([&job] { job.result = align(object(), job.scene, job.params); });
  }
  for (auto& thread : threads) thread.join();
  for (const auto& job : jobs) {
    const AlignResult sequential = align(object(), job.scene, job.params);
    EXPECT_EQ(job.result.T_scene_model, sequential.T_scene_model);
    EXPECT_EQ(job.result.fitness, sequential.fitness);
    EXPECT_EQ(job.result.iterations, sequential.iterations);
    EXPECT_EQ(job.result.history.size(), sequential.history.size());
  }
}

}  // namespace
}  // namespace spectral_vs
