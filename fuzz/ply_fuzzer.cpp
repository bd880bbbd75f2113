// The PLY reader on any bytes: ascii and binary (little and big endian) files, with and
// without normals (the seeds hold each). A bad file is std::invalid_argument; a file that
// loads gives finite points, unit normals and counts that add up.

#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  spectral_vs::fuzz::check_reader(data, size, ".ply");
  return 0;
}
