#include "alignment/algorithm1.hpp"

#include <spectral_vs/rotation/so3.hpp>

#include "common/checks.hpp"

#include <Eigen/Dense>
#include <cmath>

namespace spectral_vs::detail {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double>(to - from).count();
}

}  // namespace

Eigen::Vector3d rotation_step(const CorrelationValue& c, const LocalParams& params) {
  Eigen::Vector3d omega = params.rotation_gain * c.gradient;
  if (params.rotation_step == RotationStep::newton) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(c.hessian);
    if (eigen.eigenvalues().maxCoeff() < 0.0) {
      omega = -params.rotation_gain * c.hessian.ldlt().solve(c.gradient);
    }
  }
  const double angle = omega.norm();
  if (angle > params.max_rotation_step) omega *= params.max_rotation_step / angle;
  return omega;
}

double capped_step(double step, const LocalParams& params, bool* capped) {
  *capped = std::abs(step) > params.max_rotation_step;
  return *capped ? std::copysign(params.max_rotation_step, step) : step;
}

AlignResult run_algorithm1(const Algorithm1Problem& problem, Pose& pose, TranslationSource& source,
                           int max_iterations, Algorithm1Timings* timings) {
  const bool newton = problem.local.rotation_step == RotationStep::newton;
  AlignResult result;
  for (int iteration = 0; iteration < max_iterations; ++iteration) {
    const auto start = Clock::now();
    const CorrelationValue c = problem.correlation.evaluate(pose.R, newton);
    pose.R = pose.R * exp_so3(rotation_step(c, problem.local));
    const auto rotated = Clock::now();

    const TranslationEstimate shift = source.estimate(problem.model.move(pose));
    const Eigen::Vector3d step = problem.local.translation_gain * shift.shift;
    pose.offset += step;
    const auto translated = Clock::now();

    AlignIteration record;
    record.seconds = seconds_between(start, translated);
    record.translation_step = step.norm() / problem.voxel_size;
    record.rotation_gradient = c.gradient.norm();
    record.correlation = c.value;
    record.translation_peak = shift.peak;
    if (problem.costs) {
      record.translation_cost = source.translation_cost();
      record.rotation_cost = rotation_cost(problem.scene_coefficients, problem.model_coefficients,
                                           pose.R, problem.bandwidth, true);
    }
    record.T_scene_model = problem.model.transform_of(pose);
    result.history.push_back(record);
    result.iterations = iteration + 1;
    if (timings) {
      timings->rotation += seconds_between(start, rotated);
      timings->translation += seconds_between(rotated, translated);
      timings->records += seconds_between(translated, Clock::now());
    }
    if (record.translation_step + record.rotation_gradient < problem.local.tolerance) {
      result.converged = true;
      result.stop_reason = AlignStopReason::converged;
      break;
    }
    if (Clock::now() > problem.deadline) {
      result.stop_reason = AlignStopReason::max_seconds;
      break;
    }
    source.follow(problem.model.centre(pose), step, iteration + 1 < max_iterations);
  }
  result.T_scene_model = problem.model.transform_of(pose);
  result.correlation = problem.correlation.evaluate(pose.R).value;
  result.translation_peak = result.history.empty() ? 0.0 : result.history.back().translation_peak;
  if (const auto dims = source.window_dims()) result.window_dims = *dims;
  return result;
}

}  // namespace spectral_vs::detail

namespace spectral_vs {

AxisRotationStep rotation_step_about(So3Correlation& correlation, const Eigen::Matrix3d& R,
                                     const Eigen::Vector3d& axis, const AlignParams& params) {
  const double length = axis.norm();
  if (!(length > 0.0) || !std::isfinite(length))
    detail::fail("axis must be a finite, non-zero direction, got ", axis.transpose());
  const Eigen::Vector3d a = axis / length;
  const bool newton_law = params.local.rotation_step == RotationStep::newton;
  const CorrelationValue c = correlation.evaluate(R, newton_law);
  AxisRotationStep out;
  out.slope = a.dot(c.gradient);
  out.curvature = newton_law ? a.dot(c.hessian * a) : 0.0;
  // The law of detail::rotation_step, in one dimension.
  out.newton = newton_law && out.curvature < 0.0;
  const double step =
      params.local.rotation_gain * (out.newton ? -out.slope / out.curvature : out.slope);
  out.turn = detail::capped_step(step, params.local, &out.capped);
  return out;
}

}  // namespace spectral_vs
