#include <spectral_vs/representation/depth_image.hpp>

#include "common/checks.hpp"
#include "representation/organized_detail.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

void check(const DepthCloudParams& params) {
  if (params.depth_scale && !(std::isfinite(*params.depth_scale) && *params.depth_scale > 0.0)) {
    fail("depth_scale must be finite and > 0 sensor units per metre, got ", *params.depth_scale);
  }
  if (!(std::isfinite(params.min_depth) && params.min_depth >= 0.0)) {
    fail("min_depth must be finite and >= 0 metres, got ", params.min_depth);
  }
  if (!(params.max_depth > params.min_depth)) {  // inf allowed: no truncation; NaN refused
    fail("max_depth must be > min_depth = ", params.min_depth, " metres, got ", params.max_depth);
  }
}

[[noreturn]] void no_valid_pixel(Eigen::Index pixels, double scale,
                                 const DepthCloudParams& params) {
  fail("depth has no valid pixel: all ", pixels, " are 0, non-finite or outside [min_depth, ",
       "max_depth] = [", params.min_depth, ", ", params.max_depth, "] m (depth_scale ", scale,
       " units per metre)");
}

// Whether the metre value z is a valid depth; written without branches (the loops over
// pixels vectorise), NaN failing every comparison.
inline bool valid_depth(double z, double low, double high) {
  return (z > 0.0) & (z >= low) & (z <= high) & (z < std::numeric_limits<double>::infinity());
}

// Buffers kept per thread between frames (released after a frame when large).
std::vector<double>& metres_buffer() {
  thread_local std::vector<double> metres;
  return metres;
}

std::vector<double>& rows_buffer() {
  thread_local std::vector<double> rows;
  return rows;
}

// The depth in metres, row-major, NaN where the pixel is invalid (see DepthCloudParams):
// the image itself when it is one block of metres whose every pixel is valid or NaN (a
// renderer's or a driver's float frame), else a copy in a buffer kept per thread (one
// frame of the same size per servo step).
template <typename Image>
const double* metric_depth(const Eigen::Ref<const Image>& depth, double scale,
                           const DepthCloudParams& params) {
  const Eigen::Index h = depth.rows(), w = depth.cols();
  const double low = params.min_depth, high = params.max_depth;
  if constexpr (std::is_same_v<typename Image::Scalar, double>) {
    if (scale == 1.0 && depth.outerStride() == w) {
      std::size_t valid = 0, missing = 0;  // the rest: finite or infinite but invalid
      const double* in = depth.data();
      for (Eigen::Index i = 0; i < h * w; ++i) {
        valid += valid_depth(in[i], low, high);
        missing += in[i] != in[i];  // NaN
      }
      if (valid == 0) no_valid_pixel(h * w, scale, params);
      if (valid + missing == std::size_t(h * w)) return in;
    }
  }
  std::vector<double>& metres = metres_buffer();
  metres.resize(std::size_t(h) * std::size_t(w));
  std::size_t valid = 0;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (Eigen::Index v = 0; v < h; ++v) {
    // A row of a row-major image is contiguous; rows are outerStride() apart.
    const auto* in = depth.data() + v * depth.outerStride();
    double* row = metres.data() + std::size_t(v) * std::size_t(w);
    for (Eigen::Index u = 0; u < w; ++u) {
      // Divided rather than multiplied by 1 / scale: metres images pass through exactly.
      const double z = double(in[u]) / scale;
      const bool ok = valid_depth(z, low, high);
      row[u] = ok ? z : nan;
      valid += ok;
    }
  }
  if (valid == 0) no_valid_pixel(h * w, scale, params);
  return metres.data();
}

