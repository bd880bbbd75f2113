// Writes the fuzzers' seed corpora into OUT/{pcd,pcd_ascii,ply,urdf,align,depth}:
//   fuzz_seeds OUT DATA_DIR [URDF:BASE:TIP ...]
// PCD: small clouds (with and without normals) in each encoding, an organized ASCII
// cloud with NaN pixels, and for every scan in DATA_DIR its first 4 KB as they are plus
// its first 150 points re-saved in each encoding. PLY: small clouds binary (as
// save_cloud writes them), ASCII and big-endian by hand. URDF: "BASE\nTIP\n" and the XML
// of each given file, and two nestings (the target's byte-1 mode). pcd_ascii: a type
// byte and a value, for the values PCL misreads and their neighbours. align and depth:
// random byte strings.

#include <spectral_vs/representation/cloud_io.hpp>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>

namespace fs = std::filesystem;
using namespace spectral_vs;

namespace {

PointCloud small_cloud(int n, bool normals, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Points p(n, 3), nn(n, 3);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    p.row(i) = (0.05 * d + Eigen::Vector3d(0.1, -0.05, 0.6)).transpose();
    nn.row(i) = d.transpose();
  }
  return normals ? PointCloud(p, nn) : PointCloud(p);
}

std::string read_head(const fs::path& path, std::size_t bytes) {
  std::ifstream in(path, std::ios::binary);
  std::string out(bytes, '\0');
  in.read(out.data(), static_cast<std::streamsize>(bytes));
  out.resize(static_cast<std::size_t>(in.gcount()));
  return out;
}

