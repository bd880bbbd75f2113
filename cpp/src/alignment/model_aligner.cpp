#include <spectral_vs/alignment/model_aligner.hpp>

#include <spectral_vs/rotation/so3.hpp>
#include <spectral_vs/rotation/so3_correlation.hpp>
#include <spectral_vs/translation/phase_correlation.hpp>

#include "alignment/algorithm1.hpp"
#include "alignment/align_detail.hpp"
#include "alignment/moving_model.hpp"
#include "alignment/point_sets.hpp"
#include "alignment/polish.hpp"
#include "alignment/refinement.hpp"
#include "alignment/scale.hpp"
#include "alignment/scene_map.hpp"
#include "alignment/verdict_detail.hpp"
#include "alignment/verifier.hpp"
#include "common/checks.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <optional>
#include <vector>

namespace spectral_vs {

using detail::fail;

namespace {

using Clock = std::chrono::steady_clock;

// Phase correlations of other grid sizes a ModelAligner keeps besides the current one
// (about 20 bytes per voxel each: 8 MB for a 0.4 M-voxel grid).
constexpr std::size_t kKeptPlans = 3;

using detail::Pose;
using detail::seconds_since;

}  // namespace

struct ModelAligner::Impl {
  PointCloud model;
  AlignParams params;
  // The model's side, prepared once.
  std::optional<detail::MovingModel> moving_model;
  ShCoefficients model_coefficients;
  Eigen::Vector3i max_shift = Eigen::Vector3i::Zero();  // voxels, of max_translation
  // Re-used per scene: the translation grid's transforms and voxels.
  std::optional<PhaseCorrelation> phase;
  // Grids of other sizes seen lately, most recent first: a camera moving between views
  // of a few grid sizes re-uses their FFT plans and buffers (new ones for a 0.4 M-voxel
  // grid took 2-5 ms, as much as the step's two transforms).
  std::vector<PhaseCorrelation> kept_plans;
  VoxelGrid target, moving;
  ModelAlignerTimings timings;
  bool dense_model = false;  // sampled densely enough for the ICP's fine stage
  // Held by each align() for the whole call: calls from several threads share the
  // buffers above, so they run one at a time (guarded by ThreadSanitizer in threads_test).
  mutable std::mutex busy;

  bool local() const { return !params.search.global_search && params.local.max_translation > 0.0; }

  Pose pose_of(const Transform& T_scene_model) const {
    return moving_model->pose_of(T_scene_model);
  }
  Transform transform_of(const Pose& pose) const { return moving_model->transform_of(pose); }
  const Points& move(const Pose& pose) { return moving_model->move(pose); }

  // The scene's voxels and spectrum on the bounded grid around the model's start; the
  // FFT plans and buffers are kept while the grid's size stays the same.
  GridSpec place_grid(const PointCloud& scene, const Pose& start) {
    const Eigen::AlignedBox3d model_box = detail::points_box(move(start));
    // Only the scene points a bounded shift can reach enter the grid (as in align()).
    const Points in_reach =
        detail::points_in_reach(scene.points(), model_box, params.local.max_translation);
    const GridSpec spec = detail::bounded_translation_spec(detail::points_box(in_reach), model_box,
                                                           params.local.max_translation,
                                                           params.scene.voxel_size, params.limits);
    use_plans(spec);
    voxelize_into(in_reach, spec, params.scene.occupancy, target, params.limits);
    phase->set_target(target);
    return spec;
  }

  // Makes `phase` a phase correlation of spec's size: the most recently used one of that
  // size when kept, else new plans (the least recently used kept ones freed first).
  void use_plans(const GridSpec& spec) {
    const auto same = [&](const PhaseCorrelation& p) { return p.spec().dims == spec.dims; };
    if (phase && same(*phase)) return;
    if (phase) kept_plans.insert(kept_plans.begin(), std::move(*phase));
    phase.reset();
    const auto found = std::find_if(kept_plans.begin(), kept_plans.end(), same);
    if (found != kept_plans.end()) {
      phase.emplace(std::move(*found));
      kept_plans.erase(found);
      return;
    }
    if (kept_plans.size() > kKeptPlans) {
      kept_plans.erase(kept_plans.begin() + kKeptPlans, kept_plans.end());
    }
    phase.emplace(spec, detail::phase_params(params));
  }

  // The bounded grid placed around the model's start, as Algorithm 1's translation source.
  class BoundedGrid : public detail::TranslationSource {
   public:
    BoundedGrid(Impl& impl, const GridSpec& spec)
        : impl_(impl), spec_(spec), target_energy_(grid_energy(impl.target)) {}
    TranslationEstimate estimate(const Points& moved) override {
      const AlignParams& p = impl_.params;
      voxelize_into(moved, spec_, p.scene.occupancy, impl_.moving, p.limits);
      if (impl_.moving.empty()) fail("initial_guess: the model falls outside the scene's grid");
      return impl_.phase->estimate(impl_.moving, impl_.max_shift);
    }
    double translation_cost() const override {
      return spectral_vs::translation_cost(impl_.moving, impl_.target, Eigen::Vector3i::Zero(),
                                           target_energy_);
    }

   private:
    Impl& impl_;
    GridSpec spec_;
    double target_energy_;
  };