template <typename Image>
std::vector<double>& scan(const Eigen::Ref<const Image>& depth, const Eigen::Matrix3d& K,
                          const DepthCloudParams& params, double default_scale, bool every_pixel) {
  const PinholeIntrinsics intrinsics = intrinsics_from_matrix(K, "K");
  detail::check_organized(intrinsics, params, depth.rows(), depth.cols());
  check(params);
  const double* metres =
      metric_depth<Image>(depth, params.depth_scale.value_or(default_scale), params);
  std::vector<double>& rows = rows_buffer();
  detail::scan_depth(metres, int(depth.rows()), int(depth.cols()), intrinsics, params,
                     {params.normals, every_pixel}, rows);
  detail::release_if_large(metres_buffer());
  return rows;
}

template <typename Image>
PointCloud cloud_of(const Eigen::Ref<const Image>& depth, const Eigen::Matrix3d& K,
                    const DepthCloudParams& params, double default_scale) {
  const std::vector<double>& rows = scan<Image>(depth, K, params, default_scale, false);
  Points points, normals;
  detail::split_rows(rows, params.normals, points, normals);
  detail::release_if_large(rows_buffer());
  return PointCloud(std::move(points), std::move(normals));
}

template <typename Image>
OrganizedCloud organized_of(const Eigen::Ref<const Image>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params, double default_scale) {
  const std::vector<double>& rows = scan<Image>(depth, K, params, default_scale, true);
  OrganizedCloud out;
  out.height = int((depth.rows() + params.stride - 1) / params.stride);
  out.width = int((depth.cols() + params.stride - 1) / params.stride);
  detail::split_rows(rows, params.normals, out.points, out.normals);
  detail::release_if_large(rows_buffer());
  return out;
}

double scale_of(std::optional<double> depth_scale, double default_scale) {
  const double scale = depth_scale.value_or(default_scale);
  if (!(std::isfinite(scale) && scale > 0.0)) {
    fail("depth_scale must be finite and > 0 sensor units per metre, got ", scale);
  }
  return scale;
}

template <typename Image>
DepthScaleCheck scale_check(const Eigen::Ref<const Image>& depth, double scale) {
  DepthScaleCheck check;
  check.depth_scale = scale;
  // Compared in the image's units (no division per pixel), in its own type for floats.
  using Value = std::conditional_t<std::is_same_v<typename Image::Scalar, double>, double, float>;
  const auto low = Value(kPlausibleMinDepth * scale), high = Value(kPlausibleMaxDepth * scale);
  const auto infinity = std::numeric_limits<Value>::infinity();
  for (Eigen::Index v = 0; v < depth.rows(); ++v) {
    const auto* in = depth.data() + v * depth.outerStride();
    std::size_t valid = 0, plausible = 0;
    for (Eigen::Index u = 0; u < depth.cols(); ++u) {
      const auto z = Value(in[u]);
      valid += (z > Value(0)) & (z < infinity);
      plausible += (z >= low) & (z <= high);
    }
    check.valid += valid;
    check.plausible += plausible;
  }
  return check;
}

