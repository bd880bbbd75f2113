#pragma once
// align()'s own refinement, beyond the paper, between Algorithm 1 and the ICP: the sweep
// of the turns about a model's flat axis and the polish of the rotation on the voxel
// overlap, each in a window of the scene around the pose.

#include "alignment/stages.hpp"

namespace spectral_vs::detail {

/// The model is dense enough for the voxel overlap of the sweep and the polish.
bool dense_for_polish(const Points& model_points, double voxel_size);

/// The result turned to the best of its turns about the model's flat axis `axis`.
void sweep_result_about(const Problem& problem, WindowCache& windows, AlignResult& result,
                        const Eigen::Vector3d& axis);

/// The result's rotation polished on the voxel overlap (a pattern search).
void polish_result_rotation(const Problem& problem, WindowCache& windows, AlignResult& result);

}  // namespace spectral_vs::detail
