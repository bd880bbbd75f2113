// Bindings of the representation (paper, section II-A): clouds, files, preprocessing,
// voxel grids and the EGI.
#include "conversions.hpp"

#include <spectral_vs/representation/cloud_io.hpp>
#include <spectral_vs/representation/dominant_plane.hpp>
#include <spectral_vs/representation/egi.hpp>
#include <spectral_vs/representation/preprocessing.hpp>
#include <spectral_vs/representation/voxel_grid.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>

namespace spectral_vs::python {

namespace {

PointCloud make_cloud(const py::handle& points, const py::handle& normals, bool drop_non_finite) {
  Points p = to_points(points, "points");
  Points n = normals.is_none() ? Points() : to_points(normals, "normals");
  if (drop_non_finite) {
    py::gil_scoped_release release;
    remove_non_finite(p, n.rows() ? &n : nullptr);
  }
  return PointCloud(std::move(p), std::move(n));
}

constexpr Choices<NormalOrientation, 2> kOrientations{
    {{"toward_viewpoint", NormalOrientation::toward_viewpoint},
     {"outward", NormalOrientation::outward}}};

constexpr Choices<PcdEncoding, 3> kEncodings{
    {{"ascii", PcdEncoding::ascii},
     {"binary", PcdEncoding::binary},
     {"binary_compressed", PcdEncoding::binary_compressed}}};

py::array grid_values(const VoxelGrid& grid, py::handle owner) {
  const auto& d = grid.spec.dims;
  const auto f = static_cast<py::ssize_t>(sizeof(float));
  py::array_t<float> view({py::ssize_t(d.x()), py::ssize_t(d.y()), py::ssize_t(d.z())},
                          {f * d.y() * d.z(), f * d.z(), f}, grid.values.data(), owner);
  view.attr("setflags")(py::arg("write") = false);
  return std::move(view);
}

}  // namespace

void define_representation(py::module_& m) {
  py::class_<PointCloud>(m, "PointCloud", R"doc(
Points in metres with optional unit surface normals.

Parameters
----------
points : array_like, shape (N, 3), float
    Coordinates in metres. Every entry must be finite unless ``drop_non_finite``.
normals : array_like, shape (N, 3), float, optional
    One normal per point; rescaled to unit length. Zero-length rows are refused.
drop_non_finite : bool
    Drop rows with a non-finite coordinate or normal (as from a depth sensor)
    instead of raising ``ValueError``.
)doc")
      .def(py::init(&make_cloud), py::arg("points"), py::arg("normals") = py::none(), py::kw_only(),
           py::arg("drop_non_finite") = false)
      .def("__len__", &PointCloud::size)
      .def_property_readonly(
          "points",
          [](py::object self) {
            return readonly_view(self.cast<const PointCloud&>().points(), self);
          },
          "(N, 3) float64 read-only view of the points, metres.")
      .def_property_readonly(
          "normals",
          [](py::object self) -> py::object {
            const auto& cloud = self.cast<const PointCloud&>();
            if (!cloud.has_normals()) return py::none();
            return readonly_view(cloud.normals(), self);
          },
          "(N, 3) float64 read-only view of the unit normals, or None.")
      .def_property_readonly("has_normals", &PointCloud::has_normals)
      .def("centroid", &PointCloud::centroid, "Mean of the points, metres.")
      .def(
          "select",
          [](const PointCloud& cloud, const py::array_t<bool, py::array::c_style>& keep) {
            if (keep.ndim() != 1 || std::size_t(keep.shape(0)) != cloud.size()) {
              throw py::value_error("keep must be a boolean array of shape (" +
                                    std::to_string(cloud.size()) + ",), one entry per point");
            }
            std::vector<char> flags(keep.data(), keep.data() + keep.shape(0));
            py::gil_scoped_release release;
            return cloud.selected(flags);
          },
          py::arg("keep"),
          "The points (and normals) where the boolean array keep is True, in order: a copy "
          "made in the core, without the checks of the constructor.")
      .def(
          "transformed",
          [](const PointCloud& cloud, const py::handle& T) {
            return cloud.transformed(to_transform(T, "T_target_source"));
          },
          py::arg("T_target_source"), "The cloud moved by a 4x4 rigid transform (normals rotated).")
      .def("__repr__", [](const PointCloud& cloud) {
        std::ostringstream out;
        out << "PointCloud(" << cloud.size() << " points, " << (cloud.has_normals() ? "with" : "no")
            << " normals)";
        return out.str();
      });

  py::class_<CloudFileInfo>(m, "CloudFileInfo", "What a point cloud file held before loading.")
      .def_readonly("width", &CloudFileInfo::width)
      .def_readonly("height", &CloudFileInfo::height)
      .def_readonly("points_in_file", &CloudFileInfo::points_in_file)
      .def_readonly("non_finite_dropped", &CloudFileInfo::non_finite_dropped)
      .def_readonly("had_normals", &CloudFileInfo::had_normals)
      .def("__repr__", [](const CloudFileInfo& i) {
        std::ostringstream out;
        out << "CloudFileInfo(width=" << i.width << ", height=" << i.height
            << ", points_in_file=" << i.points_in_file
            << ", non_finite_dropped=" << i.non_finite_dropped
            << ", had_normals=" << (i.had_normals ? "True" : "False") << ")";
        return out.str();
      });

  m.def(
      "load_cloud_with_info",
      [](const std::filesystem::path& path) {
        require_file(path, "path");
        CloudFileInfo info;
        PointCloud cloud;
        {
          py::gil_scoped_release release;
          cloud = load_cloud(path.string(), &info);
        }
        return py::make_tuple(std::move(cloud), info);
      },
      py::arg("path"), "Load a .pcd or .ply file; return (PointCloud, CloudFileInfo).");

  m.def(
      "load_organized",
      [](const std::filesystem::path& path) {
        require_file(path, "path");
        CloudFileInfo info;
        Points points;
        {
          py::gil_scoped_release release;
          points = load_points(path.string(), &info);
        }
        py::array_t<double> out(
            {py::ssize_t(info.height), py::ssize_t(info.width), py::ssize_t(3)});
        std::copy(points.data(), points.data() + points.size(), out.mutable_data());
        return out;
      },
      py::arg("path"),
      "The points of a .pcd or .ply file as a (height, width, 3) array in metres, NaN where "
      "an organized cloud has no return; an unorganized cloud gives (1, N, 3).");

  m.def(
      "save_cloud",
      [](const std::filesystem::path& path, const PointCloud& cloud, const std::string& encoding) {
        const PcdEncoding parsed = parse_choice(encoding, kEncodings, "encoding");
        py::gil_scoped_release release;
        save_cloud(path.string(), cloud, parsed);
      },
      py::arg("path"), py::arg("cloud"), py::arg("encoding") = "binary_compressed",
      "Save to .pcd (encoding: ascii, binary, binary_compressed) or .ply, as float32.");

  py::class_<DominantPlane>(m, "DominantPlane",
                            "A dominant plane (dominant_plane): n . x = offset on it.")
      .def_readonly("normal", &DominantPlane::normal, "Unit normal, the side its normals face.")
      .def_readonly("offset", &DominantPlane::offset, "Offset along the normal, m.")
      .def_readonly("count", &DominantPlane::count, "Points on the plane.")
      .def_readonly("share", &DominantPlane::share, "count over the cloud's points, [0, 1].")
      .def_readonly("extent", &DominantPlane::extent,
                    "Diagonal of the bounding box of its points, m.")
      .def("__repr__", [](const DominantPlane& p) {
        std::ostringstream out;
        out << "DominantPlane(normal=[" << p.normal.x() << ", " << p.normal.y() << ", "
            << p.normal.z() << "], offset=" << p.offset << ", count=" << p.count
            << ", share=" << p.share << ", extent=" << p.extent << ")";
        return out.str();
      });

  const PlaneDetectionParams plane_defaults;
  auto plane_params = [](double direction_cone, double member_cone, double offset_bin, double band,
                         double min_share) {
    PlaneDetectionParams params;
    params.direction_cone = direction_cone;
    params.member_cone = member_cone;
    params.offset_bin = offset_bin;
    params.band = band;
    params.min_share = min_share;
    return params;
  };
  m.def(
      "dominant_direction",
      [plane_params, plane_defaults](const py::handle& normals, double direction_cone,
                                     double member_cone) {
        const Points n = to_points(normals, "normals");
        const PlaneDetectionParams params =
            plane_params(direction_cone, member_cone, plane_defaults.offset_bin,
                         plane_defaults.band, plane_defaults.min_share);
        py::gil_scoped_release release;
        const DominantDirection d = dominant_direction(n, params);
        return std::make_pair(d.axis, d.share);
      },
      py::arg("normals"), py::arg("direction_cone") = plane_defaults.direction_cone,
      py::arg("member_cone") = plane_defaults.member_cone,
      "The most common direction of unit normals (N, 3), by voting: the normal with the most\n"
      "others within direction_cone (rad), then the mean of those; and the share of the\n"
      "normals within member_cone (rad) of it. (axis, share); ((0, 0, 1), 0) for no normals.");
  m.def(
      "dominant_plane",
      [plane_params](const PointCloud& cloud, double direction_cone, double member_cone,
                     double offset_bin, double band, double min_share) {
        const PlaneDetectionParams params =
            plane_params(direction_cone, member_cone, offset_bin, band, min_share);
        py::gil_scoped_release release;
        return dominant_plane(cloud, params);
      },
      py::arg("cloud"), py::arg("direction_cone") = plane_defaults.direction_cone,
      py::arg("member_cone") = plane_defaults.member_cone,
      py::arg("offset_bin") = plane_defaults.offset_bin, py::arg("band") = plane_defaults.band,
      py::arg("min_share") = plane_defaults.min_share,
      "The dominant plane of a cloud with normals (a table top), by voting: the dominant\n"
      "direction (dominant_direction), then the most common offset along it in bins of\n"
      "offset_bin (m); its points have normals within member_cone (rad) and lie within band\n"
      "(m; inf: any distance). None when fewer than min_share of the points lie on it.\n"
      "The support plane the aligner removes from a cluttered scene is this plane.");

  m.def("voxel_downsample", &voxel_downsample, py::arg("cloud"), py::arg("voxel_size"),
        py::call_guard<py::gil_scoped_release>(),
        "Replace the points of each voxel_size cube (metres) by their centroid; normals averaged.");

  m.def(
      "prepare_cloud",
      [](const PointCloud& cloud, double voxel_size, bool downsample,
         const Eigen::Vector3d& viewpoint, const std::string& argument) {
        py::gil_scoped_release release;
        return prepare_cloud(cloud, voxel_size, downsample, viewpoint, argument);
      },
      py::arg("cloud"), py::arg("voxel_size"), py::arg("downsample") = true,
      py::arg("viewpoint") = Eigen::Vector3d::Zero(), py::arg("argument") = "cloud",
      R"doc(
The cloud as align(), align_views() and the servo take it: downsampled to half of
voxel_size (metres; downsample=False keeps every point), with normals where it has none,
fitted over a radius of twice voxel_size and turned toward viewpoint (the sensor's origin),
or outward from the centroid when viewpoint lies inside the cloud's bounding box (a model
centred at the origin). Every error names ``argument`` and the step that failed.
)doc");

  m.def(
      "estimate_normals",
      [](const PointCloud& cloud, double radius, int k_neighbors, const Eigen::Vector3d& viewpoint,
         const std::string& orientation, int threads) {
        NormalEstimationParams params;
        params.radius = radius;
        params.k_neighbors = k_neighbors;
        params.viewpoint = viewpoint;
        params.orientation = parse_choice(orientation, kOrientations, "orientation");
        params.threads = threads;
        py::gil_scoped_release release;
        return estimate_normals(cloud, params);
      },
      py::arg("cloud"), py::arg("radius") = 0.015, py::arg("k_neighbors") = 0,
      py::arg("viewpoint") = Eigen::Vector3d::Zero(), py::arg("orientation") = "toward_viewpoint",
      py::arg("threads") = 1,
      "Plane-fit normals (PCL), oriented toward `viewpoint` or 'outward' from the centroid.");

  py::class_<GridSpec>(m, "GridSpec",
                       "Origin (m), resolution (m) and dims (voxels) of a voxel grid.")
      .def(py::init([](const Eigen::Vector3d& origin, double resolution,
                       const std::array<long long, 3>& dims) {
             // Checked here: a Python int past the range of int would otherwise wrap.
             if (!origin.allFinite()) throw py::value_error("origin must be finite");
             if (!(std::isfinite(resolution) && resolution > 0.0)) {
               throw py::value_error("resolution must be finite and > 0 metres");
             }
             GridSpec spec;
             for (int axis = 0; axis < 3; ++axis) {
               if (dims[axis] < 1 || dims[axis] > kMaxGridIndex) {
                 throw py::value_error("dims must be in [1, " + std::to_string(kMaxGridIndex) +
                                       "], got " + std::to_string(dims[axis]));
               }
               spec.dims[axis] = static_cast<int>(dims[axis]);
             }
             spec.origin = origin;
             spec.resolution = resolution;
             return spec;
           }),
           py::arg("origin"), py::arg("resolution"), py::arg("dims"))
      .def_readonly("origin", &GridSpec::origin)
      .def_readonly("resolution", &GridSpec::resolution)
      .def_readonly("dims", &GridSpec::dims)
      .def_property_readonly("voxel_count", &GridSpec::voxel_count)
      .def("index_of", &GridSpec::index_of, py::arg("point"),
           "floor((point - origin) / resolution).")
      .def("__repr__", [](const GridSpec& s) {
        std::ostringstream out;
        out << "GridSpec(origin=[" << s.origin.transpose() << "], resolution=" << s.resolution
            << ", dims=[" << s.dims.transpose() << "])";
        return out.str();
      });

  m.def("fft_friendly_size", &fft_friendly_size, py::arg("n"),
        "Smallest n' >= n (2 for n <= 2) on which FFTW is fast: a measured table up to 1024, then "
        "even "
        "products of 2, 3 and 5. n <= 2^30.");

  m.def(
      "make_grid_spec",
      [](const PointCloud& a, const PointCloud& b, double resolution, long long max_voxels) {
        return make_grid_spec(bounding_box(a), bounding_box(b), resolution,
                              GridLimits{to_max_voxels(max_voxels)});
      },
      py::arg("cloud_a"), py::arg("cloud_b"), py::arg("resolution"),
      py::arg("max_voxels") = static_cast<long long>(GridLimits{}.max_voxels),
      "A grid holding both clouds in which their shift cannot alias; refuses grids over "
      "max_voxels.");

  py::class_<VoxelGrid>(m, "VoxelGrid", "Voxel values on a GridSpec (eq. 1-2).")
      .def_readonly("spec", &VoxelGrid::spec)
      .def_property_readonly(
          "values",
          [](py::object self) { return grid_values(self.cast<const VoxelGrid&>(), self); },
          "(nx, ny, nz) float32 read-only view of the voxel values.")
      .def_readonly("points_outside", &VoxelGrid::points_outside)
      .def_readonly("occupied_min", &VoxelGrid::occupied_min)
      .def_readonly("occupied_max", &VoxelGrid::occupied_max)
      .def("__repr__", [](const VoxelGrid& g) {
        std::ostringstream out;
        out << "VoxelGrid(dims=[" << g.spec.dims.transpose()
            << "], resolution=" << g.spec.resolution << ", points_outside=" << g.points_outside
            << ")";
        return out.str();
      });

  m.def(
      "voxelize",
      [](const PointCloud& cloud, const GridSpec& spec, const std::string& occupancy,
         long long max_voxels) {
        const Occupancy parsed = parse_choice(occupancy, kOccupancies, "occupancy");
        py::gil_scoped_release release;
        return voxelize(cloud, spec, parsed, GridLimits{to_max_voxels(max_voxels)});
      },
      py::arg("cloud"), py::arg("spec"), py::arg("occupancy") = "binary",
      py::arg("max_voxels") = static_cast<long long>(GridLimits{}.max_voxels),
      "Voxel grid of a cloud: 'binary' (eq. 2), 'count' or 'trilinear' occupancy.");

  m.def(
      "egi",
      [](const py::handle& cloud_or_normals, int bandwidth,
         std::optional<Eigen::VectorXd> weights) {
        const Points normals = normals_of(cloud_or_normals);
        return egi_histogram(normals, bandwidth, weights ? &*weights : nullptr);
      },
      py::arg("cloud_or_normals"), py::arg("bandwidth"), py::arg("weights") = py::none(),
      "EGI of eq. (4): (2B, 2B) histogram of normals indexed [j, k] at theta_j, phi_k.");

  m.def("egi_cell", &egi_cell, py::arg("normal"), py::arg("bandwidth"),
        "(j, k) of the grid node nearest to a unit normal.");

  m.def(
      "sphere_grid",
      [](int bandwidth) {
        require_bandwidth(bandwidth);
        Eigen::VectorXd theta(2 * bandwidth), phi(2 * bandwidth);
        for (int i = 0; i < 2 * bandwidth; ++i) {
          theta[i] = grid_theta(i, bandwidth);
          phi[i] = grid_phi(i, bandwidth);
        }
        return py::make_tuple(theta, phi);
      },
      py::arg("bandwidth"), "(theta_j, phi_k) of the 2B x 2B grid, radians.");
}

}  // namespace spectral_vs::python