template <typename Image>
double median_of(const Eigen::Ref<const Image>& depth, double scale) {
  std::vector<double> values;
  values.reserve(std::size_t(depth.size()));
  for (Eigen::Index v = 0; v < depth.rows(); ++v) {
    const auto* in = depth.data() + v * depth.outerStride();
    for (Eigen::Index u = 0; u < depth.cols(); ++u) {
      const double z = double(in[u]) / scale;
      if (z > 0.0 && z < std::numeric_limits<double>::infinity()) values.push_back(z);
    }
  }
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace

DepthScaleCheck check_depth_scale(const Eigen::Ref<const RawDepthImage>& depth,
                                  std::optional<double> depth_scale) {
  return scale_check<RawDepthImage>(depth, scale_of(depth_scale, kDefaultDepthScale));
}
DepthScaleCheck check_depth_scale(const Eigen::Ref<const DepthImageF>& depth,
                                  std::optional<double> depth_scale) {
  return scale_check<DepthImageF>(depth, scale_of(depth_scale, 1.0));
}
DepthScaleCheck check_depth_scale(const Eigen::Ref<const DepthImage>& depth,
                                  std::optional<double> depth_scale) {
  return scale_check<DepthImage>(depth, scale_of(depth_scale, 1.0));
}

double median_depth(const Eigen::Ref<const RawDepthImage>& depth,
                    std::optional<double> depth_scale) {
  return median_of<RawDepthImage>(depth, scale_of(depth_scale, kDefaultDepthScale));
}
double median_depth(const Eigen::Ref<const DepthImageF>& depth, std::optional<double> depth_scale) {
  return median_of<DepthImageF>(depth, scale_of(depth_scale, 1.0));
}
double median_depth(const Eigen::Ref<const DepthImage>& depth, std::optional<double> depth_scale) {
  return median_of<DepthImage>(depth, scale_of(depth_scale, 1.0));
}

PinholeIntrinsics intrinsics_from_matrix(const Eigen::Matrix3d& K, const std::string& argument) {
  if (!K.allFinite()) fail(argument, " must have finite entries");
  const double tolerance = 1e-9;
  if (std::abs(K(2, 0)) > tolerance || std::abs(K(2, 1)) > tolerance ||
      std::abs(K(2, 2) - 1.0) > tolerance) {
    fail(argument, " must be a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]: its bottom ",
         "row is (", K(2, 0), ", ", K(2, 1), ", ", K(2, 2), "), not (0, 0, 1)");
  }
  if (K(0, 1) != 0.0 || K(1, 0) != 0.0) {
    fail(argument, " must have no skew: K[0, 1] and K[1, 0] must be 0, got ", K(0, 1), " and ",
         K(1, 0));
  }
  if (!(K(0, 0) > 0.0 && K(1, 1) > 0.0)) {
    fail(argument, " must have focal lengths fx = K[0, 0] > 0 and fy = K[1, 1] > 0 pixels, got ",
         K(0, 0), " and ", K(1, 1));
  }
  return {K(0, 0), K(1, 1), K(0, 2), K(1, 2)};
}

bool OrganizedCloud::valid(Eigen::Index row) const {
  return std::isfinite(points(row, 2)) && (!has_normals() || std::isfinite(normals(row, 0)));
}

PointCloud OrganizedCloud::valid_cloud() const {
  std::vector<char> keep(std::size_t(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) keep[std::size_t(i)] = valid(i);
  Eigen::Index kept = 0;
  for (char k : keep) kept += k;
  Points p(kept, 3), n(has_normals() ? kept : 0, 3);
  for (Eigen::Index i = 0, k = 0; i < points.rows(); ++i) {
    if (!keep[std::size_t(i)]) continue;
    p.row(k) = points.row(i);
    if (has_normals()) n.row(k) = normals.row(i);
    ++k;
  }
  return PointCloud(std::move(p), std::move(n));
}

PointCloud cloud_from_depth(const Eigen::Ref<const RawDepthImage>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params) {
  return cloud_of<RawDepthImage>(depth, K, params, kDefaultDepthScale);
}
PointCloud cloud_from_depth(const Eigen::Ref<const DepthImageF>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params) {
  return cloud_of<DepthImageF>(depth, K, params, 1.0);
}
PointCloud cloud_from_depth(const Eigen::Ref<const DepthImage>& depth, const Eigen::Matrix3d& K,
                            const DepthCloudParams& params) {
  return cloud_of<DepthImage>(depth, K, params, 1.0);
}

OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const RawDepthImage>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params) {
  return organized_of<RawDepthImage>(depth, K, params, kDefaultDepthScale);
}
OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const DepthImageF>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params) {
  return organized_of<DepthImageF>(depth, K, params, 1.0);
}
OrganizedCloud organized_cloud_from_depth(const Eigen::Ref<const DepthImage>& depth,
                                          const Eigen::Matrix3d& K,
                                          const DepthCloudParams& params) {
  return organized_of<DepthImage>(depth, K, params, 1.0);
}

}  // namespace spectral_vs
