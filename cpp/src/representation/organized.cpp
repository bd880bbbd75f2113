#include <spectral_vs/representation/organized.hpp>

#include "common/checks.hpp"
#include "representation/organized_detail.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace detail {

void check_organized(const PinholeIntrinsics& intrinsics, const OrganizedNormalParams& params,
                     long long rows, long long cols) {
  if (rows < 1 || cols < 1) fail("depth is empty: ", rows, " x ", cols, " pixels");
  if (rows * cols > kMaxDepthPixels) {
    fail("depth has ", rows, " x ", cols, " pixels, over the ", kMaxDepthPixels,
         " that a cloud is made of (8192 x 8192)");
  }
  const long long side = std::max(rows, cols);
  if (params.normal_step > side) {
    fail("normal_step must be <= the image's larger side, ", side, " pixels, got ",
         params.normal_step);
  }
  if (params.window > 2 * side + 1) {
    fail("window must be <= twice the image's larger side plus one, ", 2 * side + 1,
         " pixels, got ", params.window);
  }
  if (params.stride > side) {
    fail("stride must be <= the image's larger side, ", side, " pixels, got ", params.stride);
  }
  require_positive_finite(intrinsics.fx, "fx");
  require_positive_finite(intrinsics.fy, "fy");
  if (!std::isfinite(intrinsics.cx) || !std::isfinite(intrinsics.cy)) {
    fail("the principal point (cx, cy) must be finite, got (", intrinsics.cx, ", ", intrinsics.cy,
         ")");
  }
  if (params.normal_step < 1) fail("normal_step must be >= 1, got ", params.normal_step);
  if (params.window < 1 || params.window % 2 == 0)
    fail("window must be odd and >= 1, got ", params.window);
  if (!(params.max_depth_jump > 0.0))
    fail("max_depth_jump must be > 0, got ", params.max_depth_jump);
  if (params.stride < 1) fail("stride must be >= 1, got ", params.stride);
}

namespace {

// Scratch buffers kept per thread: a servo converts one image of the same size per step.
struct Scratch {
  std::vector<double> cross[3];    // per interior pixel, zero where unreliable
  std::vector<double> columns[3];  // per kept interior row: sums over the window's rows
  std::vector<unsigned char> reliable;
};

}  // namespace

