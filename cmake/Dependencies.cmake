# Third-party libraries, each wrapped as a target so the rest of the build links
# targets only. spectral_vs_private_deps gathers what the implementation needs and
# its public headers do not expose (everything but Eigen).
find_package(Eigen3 3.3 REQUIRED NO_MODULE)

find_package(PCL 1.12 REQUIRED COMPONENTS common io filters features kdtree search)

# FFTW ships no usable CMake config on Debian: pkg-config for the library, and the
# threads library beside it by name.
find_package(PkgConfig REQUIRED)
pkg_check_modules(FFTW3F REQUIRED IMPORTED_TARGET fftw3f)
find_library(FFTW3F_THREADS_LIBRARY NAMES fftw3f_threads HINTS ${FFTW3F_LIBRARY_DIRS} REQUIRED)

add_library(spectral_vs_private_deps INTERFACE)
target_include_directories(spectral_vs_private_deps SYSTEM INTERFACE ${PCL_INCLUDE_DIRS})
target_link_libraries(spectral_vs_private_deps INTERFACE
  ${PCL_LIBRARIES} PkgConfig::FFTW3F ${FFTW3F_THREADS_LIBRARY})

# Rotation: the global SO(3) search transforms in double precision (libfftw3).
pkg_check_modules(FFTW3 REQUIRED IMPORTED_TARGET fftw3)
target_link_libraries(spectral_vs_private_deps INTERFACE PkgConfig::FFTW3)

# Kinematics: orocos KDL sets variables only; urdfdom exports targets. The chain is built
# from urdfdom's model in the code, because find_package(kdl_parser) needs ROS's ament.
find_package(orocos_kdl REQUIRED)
find_package(urdfdom CONFIG REQUIRED)
target_include_directories(spectral_vs_private_deps SYSTEM INTERFACE ${orocos_kdl_INCLUDE_DIRS})
target_link_libraries(spectral_vs_private_deps INTERFACE ${orocos_kdl_LIBRARIES} urdfdom::urdfdom_model)
