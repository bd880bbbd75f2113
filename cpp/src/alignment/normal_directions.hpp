#pragma once
// Internal to the aligner: a normal as one of the 26 directions to a voxel's neighbours,
// how the verification's voxel screen (FitnessMap) and the view aligner bin normals.

#include <Eigen/Core>
#include <cstdint>

namespace spectral_vs::detail {

/// The nearest of the 26 directions to a voxel's neighbours (about 35-45 degrees apart)
/// to `normal` (either of exact equals); in `cone`, if given, every direction within 50
/// degrees of it together with the nearest.
int normal_direction(const Eigen::Vector3d& normal, std::uint32_t* cone = nullptr);

}  // namespace spectral_vs::detail
