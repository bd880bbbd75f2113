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

/// Whether an alternative replaced the refined pose `best` (the rule of reselection.cpp).
bool reselect(const Problem& problem, Prepared& prepared, const PointCloud& model,
              const std::optional<PartCoverage>& coverage, AlignResult& best);

/// Whether a resting pose replaced `best`, one that does not rest by `check` (made on
/// prepared's support plane; kRestingMargin).
bool rest_on_support(const Problem& problem, Prepared& prepared, const PointCloud& model,
                     const Verifier& verifier, const RestingCheck& check, AlignResult& best);

}  // namespace spectral_vs::detail
