// Times FFTW's forward + inverse real 3D transform of n^3 grids, single precision, with
// the library's planning flag (FFTW_ESTIMATE, deterministic) and, given any argument,
// with FFTW_MEASURE for comparison. Prints "n milliseconds nanoseconds-per-voxel" per
// even length with factors 2, 3, 5 from 16 to 128: the data behind fft_friendly_size.
#include <fftw3.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <vector>

namespace {

double thread_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * double(t.tv_sec) + 1e-6 * double(t.tv_nsec);
}

bool smooth_even(int n) {
  if (n % 2) return false;
  for (int p : {2, 3, 5}) {
    while (n % p == 0) n /= p;
  }
  return n == 1;
}

double median_pair_ms(int n, unsigned flags, int runs) {
  const std::size_t voxels = std::size_t(n) * n * n;
  float* real = fftwf_alloc_real(voxels);
  fftwf_complex* spectrum = fftwf_alloc_complex(std::size_t(n) * n * (n / 2 + 1));
  fftwf_plan forward = fftwf_plan_dft_r2c_3d(n, n, n, real, spectrum, flags);
  fftwf_plan inverse = fftwf_plan_dft_c2r_3d(n, n, n, spectrum, real, flags);
  std::vector<double> times;
  for (int k = 0; k < runs; ++k) {
    std::fill(real, real + voxels, 0.0f);
    const double start = thread_ms();
    fftwf_execute(forward);
    fftwf_execute(inverse);
    times.push_back(thread_ms() - start);
  }
  fftwf_destroy_plan(forward);
  fftwf_destroy_plan(inverse);
  fftwf_free(real);
  fftwf_free(spectrum);
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const unsigned flags = argc > 1 ? FFTW_MEASURE : FFTW_ESTIMATE;
  for (int n = 16; n <= 128; n += 2) {
    if (!smooth_even(n)) continue;
    const double ms = median_pair_ms(n, flags, 15);
    std::printf("%d %.3f %.2f\n", n, ms, ms * 1e6 / (double(n) * n * n));
  }
  return 0;
}