  // Algorithm 1 (eq. 16-17) on the bounded grid: the loop of align().
  AlignResult run(const PointCloud& scene, const Transform& initial_guess,
                  Clock::time_point started) {
    auto t = Clock::now();
    const ShCoefficients scene_coefficients =
        egi_coefficients(scene, params.scene.bandwidth, params.scene.egi_method);
    So3Correlation correlation(scene_coefficients, model_coefficients, params.scene.bandwidth,
                               true);
    timings.scene_coefficients = seconds_since(t);
    t = Clock::now();
    // The verification, for the final pose only: the screen records the scene's
    // directions around the model, or reads what a declared view's sensor saw.
    const detail::Verifier verifier(
        scene, params.scene.voxel_size, detail::declared_viewpoint(params),
        detail::FitnessMap::spec_of(scene, params.scene.voxel_size, params.limits),
        detail::FitnessMap::Coverage::around_model);
    timings.scene_map = seconds_since(t);

    t = Clock::now();
    Pose pose = pose_of(initial_guess);
    BoundedGrid grid(*this, place_grid(scene, pose));
    timings.translation_grid = seconds_since(t);

    const detail::Algorithm1Problem loop{correlation,
                                         scene_coefficients,
                                         model_coefficients,
                                         *moving_model,
                                         params.local,
                                         params.scene.voxel_size,
                                         params.scene.bandwidth,
                                         detail::deadline_of(params.max_seconds, started)};
    detail::Algorithm1Timings loop_timings;
    AlignResult result =
        detail::run_algorithm1(loop, pose, grid, params.local.max_iterations, &loop_timings);
    timings.rotation = loop_timings.rotation;
    timings.translation = loop_timings.translation;
    timings.records = loop_timings.records;
    t = Clock::now();
    const double voxel_size = params.scene.voxel_size;
    const auto fitness_of = [&](const Pose& p) {
      return verifier.fitness(move(p), moving_model->turned_normals(p), voxel_size);
    };
    result.fitness = fitness_of(pose);
    timings.fitness = seconds_since(t);
    if (params.local.icp) {
      t = Clock::now();
      detail::icp_step(
          model, scene, voxel_size, detail::local_icp_settings(detail::declared_viewpoint(params)),
          dense_model, [&](const Transform& T) { return fitness_of(pose_of(T)); }, result);
      timings.icp = seconds_since(t);
    }
    t = Clock::now();
    result.voxel_size = voxel_size;
    if (params.verification.verify) {
      detail::set_verification(result, verifier.verify(model, result.T_scene_model));
      // No support plane is looked for around a tracked model: its pose always rests.
      detail::judge(result, model, verifier, detail::typical_size(model.points()),
                    detail::typical_size(scene.points()), params.verification.expect_resting);
    } else {
      detail::leave_unjudged(result);
    }
    timings.fitness += seconds_since(t);
    return result;
  }
};

ModelAligner::ModelAligner(const PointCloud& model, const AlignParams& params)
    : impl_(std::make_unique<Impl>()) {
  require_non_empty(model, "model");
  require_normals(model, "model");
  detail::check_align_params(params);
  Impl& im = *impl_;
  im.model = model;
  im.params = params;
  if (params.scene.voxel_size == 0.0)
    im.params.scene.voxel_size = alignment_voxel_size(model, model);
  // A tracker checks a view only when it is declared: 'automatic' is all sides here.
  if (params.scene.scene_view == SceneView::automatic && !detail::declared_viewpoint(params))
    im.params.scene.scene_view = SceneView::all_sides;
  im.moving_model.emplace(model);
  im.dense_model = detail::dense_for_polish(model.points(), im.params.scene.voxel_size);
  im.model_coefficients = egi_coefficients(model, params.scene.bandwidth, params.scene.egi_method);
  if (im.local()) {
    im.max_shift = Eigen::Vector3i::Constant(detail::voxels_along(
        params.local.max_translation, im.params.scene.voxel_size, params.limits));
  }
}

ModelAligner::~ModelAligner() = default;
ModelAligner::ModelAligner(ModelAligner&&) noexcept = default;
ModelAligner& ModelAligner::operator=(ModelAligner&&) noexcept = default;

AlignResult ModelAligner::align(const PointCloud& scene) {
  return align(scene, impl_->params.initial_guess);
}

namespace {

// The local mode's stages as align()'s: the scene's side prepared, Algorithm 1, the
// verification with the verdict.
AlignTimings local_timings(const ModelAlignerTimings& t) {
  AlignTimings timings;
  timings.preparation = t.scene_coefficients + t.scene_map + t.translation_grid;
  timings.algorithm1 = t.rotation + t.translation + t.records;
  timings.icp = t.icp;
  timings.verdict = t.fitness;
  timings.total = t.total;
  return timings;
}

}  // namespace

AlignResult ModelAligner::align(const PointCloud& scene, const Transform& initial_guess) {
  Impl& im = *impl_;
  const std::lock_guard<std::mutex> lock(im.busy);
  const Clock::time_point started = Clock::now();
  require_non_empty(scene, "scene");
  require_normals(scene, "scene");
  require_rigid_transform(initial_guess, "initial_guess");
  im.timings = {};
  AlignResult result;
  if (im.local()) {
    result = im.run(scene, initial_guess, started);
  } else {
    AlignParams params = im.params;
    params.initial_guess = initial_guess;
    result = spectral_vs::align(im.model, scene, params);
  }
  im.timings.total = seconds_since(started);
  if (im.local()) result.timings = local_timings(im.timings);
  return result;
}

const AlignParams& ModelAligner::params() const { return impl_->params; }
const PointCloud& ModelAligner::model() const { return impl_->model; }
const ShCoefficients& ModelAligner::model_coefficients() const { return impl_->model_coefficients; }
ModelAlignerTimings ModelAligner::last_timings() const {
  const std::lock_guard<std::mutex> lock(impl_->busy);
  return impl_->timings;
}

}  // namespace spectral_vs
