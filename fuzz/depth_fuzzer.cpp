// cloud_from_depth on random depth images: raw (uint16, any scale) or floating (float or
// double, with NaN, infinities and negative depths), any size up to 48 x 48, a camera
// matrix that may not be one, and random settings (the integer ones over int's whole
// range). Either the call refuses the input with
// std::invalid_argument, or the cloud keeps what depth_image.hpp promises: finite points
// inside the depth range, unit normals toward the camera, no more points than lattice
// pixels, and the organized call agrees with it point for point.

#include <spectral_vs/representation/depth_image.hpp>

#include "fuzz_support.hpp"

#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace {

using namespace spectral_vs;

Eigen::Matrix3d random_camera(FuzzedDataProvider& in) {
  Eigen::Matrix3d K = Eigen::Matrix3d::Zero();
  K(0, 0) = in.ConsumeFloatingPointInRange(-10.0, 600.0);
  K(1, 1) = in.ConsumeFloatingPointInRange(-10.0, 600.0);
  K(0, 2) = in.ConsumeFloatingPointInRange(-50.0, 100.0);
  K(1, 2) = in.ConsumeFloatingPointInRange(-50.0, 100.0);
  K(2, 2) = 1.0;
  if (in.ConsumeBool()) {  // something that is not a camera matrix
    const int entry = in.ConsumeIntegralInRange(0, 8);
    const double values[] = {0.0,
                             1.0,
                             -1.0,
                             std::numeric_limits<double>::quiet_NaN(),
                             std::numeric_limits<double>::infinity(),
                             1e300};
    K(entry / 3, entry % 3) = values[in.ConsumeIntegralInRange(0, 5)];
  }
  return K;
}

// An integer setting: mostly small (where the stencils work), else anywhere in int's
// range or at one of its edges (where 2 * normal_step and h + stride - 1 overflowed, and
// window = 2^16 + 1 took 33 s).
int integer_setting(FuzzedDataProvider& in, int small_max) {
  switch (in.ConsumeIntegralInRange(0, 3)) {
    case 0:
      return in.ConsumeIntegral<int>();
    case 1: {
      const int edges[] = {std::numeric_limits<int>::min(), -1, (1 << 16) + 1, 1 << 30,
                           std::numeric_limits<int>::max()};
      return edges[in.ConsumeIntegralInRange(0, 4)];
    }
    default:
      return in.ConsumeIntegralInRange(0, small_max);
  }
}

DepthCloudParams random_params(FuzzedDataProvider& in) {
  DepthCloudParams p;
  p.normal_step = integer_setting(in, 4);
  p.window = integer_setting(in, 7);
  p.max_depth_jump = in.ConsumeFloatingPointInRange(-0.1, 0.5);
  p.stride = integer_setting(in, 4);
  if (in.ConsumeBool()) p.depth_scale = in.ConsumeFloatingPointInRange(-10.0, 10000.0);
  p.min_depth = in.ConsumeFloatingPointInRange(-1.0, 2.0);
  p.max_depth = in.ConsumeBool() ? std::numeric_limits<double>::infinity()
                                 : in.ConsumeFloatingPointInRange(-1.0, 10.0);
  p.normals = in.ConsumeBool();
  return p;
}

template <typename Image>
Image random_image(FuzzedDataProvider& in, int rows, int cols) {
  Image depth(rows, cols);
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) {
      using Scalar = typename Image::Scalar;
      if constexpr (std::is_integral_v<Scalar>) {
        depth(i, j) = in.ConsumeIntegral<Scalar>();
      } else {
        // Mostly smooth metric depth, sometimes any bit pattern (NaN, inf, negative).
        depth(i, j) = in.ConsumeBool()
                          ? static_cast<Scalar>(in.ConsumeFloatingPointInRange(0.0, 5.0))
                          : in.ConsumeFloatingPoint<Scalar>();
      }
    }
  }
  return depth;
}

void check_cloud(const PointCloud& cloud, const OrganizedCloud& organized,
                 const DepthCloudParams& params, int rows, int cols) {
  using fuzz::check;
  fuzz::check_cloud(cloud);
  const int stride = params.stride;
  const Eigen::Index lattice =
      Eigen::Index((rows + stride - 1) / stride) * Eigen::Index((cols + stride - 1) / stride);
  check(organized.points.rows() == lattice, "the organized cloud is not the lattice");
  check(cloud.size() <= lattice, "more points than lattice pixels");
  check(cloud.size() == 0 || params.normals == cloud.has_normals(),
        "normals present against params.normals");
  for (Eigen::Index i = 0; i < cloud.size(); ++i) {
    const double z = cloud.points()(i, 2);
    check(z > 0.0 && z >= params.min_depth - 1e-9 && z <= params.max_depth + 1e-9,
          "a point outside the depth range");
    if (cloud.has_normals()) {
      check(cloud.normals().row(i).dot(cloud.points().row(i)) <= 1e-9,
            "a normal turned away from the camera");
    }
  }
  const PointCloud again = organized.valid_cloud();
  check(again.size() == cloud.size() && again.points() == cloud.points(),
        "organized_cloud_from_depth disagrees with cloud_from_depth");
}

template <typename Image>
void run(FuzzedDataProvider& in) {
  const int rows = in.ConsumeIntegralInRange(0, 48);
  const int cols = in.ConsumeIntegralInRange(0, 48);
  const Eigen::Matrix3d K = random_camera(in);
  const DepthCloudParams params = random_params(in);
  const Image depth = random_image<Image>(in, rows, cols);
  PointCloud cloud;
  try {
    cloud = cloud_from_depth(depth, K, params);
  } catch (const std::invalid_argument&) {
    return;  // refused, with a message naming the argument
  } catch (const std::exception& error) {
    fuzz::fail(std::string("cloud_from_depth threw other than invalid_argument: ") + error.what());
  }
  try {
    check_cloud(cloud, organized_cloud_from_depth(depth, K, params), params, rows, cols);
  } catch (const std::exception& error) {
    fuzz::fail(std::string("organized_cloud_from_depth threw after cloud_from_depth did not: ") +
               error.what());
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  switch (in.ConsumeIntegralInRange(0, 2)) {
    case 0:
      run<RawDepthImage>(in);
      break;
    case 1:
      run<DepthImageF>(in);
      break;
    default:
      run<DepthImage>(in);
      break;
  }
  return 0;
}
