// The general CJM over stacked rows (controllers/cjm/general.py, docs/design.md 4.5) and
// its restriction to the free joints that saturation solves again and again
// (controllers/cjm/saturation.py's _solve_over_free, section 9).
#include "step.hpp"

namespace cjm {

namespace {
//! ``max |rows x - rhs|`` (0 without rows), with ``scratch`` for the product.
double residual_of(const ConstMatrixRef& rows, const ConstVectorRef& x, const ConstVectorRef& rhs,
                   VectorRef scratch) {
  if (rows.rows() == 0) return 0.0;
  scratch.noalias() = rows * x;
  scratch -= rhs;
  return scratch.cwiseAbs().maxCoeff();
}
}  // namespace

void Step::general(const Inputs& in, VectorRef qd) {
  ensure_rows(in);
  gather_active_rows();
  const Index m = row_count_;
  const auto rows = rows_.topRows(m);
  const auto rhs = rhs_.head(m);
  null_.factor(rows);
  null_.pseudo_solve(rhs, qd);  // qd_0 = A^+ b
  if (null_.rank() < m) {
    const double residual = residual_of(rows, qd, rhs, scratch_rows_.head(m));
    if (residual > tol_.conflict_residual && !active_pairs_.empty()) {
      hold_pairs_below();
      null_.pseudo_solve(rhs, qd);
    } else if (residual > tol_.conflict_residual) {
      report(Status::constraint_degraded);
      event(Event::conflict, static_cast<double>(null_.rank()), static_cast<double>(m), residual);
    }
  }
  const Index d = null_.dimension();
  if (d > 0) {
    // Jbar = J_e N, from (N^T J_e^T)
    auto task_t = task_t_.topLeftCorner(nv_, task_rows_);
    task_t = in.ee_jacobian.transpose();
    auto task_null_t = task_null_t_.topLeftCorner(d, task_rows_);
    null_.to_null(task_t, task_null_t);
    auto task_null = task_null_.topLeftCorner(task_rows_, d);
    task_null = task_null_t.transpose();
    auto task_rhs = task_rhs_.col(0).head(task_rows_);
    task_rhs = in.twist;
    task_rhs.noalias() -= in.ee_jacobian * qd;
    factor_task(task_null, policy_);
    auto y = task_x_.col(0).head(d);
    dls_.solve(task_rhs, y);
    null_.from_null(y, delta_);
    qd += delta_;
    report_task_solution(task_null, task_rhs, y);
    if (in.use_posture && dls_.rank() < d) {  // the posture in what null(A) leaves
      auto posture = task_t_.col(0);
      posture = in.posture;
      auto posture_null = posture_null_.head(d);
      null_.to_null(posture, posture_null);
      auto weights = rank_weights_.head(dls_.rank());
      weights.noalias() = dls_.row_space().transpose() * posture_null;
      posture_null.noalias() -= dls_.row_space() * weights;
      null_.from_null(posture_null, delta_);
      qd += delta_;
    }
  } else if ((in.twist.array() != 0.0).any()) {
    report(Status::least_squares);
    event(Event::no_free_joint);
  }
  report_.equality_residual = residual_of(rows, qd, rhs, scratch_rows_.head(m));
  report_.method = Method::general;
}

void Step::hold_pairs_below() {
  const Index p = static_cast<Index>(active_pairs_.size());
  const Index first = row_count_ - p;
  const auto second = rows_.middleRows(first, p);
  auto qd = first_qd_.head(nv_);
  auto held = second_x_.head(p);
  if (first == 0) {  // no row before them: least squares over every joint
    null_second_.factor(second);
    null_second_.pseudo_solve(rhs_.segment(first, p), qd);
  } else {
    const auto level_one = rows_.topRows(first);
    null_first_.factor(level_one);
    null_first_.pseudo_solve(rhs_.head(first), qd);
    if (null_first_.rank() < first) {
      const double residual = residual_of(level_one, qd, rhs_.head(first), scratch_rows_.head(first));
      if (residual > tol_.conflict_residual) {
        report(Status::constraint_degraded);
        event(Event::conflict, static_cast<double>(null_first_.rank()),
              static_cast<double>(first), residual);
      }
    }
    const Index d = null_first_.dimension();
    if (d > 0) {  // (A_2 N_1)^T = N_1^T A_2^T
      auto second_t = second_t_.leftCols(p);
      second_t = second.transpose();
      auto second_null_t = second_null_t_.topLeftCorner(d, p);
      null_first_.to_null(second_t, second_null_t);
      auto second_null = second_null_.topLeftCorner(p, d);
      second_null = second_null_t.transpose();
      null_second_.factor(second_null);
      held.noalias() = second * qd;
      held = rhs_.segment(first, p) - held;
      auto y = delta_.head(d);
      null_second_.pseudo_solve(held, y);
      auto step = direction_.head(nv_);  // free until saturation
      null_first_.from_null(y, step);
      qd += step;
    }
  }
  held.noalias() = second * qd;
  for (Index k = 0; k < p; ++k) {
    const double shortfall = rhs_(first + k) - held(k);
    if (shortfall > tol_.conflict_residual) {
      report(Status::constraint_degraded);
      event(Event::pair_conflict, static_cast<double>(active_pairs_[k]), shortfall);
    }
    pair_rhs_(active_pairs_[k]) = held(k);
    rhs_(first + k) = held(k);
  }
}

Step::Split Step::solve_over_free(const ConstVectorRef& rows_rhs,
                                  const Eigen::Ref<const RowMatrix>& task,
                                  const ConstVectorRef& twist, const DampingPolicy& policy,
                                  DampedLeastSquares* factored) {
  // rows exactly over the free joints, held ones moved to the right-hand side
  const Index m = row_count_, p = task.rows();
  Index n_free = 0;
  for (Index j = 0; j < nv_; ++j) {
    if (!free_(j)) continue;
    columns_.col(n_free).head(m) = rows_.col(j).head(m);
    task_columns_.col(n_free).head(p) = task.col(j);
    ++n_free;
  }
  auto rhs = scratch_rows_.head(m);
  rhs = rows_rhs;
  rhs.noalias() -= rows_.topRows(m) * held_;
  const auto rows_free = columns_.topLeftCorner(m, n_free);
  if (factored == nullptr) null_.factor(rows_free);
  auto x0 = free_x_.head(n_free);
  null_.pseudo_solve(rhs, x0);
  Split split;
  if (m > 0) {
    auto check = rows_scratch_.head(m);
    check.noalias() = rows_free * x0;
    check -= rhs;
    split.rows_residual = check.cwiseAbs().maxCoeff();
  }
  base_ = held_;
  direction_.setZero();
  const Index d = null_.dimension();
  if (d > 0) {
    for (Index j = 0, f = 0; j < nv_; ++j)
      if (free_(j)) base_(j) = x0(f++);
    if (factored == nullptr) {
      auto task_t = task_t_.topLeftCorner(n_free, p);
      task_t = task_columns_.topLeftCorner(p, n_free).transpose();
      auto task_null_t = task_null_t_.topLeftCorner(d, p);
      null_.to_null(task_t, task_null_t);
      auto task_null = task_null_.topLeftCorner(p, d);
      task_null = task_null_t.transpose();
      factor_task(task_null, policy);
    }
    DampedLeastSquares& task_dls = factored != nullptr ? *factored : dls_;
    auto task_rhs = task_rhs_.topRows(p);
    task_rhs.col(0) = twist;
    task_rhs.col(1).noalias() = task * base_;
    task_rhs.col(1) = -task_rhs.col(1);
    auto x = task_x_.topLeftCorner(d, 2);
    // ``factored`` solves J_e N's rows: the damping rows' right-hand sides are 0 and
    // -D base = -lambda V_r^T N^T A^+ b, 0 but for rounding (A^+ b is in A's row space)
    task_dls.solve(task_rhs.topRows(factored != nullptr ? task_rows_ : p), x);
    auto delta = delta_.head(n_free);
    null_.from_null(x.col(1), delta);
    for (Index j = 0, f = 0; j < nv_; ++j)
      if (free_(j)) base_(j) += delta(f++);
    null_.from_null(x.col(0), delta);
    for (Index j = 0, f = 0; j < nv_; ++j)
      if (free_(j)) direction_(j) = delta(f++);
    split.task_rank = task_dls.rank();
    split.task_solved = true;
  } else {
    for (Index j = 0, f = 0; j < nv_; ++j)
      if (free_(j)) base_(j) = x0(f++);
  }
  return split;
}

}  // namespace cjm