void write(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

PointCloud first_points(const PointCloud& cloud, std::size_t n) {
  n = std::min(n, cloud.size());
  Points p = cloud.points().topRows(Eigen::Index(n));
  if (!cloud.has_normals()) return PointCloud(p);
  return PointCloud(p, Points(cloud.normals().topRows(Eigen::Index(n))));
}

void save_pcds(const fs::path& dir, const std::string& stem, const PointCloud& cloud) {
  save_cloud((dir / (stem + "_ascii.pcd")).string(), cloud, PcdEncoding::ascii);
  save_cloud((dir / (stem + "_binary.pcd")).string(), cloud, PcdEncoding::binary);
  save_cloud((dir / (stem + "_compressed.pcd")).string(), cloud, PcdEncoding::binary_compressed);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: fuzz_seeds OUT DATA_DIR [URDF:BASE:TIP ...]\n";
    return 2;
  }
  const fs::path out = argv[1], data = argv[2];
  for (const char* name : {"pcd", "pcd_ascii", "ply", "urdf", "align", "depth"})
    fs::create_directories(out / name);

  // pcd_ascii: the type index (F4 F8 I1 I2 I4 I8 U1 U2 U4 U8) and the value.
  const char* values[] = {"1.5",   "-.25", "0x1p3", "1e39",  "5e",    "1e3",
                          ".5",    "inf",  "nan",   "70000", "-1",    "300",
                          "65535", "-0",   "010",   "+7",    "1e-50", "9007199254740993"};
  int seed = 0;
  for (char type = 0; type < 10; ++type) {
    for (const char* value : values) {
      write(out / "pcd_ascii" / ("value_" + std::to_string(seed++)), std::string(1, type) + value);
    }
  }

  // PCD
  save_pcds(out / "pcd", "normals", small_cloud(40, true, 1));
  save_pcds(out / "pcd", "points", small_cloud(30, false, 2));
  write(out / "pcd" / "organized_nan.pcd",
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        "WIDTH 3\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 6\nDATA ascii\n"
        "0 0 1\nnan nan nan\n0.1 0 1\n0 0.1 1\n0.1 0.1 1\nnan nan nan\n");
  write(out / "pcd" / "rgb_double.pcd",
        "VERSION 0.7\nFIELDS x y z rgb\nSIZE 8 8 8 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n0 0 1 4278190080\n0.5 0.25 1.5 255\n");
  int scans = 0;
  if (fs::is_directory(data)) {
    for (const auto& entry : fs::directory_iterator(data)) {
      if (entry.path().extension() != ".pcd") continue;
      const std::string stem = entry.path().stem().string();
      write(out / "pcd" / (stem + "_head.pcd"), read_head(entry.path(), 4096));
      save_pcds(out / "pcd", stem + "_150", first_points(load_cloud(entry.path().string()), 150));
      ++scans;
    }
  }

  // PLY
  save_cloud((out / "ply" / "normals.ply").string(), small_cloud(40, true, 3));
  save_cloud((out / "ply" / "points.ply").string(), small_cloud(30, false, 4));
  write(out / "ply" / "ascii_normals.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nproperty float normal_x\nproperty float normal_y\n"
        "property float normal_z\nend_header\n0 0 1 0 0 -1\n0.1 0 1 0 0 -1\n0 0.1 1 0 0 -1\n");
  write(out / "ply" / "ascii_faces.ply",
        "ply\nformat ascii 1.0\ncomment a triangle\nelement vertex 3\nproperty double x\n"
        "property double y\nproperty double z\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  // The layouts PCL's reader sizes a cloud by, and colours: what check_ply guards.
  write(out / "ply" / "ascii_colours.ply",
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
        "property uchar alpha\nend_header\n0 0 1 255 0 0 255\n0.1 0 1 0 255 0 128\n");
  write(out / "ply" / "ascii_range_grid.ply",
        "ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\nelement vertex 3\n"
        "property float x\nproperty float y\nproperty float z\nelement range_grid 4\n"
        "property list uchar int vertex_indices\nend_header\n0 0 1\n0.1 0 1\n0 0.1 1\n"
        "1 0\n1 1\n0\n1 2\n");
  write(out / "ply" / "ascii_camera.ply",
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nelement camera 1\nproperty float view_px\n"
        "property int viewportx\nproperty int viewporty\nend_header\n0 0 1\n0.1 0 1\n"
        "0 2 1\n");
  {
    std::string big =
        "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n";
    const float values[6] = {0.0f, 0.0f, 1.0f, 0.5f, -0.25f, 2.0f};
    for (float v : values) {
      unsigned char bytes[4];
      std::memcpy(bytes, &v, 4);
      for (int k = 3; k >= 0; --k) big.push_back(static_cast<char>(bytes[k]));
    }
    write(out / "ply" / "big_endian.ply", big);
  }

  // URDF
  for (int i = 3; i < argc; ++i) {
    std::stringstream spec(argv[i]);
    std::string path, base, tip;
    std::getline(spec, path, ':');
    std::getline(spec, base, ':');
    std::getline(spec, tip, ':');
    if (!fs::exists(path)) continue;
    std::ifstream in(path, std::ios::binary);
    std::stringstream xml;
    xml << in.rdbuf();
    write(out / "urdf" /
              (fs::path(path).parent_path().filename().string() + "_" +
               fs::path(path).stem().string() + "_" + tip + ".txt"),
          base + "\n" + tip + "\n" + xml.str());
  }

  // URDF nestings: byte 1, the depth / 4 in two bytes, the element
  write(out / "urdf" / "nested_shallow.bin", std::string("\x01\x10\x00visual", 9));
  write(out / "urdf" / "nested_deep.bin", std::string("\x01\x50\xc3origin", 9));

  // align: random bytes of a few lengths
  std::mt19937 rng(17);
  for (int i = 0; i < 12; ++i) {
    std::string bytes(std::size_t(64 + 40 * i), '\0');
    for (char& c : bytes) c = static_cast<char>(rng() & 0xff);
    write(out / "align" / ("random_" + std::to_string(i)), bytes);
  }

  // depth: random bytes too (the target reads sizes, camera and settings from them)
  for (int i = 0; i < 8; ++i) {
    std::string bytes(std::size_t(256 + 1024 * i), '\0');
    for (char& c : bytes) c = static_cast<char>(rng() & 0xff);
    write(out / "depth" / ("random_" + std::to_string(i)), bytes);
  }
  std::cout << "seeds in " << out.string() << " (" << scans << " scans of " << data.string()
            << ")\n";
  return 0;
}