void scan_depth(const double* d, int h, int w, const PinholeIntrinsics& intrinsics,
                const OrganizedNormalParams& params, const ScanOutput& output,
                std::vector<double>& out) {
  out.clear();
  const int s = params.normal_step, r = params.window / 2, stride = params.stride;
  // Normals need the whole stencil: the interior (rows and columns s .. size - s - 1).
  const bool normals = output.normals && h > 2 * s && w > 2 * s;
  if (output.normals && !normals && !output.every_pixel) return;  // no pixel has a normal

  // Back-projection factors of each column and row: x = d (u - cx) / fx, y = d (v - cy) / fy.
  std::vector<double> along_u(static_cast<std::size_t>(w)), along_v(static_cast<std::size_t>(h));
  for (int u = 0; u < w; ++u) along_u[std::size_t(u)] = (u - intrinsics.cx) / intrinsics.fx;
  for (int v = 0; v < h; ++v) along_v[std::size_t(v)] = (v - intrinsics.cy) / intrinsics.fy;
  auto at = [&](int v, int u) { return d[std::size_t(v) * std::size_t(w) + std::size_t(u)]; };

  const int ih = normals ? h - 2 * s : 0, iw = normals ? w - 2 * s : 0;
  const std::size_t interior = std::size_t(ih) * std::size_t(iw);
  thread_local Scratch per_thread;
  Scratch& scratch = per_thread;  // one look-up of the thread's buffers, not one per access
  for (auto& c : scratch.cross) c.assign(interior, 0.0);
  scratch.reliable.assign(interior, 0);
  double* const cross_x = scratch.cross[0].data();
  double* const cross_y = scratch.cross[1].data();
  double* const cross_z = scratch.cross[2].data();
  unsigned char* const reliable = scratch.reliable.data();
  for (int i = 0; i < ih; ++i) {
    const int v = i + s;
    const double yv = along_v[std::size_t(v)], y_up = along_v[std::size_t(v - s)],
                 y_down = along_v[std::size_t(v + s)];
    for (int j = 0; j < iw; ++j) {
      const int u = j + s;
      const double z = at(v, u);
      if (!std::isfinite(z)) continue;
      const double limit = params.max_depth_jump * z;
      const double z_right = at(v, u + s), z_left = at(v, u - s), z_down = at(v + s, u),
                   z_up = at(v - s, u);
      // Written so that a NaN neighbour fails the test.
      if (!(std::abs(z_right - z) <= limit && std::abs(z_left - z) <= limit &&
            std::abs(z_down - z) <= limit && std::abs(z_up - z) <= limit)) {
        continue;
      }
      const double xu_right = along_u[std::size_t(u + s)], xu_left = along_u[std::size_t(u - s)],
                   xu = along_u[std::size_t(u)];
      // Central differences along the columns (a) and the rows (b).
      const double ax = z_right * xu_right - z_left * xu_left, ay = z_right * yv - z_left * yv,
                   az = z_right - z_left;
      const double bx = z_down * xu - z_up * xu, by = z_down * y_down - z_up * y_up,
                   bz = z_down - z_up;
      const std::size_t k = std::size_t(i) * std::size_t(iw) + std::size_t(j);
      cross_x[k] = by * az - bz * ay;
      cross_y[k] = bz * ax - bx * az;
      cross_z[k] = bx * ay - by * ax;
      reliable[k] = 1;
    }
  }

  // The lattice: rows and columns multiples of the stride.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::size_t lattice =
      std::size_t((h + stride - 1) / stride) * std::size_t((w + stride - 1) / stride);
  out.reserve(lattice * 6);
  // Column sums with r zeros on either side: the window's columns need no bounds test.
  for (auto& c : scratch.columns) c.assign(normals ? std::size_t(iw + 2 * r) : 0, 0.0);
  // Without normals the columns are empty and unused: no offset into a null buffer.
  const auto column_start = [&](int c) {
    return normals ? scratch.columns[c].data() + r : nullptr;
  };
  double* const columns[3] = {column_start(0), column_start(1), column_start(2)};
  const double* const crosses[3] = {cross_x, cross_y, cross_z};
  for (int v = 0; v < h; v += stride) {
    const int i = v - s;
    const bool interior_row = normals && v >= s && v < h - s;
    if (output.normals && !interior_row && !output.every_pixel) continue;
    if (interior_row) {
      // Sums over the window's rows (zero outside the interior), for every interior column.
      for (int c = 0; c < 3; ++c) {
        double* column = columns[c];
        std::fill(column, column + iw, 0.0);
        for (int row = std::max(i - r, 0); row <= std::min(i + r, ih - 1); ++row) {
          const double* line = crosses[c] + std::size_t(row) * std::size_t(iw);
          for (int j = 0; j < iw; ++j) column[j] += line[j];
        }
      }
    }
    const double yv = along_v[std::size_t(v)];
    for (int u = 0; u < w; u += stride) {
      const double z = at(v, u);
      double n[3] = {nan, nan, nan};
      bool has_normal = false;
      const int j = u - s;
      if (interior_row && u >= s && u < w - s &&
          reliable[std::size_t(i) * std::size_t(iw) + std::size_t(j)]) {
        for (int c = 0; c < 3; ++c) {
          double sum = 0.0;
          for (int dj = -r; dj <= r; ++dj) sum += columns[c][j + dj];
          n[c] = sum;
        }
        const double norm = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        has_normal = norm > 0.0;
        if (has_normal) {
          const double x = z * along_u[std::size_t(u)], y = z * yv;
          // Toward the camera: n . (0 - p) > 0.
          const double scale = (n[0] * x + n[1] * y + n[2] * z > 0.0 ? -1.0 : 1.0) / norm;
          for (double& component : n) component *= scale;
        } else {
          n[0] = n[1] = n[2] = nan;
        }
      }
      if (!output.every_pixel && !(output.normals ? has_normal : std::isfinite(z))) continue;
      const bool has_point = std::isfinite(z);
      const double x = has_point ? z * along_u[std::size_t(u)] : nan;
      const double y = has_point ? z * yv : nan;
      out.insert(out.end(), {x, y, has_point ? z : nan, n[0], n[1], n[2]});
    }
  }
  for (auto& c : scratch.cross) release_if_large(c);
  for (auto& c : scratch.columns) release_if_large(c);
  release_if_large(scratch.reliable);
}

void split_rows(const std::vector<double>& rows, bool with_normals, Points& points,
                Points& normals) {
  // Allocated at their size only now (a frame's cloud is megabytes).
  const Eigen::Index kept = Eigen::Index(rows.size() / 6);
  points.resize(kept, 3);
  normals.resize(with_normals ? kept : 0, 3);
  for (Eigen::Index i = 0; i < kept; ++i) {
    const double* row = rows.data() + 6 * i;
    points.row(i) << row[0], row[1], row[2];
    if (with_normals) normals.row(i) << row[3], row[4], row[5];
  }
}

}  // namespace detail

PointCloud organized_cloud(const Eigen::Ref<const DepthImage>& depth,
                           const PinholeIntrinsics& intrinsics,
                           const OrganizedNormalParams& params) {
  detail::check_organized(intrinsics, params, depth.rows(), depth.cols());
  // The scan reads one row-major block: an Eigen::Ref with an outer stride is copied.
  DepthImage copy;
  const double* data = depth.data();
  if (depth.outerStride() != depth.cols()) {
    copy = depth;
    data = copy.data();
  }
  thread_local std::vector<double> rows;
  detail::scan_depth(data, int(depth.rows()), int(depth.cols()), intrinsics, params,
                     {/*normals=*/true, /*every_pixel=*/false}, rows);
  Points points, normals;
  detail::split_rows(rows, true, points, normals);
  detail::release_if_large(rows);
  return PointCloud(std::move(points), std::move(normals));
}

}  // namespace spectral_vs
