# Language standard and warnings, set per target (never globally) so that a parent
# project embedding spectral_vs keeps its own flags.
function(spectral_vs_set_compiler_options target)
  target_compile_features(${target} PUBLIC cxx_std_17)
  set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF)
  if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wno-unused-parameter)
    # No errno from math functions: lets sqrt and rounding compile to single
    # instructions and the spectrum loops vectorise. Nothing here reads errno.
    # `#pragma omp simd` marks loops whose float sums may be reordered; no OpenMP runtime.
    target_compile_options(${target} PRIVATE -fno-math-errno -fopenmp-simd)
  endif()
endfunction()
