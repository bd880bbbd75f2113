// The PCD reader on any bytes: ascii, binary and binary_compressed files (the seeds hold
// each encoding), organized or not. A bad file is std::invalid_argument; a file that
// loads gives finite points, unit normals and counts that add up.

#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  spectral_vs::fuzz::check_reader(data, size, ".pcd");
  return 0;
}
