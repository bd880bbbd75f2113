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

/// Two normals agree when they are within 45 degrees: what every pairing of a model point
/// with a scene point asks (the verification's pixels and points, the ICP, the covariance,
/// the alternatives' translation fit). A surface turned another way (the other side of a
/// thin part, a flip onto a parallel face, the table under an object) is no support.
inline constexpr double kAgreeingCosine = 0.7071;

}  // namespace spectral_vs::detail
