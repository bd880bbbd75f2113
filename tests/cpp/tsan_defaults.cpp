// Built into the test programs of the ThreadSanitizer build only (SPECTRAL_VS_SANITIZE_THREAD).
// Compiled in, rather than given in TSAN_OPTIONS, so that it also holds when CMake lists a
// program's tests right after linking it. Two suppressions, both of third-party code that
// ThreadSanitizer cannot judge; nothing of spectral_vs or FFTW is suppressed
// (docs/reliability.md, "ThreadSanitizer"):
//
// - OpenNI2, which spectral_vs never calls: PCL's I/O library links it, and its static
//   constructors and destructors unlock mutexes it has already destroyed, at start-up and
//   exit of any program linked with it ("unlock of an unlocked mutex" in libOpenNI2.so.0,
//   no frame of this project).
// - PCL's OpenMP normal estimation (estimate_normals with threads > 1): it runs in GCC's
//   OpenMP runtime (libgomp, not instrumented), whose barriers TSan does not see, so the
//   workers' reads inside the parallel region look unordered with the main thread's frees
//   after it (reported in pcl::NormalEstimationOMP::computeFeature). The region's end
//   orders them; the normals are checked against one thread bit for bit in threads_test.
extern "C" const char* __tsan_default_suppressions() {
  return "called_from_lib:libOpenNI2.so.0\n"
         "race:pcl::NormalEstimationOMP\n";
}
