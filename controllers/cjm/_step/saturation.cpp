// Joint limits by saturation in the null space (controllers/cjm/saturation.py and the
// CJM's _saturate, docs/design.md section 9): Flacco, De Luca, Khatib, IEEE T-RO 2015,
// Algorithm 1, with the constraint rows as a hard first priority. With acceleration
// limits the saturation walks around the previous command instead (saturation_walk.cpp).
#include "step.hpp"

namespace cjm {

namespace {
constexpr double kInfinity = std::numeric_limits<double>::infinity();
}  // namespace

//! controllers.cjm.saturation.gap_to_bound: ``bound - base``, 0 within its rounding.
double Step::gap_to_bound(double bound, double base, double noise) const {
  const double gap = bound - base;
  return std::abs(gap) <= tol_.at_bound * (1.0 + std::abs(bound) + noise) ? 0.0 : gap;
}

void Step::saturate(const Inputs& in, VectorRef qd) {
  ensure_rows(in);
  for (Index pass = 0; pass <= static_cast<Index>(barriers_.size()) + pair_count_; ++pass) {
    gather_active_rows();
    if (accelerating_) {
      saturate_around_previous(in);
    } else {
      saturate_in_null_space(in);
    }
    if (!activate_worst(sns_qd_)) break;
  }
  report_saturation(qd);
}

void Step::report_saturation(VectorRef qd) {
  qd = sns_qd_;
  report_.method = Method::saturated;
  report_.scale = sns_task_scale_;
  if (sns_sigma_deferred_) {  // the walk's undamped DLS: its sigma_min when the report is read
    report_.damping = sns_damping_;
    sigma_min_source_ = &walk_dls_;
  } else if (!std::isnan(sns_sigma_min_)) {  // the task's DLS that gave this command
    report_.sigma_min = sns_sigma_min_;
    report_.damping = sns_damping_;
  }
  report_.saturated_count = 0;
  for (Index j = 0; j < nv_; ++j)
    if (!free_(j)) saturated_(report_.saturated_count++) = j;
  const Index m = row_count_;
  if (m > 0) {
    auto residual = rows_scratch_.head(m);
    residual.noalias() = rows_.topRows(m) * qd;
    residual -= rhs_.head(m);
    report_.equality_residual = residual.cwiseAbs().maxCoeff();
  } else {
    report_.equality_residual = 0.0;
  }
  if (sns_rows_scale_ < 1.0) {
    report(Status::constraint_degraded);
    event(Event::rows_scaled, sns_rows_scale_);
  } else if (sns_missed_) {
    report(Status::least_squares);
    report_.saturation_joint_count = report_.saturated_count;
    saturation_joints_.head(report_.saturated_count) = saturated_.head(report_.saturated_count);
    const Index recorded = report_.event_count;
    event(Event::task_missed, sns_sigma_min_, sns_damping_);  // deferred: written when settled
    if (sns_sigma_deferred_ && report_.event_count > recorded) sigma_min_event_ = recorded;
  } else if (sns_task_scale_ < 1.0) {
    report(Status::scaled);
    event(Event::task_scaled, static_cast<double>(sns_limiting_), sns_task_scale_);
  }
}

void Step::saturate_in_null_space(const Inputs& in) {
  free_.setConstant(true);
  held_.setZero();
  for (Index j = 0; j < nv_; ++j) {
    box_lower_(j) = lower_(j) - tol_.box_margin * (1.0 + std::abs(lower_(j)));
    box_upper_(j) = upper_(j) + tol_.box_margin * (1.0 + std::abs(upper_(j)));
  }
  bool have_scaled = false, have_reference = false;
  double best_scale = 0.0;
  Index best_critical = -1, reference_rank = 0;
  for (Index iteration = 0; iteration <= nv_; ++iteration) {
    const Split split = solve_over_free(rhs_.head(row_count_), in.ee_jacobian, in.twist, policy_);
    if (!have_reference) {
      reference_rank = split.task_rank;
      have_reference = true;
    }
    if (split.rows_residual > tol_.rows) break;  // too few free joints for the rows
    if (split.task_rank < reference_rank && have_scaled) break;  // keep the best full-rank scale
    sns_qd_ = base_ + direction_;
    if ((sns_qd_.array() >= box_lower_.array()).all() && (sns_qd_.array() <= box_upper_.array()).all()) {
      saturation_result(in, 1.0, 1.0, -1, split);
      return;
    }
    Index critical = -1;
    const double scale = task_scale_limit(base_, direction_, critical);
    if (critical < 0) break;
    const double bound = sns_qd_(critical) > upper_(critical) ? upper_(critical) : lower_(critical);
    held_(critical) = bound;
    free_(critical) = false;
    if (std::abs(bound) < box_.velocity_limit(critical) * (1.0 - tol_.box_margin)) {  // a position bound
      have_reference = have_scaled = false;
    } else if (scale >= 0.0 && (!have_scaled || scale > best_scale)) {
      have_scaled = true;
      best_scale = scale;
      best_critical = critical;
      best_free_ = free_;
      best_held_ = held_;
      best_free_(critical) = true;  // it is free there
      best_held_(critical) = 0.0;
    }
    if (!free_.any()) break;
  }
  if (have_scaled) {
    free_ = best_free_;
    held_ = best_held_;
    const Split best = solve_over_free(rhs_.head(row_count_), in.ee_jacobian, in.twist, policy_);
    sns_qd_ = base_ + best_scale * direction_;
    saturation_result(in, best_scale, 1.0, best_critical, best);
    return;
  }
  scale_rows(in);
}

double Step::task_scale_limit(const ConstVectorRef& base, const ConstVectorRef& direction,
                              Index& critical) const {
  double smallest_max = kInfinity, largest_min = -kInfinity;
  Index needs_more = -1;
  critical = -1;
  double noise = 0.0, largest = 0.0;  // max |base| and max |direction| over the joints
  for (Index i = 0; i < nv_; ++i) {
    noise = std::max(noise, std::abs(base(i)));
    largest = std::max(largest, std::abs(direction(i)));
  }
  const double still = std::max(tol_.still_direction, tol_.at_bound * largest);  // a direction entry of 0
  for (Index i = 0; i < nv_; ++i) {
    if (!free_(i)) continue;
    const double a = direction(i), b = base(i);
    const double to_lower = gap_to_bound(lower_(i), b, noise);
    const double to_upper = gap_to_bound(upper_(i), b, noise);
    double low, high;
    if (std::abs(a) > still) {
      low = to_lower / a;
      high = to_upper / a;
      if (a < 0.0) std::swap(low, high);
    } else if (to_lower <= 0.0 && 0.0 <= to_upper) {
      continue;
    } else {
      low = kInfinity;  // outside whatever the scale
      high = -kInfinity;
    }
    if (high < smallest_max) {
      smallest_max = high;
      critical = i;
    }
    if (low > largest_min) {
      largest_min = low;
      needs_more = i;
    }
  }
  const double scale = std::min(1.0, smallest_max) + 0.0;  // no -0 (a joint at its bound)
  if (largest_min > scale) {
    critical = needs_more;
    return -kInfinity;
  }
  if (scale < 0.0) return -kInfinity;
  return scale;
}

void Step::saturation_result(const Inputs& in, double task_scale, double rows_scale,
                             Index limiting_joint, const Split& split) {
  // the split is the last one solved: dls_ holds its task's DLS
  sns_sigma_min_ = split.task_solved ? dls_.sigma_min() : std::numeric_limits<double>::quiet_NaN();
  sns_damping_ = split.task_solved ? dls_.damping() : 0.0;
  sns_sigma_deferred_ = false;
  auto achieved = scratch_rows_.head(task_rows_);
  achieved.noalias() = in.ee_jacobian * sns_qd_;
  achieved -= task_scale * in.twist;
  const double tolerance = tol_.twist * (1.0 + in.twist.cwiseAbs().maxCoeff());
  sns_missed_ = achieved.cwiseAbs().maxCoeff() > tolerance;
  sns_task_scale_ = task_scale;
  sns_rows_scale_ = rows_scale;
  sns_limiting_ = limiting_joint;
}

void Step::scale_rows(const Inputs& in) {
  // no task, the rows' minimum-norm correction from rest scaled by the largest factor in the box
  const Index m = row_count_;
  null_.factor(rows_.topRows(m));
  base_.setZero();
  null_.pseudo_solve(rhs_.head(m), direction_);
  free_.setConstant(true);
  Index critical = -1;
  const double scale = std::max(task_scale_limit(base_, direction_, critical), 0.0);
  sns_qd_ = base_ + scale * direction_;
  saturation_result(in, 0.0, scale, -1, Split());  // no task solved
}

}  // namespace cjm
