#pragma once
// Internal to align(): its last stages, after the alternatives. An alternative replaces
// the refined pose (reselect), and in clutter a pose that does not rest on the support
// plane or a scene surface gives way to one that does (rest_on_support).

#include <spectral_vs/alignment/aligner.hpp>

#include "alignment/part_coverage.hpp"
#include "alignment/prepared.hpp"
#include "alignment/resting.hpp"
#include "alignment/stages.hpp"

#include <optional>

namespace spectral_vs::detail {

/// Whether an alternative replaced the refined pose `best` (the rule of reselection.cpp,
/// verification.reselect_margin).
bool reselect(const Problem& problem, const VerificationParams& verification, Prepared& prepared,
              const PointCloud& model, const std::optional<PartCoverage>& coverage,
              AlignResult& best);

/// Whether a resting pose replaced `best`, one that does not rest by `check` (made on
/// prepared's support plane; kRestingMargin): one of the alternatives, or of the model's
/// flat faces down at each of the scene's parts (at most search.max_parts); the pose it
/// adopts rests by `check`. Not with verification.reselect_margin at 1 (reselection off).
bool rest_on_support(const Problem& problem, const VerificationParams& verification,
                     const GlobalSearchParams& search, Prepared& prepared, const PointCloud& model,
                     const Verifier& verifier, const RestingCheck& check, AlignResult& best);

}  // namespace spectral_vs::detail
