#pragma once
// The one pass over a metric depth image that both organized_cloud and cloud_from_depth
// run: back-projection and the stencil normals, pixel by pixel of the stride's lattice.

#include <spectral_vs/representation/organized.hpp>

#include <vector>

namespace spectral_vs::detail {

/// What `scan_depth` writes out, of the pixels of the lattice (rows and columns multiples
/// of the stride).
struct ScanOutput {
  bool normals = true;       ///< Compute normals (else NaN normals).
  bool every_pixel = false;  ///< Every lattice pixel, NaN where it has no point or normal;
                             ///< else those with a normal (with normals) or a point.
};

/// Throws std::invalid_argument for invalid intrinsics or normal params, or for an image of
/// `rows` x `cols` pixels that is empty, over kMaxDepthPixels, or smaller than the stencil
/// allows (normal_step over its larger side, window over twice that plus one).
void check_organized(const PinholeIntrinsics& intrinsics, const OrganizedNormalParams& params,
                     long long rows, long long cols);

/// Frees `buffer` when it holds more than kKeptScratchBytes.
template <typename T>
void release_if_large(std::vector<T>& buffer) {
  if (buffer.capacity() * sizeof(T) > kKeptScratchBytes) std::vector<T>().swap(buffer);
}

/// Appends x, y, z, nx, ny, nz (metres, unit normal toward the camera; NaN where missing)
/// per written pixel of the h x w row-major metric depth image `depth` (non-finite: no
/// return) to `out`, in row-major order. The arguments must have been checked.
void scan_depth(const double* depth, int h, int w, const PinholeIntrinsics& intrinsics,
                const OrganizedNormalParams& params, const ScanOutput& output,
                std::vector<double>& out);

/// Splits rows of 6 (point, normal) into the two matrices; no normals when `with_normals`
/// is false.
void split_rows(const std::vector<double>& rows, bool with_normals, Points& points,
                Points& normals);

}  // namespace spectral_vs::detail
