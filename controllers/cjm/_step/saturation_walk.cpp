// Joint limits with acceleration limits: saturation around the previous command
// (controllers/cjm/saturation_walk.py, docs/design.md section 12). Every point is reached
// by walking from the previous command inside the box: the rows first (an active-set
// bounded least squares, exact whenever the box allows it), then the twist.
#include "step.hpp"

namespace cjm {

void Step::saturate_around_previous(const Inputs& in) {
  walk_point_ = previous_.cwiseMax(lower_).cwiseMin(upper_);
  for (Index j = 0; j < nv_; ++j) free_(j) = previous_(j) >= lower_(j) && previous_(j) <= upper_(j);
  const double rows_scale = walk_to_rows();
  Index limiting_joint = -1;
  double sigma_min = std::numeric_limits<double>::quiet_NaN(), damping = 0.0;
  if (rows_scale >= 1.0) {
    for (Index iteration = 0; iteration <= nv_ && free_.any(); ++iteration) {
      for (Index j = 0; j < nv_; ++j) held_(j) = free_(j) ? 0.0 : walk_point_(j);
      const Split split = solve_over_free(in, walk_policy_);
      if (split.rows_residual > tol_.rows) break;  // the held joints leave the rows no freedom
      sigma_min = split.sigma_min;
      damping = split.damping;
      walk_goal_ = base_ + direction_;
      const Index joint = walk();
      if (joint < 0) break;
      free_(joint) = false;
      if (limiting_joint < 0) limiting_joint = joint;
    }
  }
  sns_qd_ = walk_point_;
  walk_result(in, rows_scale, limiting_joint, sigma_min, damping);
}

double Step::walk_to_rows() {
  const Index m = row_count_;
  if (m == 0) return 1.0;
  auto residual = rows_scratch_.head(m);
  auto reduction = scratch_rows_.head(m);
  residual.noalias() = rows_.topRows(m) * walk_point_;
  residual = rhs_.head(m) - residual;
  const double initial = residual.cwiseAbs().maxCoeff();
  for (Index iteration = 0; iteration <= 3 * nv_; ++iteration) {
    residual.noalias() = rows_.topRows(m) * walk_point_;
    residual = rhs_.head(m) - residual;
    if (residual.cwiseAbs().maxCoeff() <= tol_.rows) return 1.0;
    walk_move_.setZero();
    Index n_free = 0;
    for (Index j = 0; j < nv_; ++j)
      if (free_(j)) columns_.col(n_free++).head(m) = rows_.col(j).head(m);
    if (n_free > 0) {
      null_.factor(columns_.topLeftCorner(m, n_free));
      auto correction = free_x_.head(n_free);
      null_.pseudo_solve(residual, correction);
      for (Index j = 0, f = 0; j < nv_; ++j)
        if (free_(j)) walk_move_(j) = correction(f++);
    }
    reduction.noalias() = rows_.topRows(m) * walk_move_;
    if (reduction.cwiseAbs().maxCoeff() <= tol_.rows) {
      const Index joint = wrong_side(residual);
      if (joint < 0) break;  // the least-squares point of the box: the rows cannot hold
      free_(joint) = true;
      continue;
    }
    walk_goal_ = walk_point_ + walk_move_;
    const Index joint = walk();
    if (joint >= 0) free_(joint) = false;
  }
  residual.noalias() = rows_.topRows(m) * walk_point_;
  residual = rhs_.head(m) - residual;
  const double left = residual.cwiseAbs().maxCoeff();
  if (left <= tol_.rows) return 1.0;
  return std::max(0.0, 1.0 - left / initial);
}

Index Step::wrong_side(const ConstVectorRef& residual) {
  const Index m = row_count_;
  auto descent = delta_.head(nv_);  // minus the gradient of |rows qd - rhs|^2 / 2
  descent.noalias() = rows_.topRows(m).transpose() * residual;
  Index best = -1;
  double best_inward = tol_.rows;
  for (Index j = 0; j < nv_; ++j) {
    if (free_(j)) continue;
    double inward = -std::numeric_limits<double>::infinity();
    if (walk_point_(j) >= upper_(j)) {
      inward = -descent(j);
    } else if (walk_point_(j) <= lower_(j)) {
      inward = descent(j);
    }
    if (inward > best_inward) {
      best_inward = inward;
      best = j;
    }
  }
  return best;
}

Index Step::walk() {
  walk_move_ = walk_goal_ - walk_point_;
  const double noise = walk_point_.cwiseAbs().maxCoeff();
  const double still = std::max(tol_.still_direction, tol_.at_bound * walk_move_.cwiseAbs().maxCoeff());
  double fraction = 1.0, bound = 0.0;
  Index joint = -1;
  for (Index j = 0; j < nv_; ++j) {
    const double move = walk_move_(j);
    if (!free_(j) || !(std::abs(move) > still)) continue;
    const double side = move > 0.0 ? upper_(j) : lower_(j);
    const double reach = std::max(gap_to_bound(side, walk_point_(j), noise) / move, 0.0);
    if (reach < fraction) {
      fraction = reach;
      joint = j;
      bound = side;
    }
  }
  for (Index j = 0; j < nv_; ++j)
    if (free_(j)) walk_point_(j) += fraction * walk_move_(j);
  if (joint >= 0) walk_point_(joint) = bound;
  walk_point_ = walk_point_.cwiseMax(lower_).cwiseMin(upper_);
  return joint;
}

void Step::walk_result(const Inputs& in, double rows_scale, Index limiting_joint,
                       double sigma_min, double damping) {
  auto achieved = scratch_rows_.head(task_rows_);
  achieved.noalias() = in.ee_jacobian * sns_qd_;
  const double twist_norm = in.twist.squaredNorm();
  double task_scale = 1.0;
  if (rows_scale < 1.0) {
    task_scale = 0.0;
  } else if (twist_norm > 0.0) {
    task_scale = std::min(std::max(achieved.dot(in.twist) / twist_norm, 0.0), 1.0);
  }
  achieved -= task_scale * in.twist;
  const double tolerance = tol_.twist * (1.0 + in.twist.cwiseAbs().maxCoeff());
  sns_missed_ = achieved.cwiseAbs().maxCoeff() > tolerance;
  sns_task_scale_ = task_scale;
  sns_rows_scale_ = rows_scale;
  sns_limiting_ = limiting_joint;
  sns_sigma_min_ = sigma_min;
  sns_damping_ = damping;
}

}  // namespace cjm
