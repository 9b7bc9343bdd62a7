// The analytical CJM (controllers/cjm/analytical.py, docs/design.md sections 4.2-4.4):
// one equality row set, at least 6 joints before its link, one 6-row task.
#include "step.hpp"
#include "terms_layout.hpp"

namespace cjm {

bool Step::analytical(const Inputs& in, Index index, VectorRef qd) {
  const ConstraintPlan& plan = constraints_[index];
  if (!plan.analytical || task_rows_ != 6) return false;
  const bool solved = plan.pre.size() == 6 ? square_pre_chain(in, index, qd)
                                           : redundant_pre_chain(in, index, qd);
  // the joints off the path to the EE move neither task nor constraint: the posture
  // (CJMController._solve_analytical)
  if (solved && in.use_posture)
    for (Index j : plan.off) qd(j) = in.posture(j);
  return solved;
}

bool Step::square_pre_chain(const Inputs& in, Index index, VectorRef qd) {
  const ConstraintPlan& plan = constraints_[index];
  const Index k = plan.rows, n_free = 6 - k, n_post = static_cast<Index>(plan.post.size());
  const Index n_columns = n_free + n_post;  // columns of Jbar
  const auto jacobian_a = in.frame_jacobians.middleRows(6 * index, 6);
  for (Index j = 0; j < 6; ++j) square_.col(j) = jacobian_a.col(plan.pre[j]);
  lu_pre_.compute(square_);
  const auto pivots = lu_pre_.matrixLU().diagonal().cwiseAbs();
  if (!(pivots.minCoeff() >= tol_.pre_chain_pivot_ratio * pivots.maxCoeff())) {
    event(Event::pre_chain_singular);
    return false;
  }
  // qd = joint_map [1; v_m]: J_a^-1 [V_a0, S] on the pre rows, the identity on the post rows
  const auto pre_rhs = pre_rhs_of(in.terms.data() + terms_offset_[index], k);
  auto joint_map = joint_map_.topLeftCorner(nv_, n_columns + 1);
  joint_map.setZero();
  const Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, 7> pre_solution = lu_pre_.solve(pre_rhs);
  for (Index j = 0; j < 6; ++j) joint_map.row(plan.pre[j]).head(n_free + 1) = pre_solution.row(j);
  for (Index j = 0; j < n_post; ++j) joint_map(plan.post[j], n_free + 1 + j) = 1.0;
  auto task_map = task_map_.topLeftCorner(6, n_columns + 1);  // [J_e qd_0, Jbar]
  task_map.noalias() = in.ee_jacobian.lazyProduct(joint_map);  // small: no GEMM blocking (0.3 us)
  cjm_rhs_ = in.twist - task_map.col(0);  // V_e - Ad_ea V_a0 (eq 22)
  const auto cjm = task_map.rightCols(n_columns);
  auto free_with_one = free_with_one_.head(n_columns + 1);
  free_with_one(0) = 1.0;
  auto free = free_with_one.tail(n_columns);
  bool solved = false;
  if (n_columns == 6 && policy_.damping == 0.0) {  // the LU fast path (section 4.3)
    square_ = cjm;
    lu_cjm_.compute(square_);
    const double bound = 1.0 / lu_cjm_.inverse().norm();  // <= sigma_min
    if (bound >= policy_.threshold && bound >= tol_.fast_path_min_sigma) {
      free = lu_cjm_.solve(cjm_rhs_);
      report_.sigma_min = bound;
      solved = true;
    }
  }
  if (!solved) {  // the SVD DLS (eq 35)
    factor_task(cjm, policy_);
    dls_.solve(cjm_rhs_, free);
    report_task_solution(cjm, cjm_rhs_, free);
    if (dls_.rank() < n_columns) closest_to_posture(in, n_columns, n_columns != 6 && in.use_posture);
  }
  qd.noalias() = joint_map * free_with_one;
  twist_a_with_one_.tail(6).noalias() = jacobian_a * qd;  // what the pre-chain produces
  record_pre_chain_residual(in, index, k);
  return true;
}

void Step::record_pre_chain_residual(const Inputs& in, Index index, Index k) {
  twist_a_with_one_(0) = 1.0;
  const auto residual_rows = residual_rows_of(in.terms.data() + terms_offset_[index], k);
  auto residual = scratch_rows_.head(k);
  residual.noalias() = residual_rows * twist_a_with_one_;
  report_.equality_residual = residual.cwiseAbs().maxCoeff();
  report_.method = Method::analytical;
}

void Step::closest_to_posture(const Inputs& in, Index n_columns, bool use_posture) {
  // null(Jbar): the complement of the DLS's row space, from a QR of that row space
  const Index rank = dls_.rank(), d = n_columns - rank;
  auto row_space = basis_qr_.topLeftCorner(n_columns, rank);
  row_space = dls_.row_space();
  householder_qr(row_space, basis_tau_.head(rank));
  auto basis = basis_.topLeftCorner(n_columns, d);
  basis.setZero();
  basis.bottomRows(d).setIdentity();
  apply_q(row_space, basis_tau_.head(rank), basis);
  auto joint_map = joint_map_.topLeftCorner(nv_, n_columns + 1);
  auto free_with_one = free_with_one_.head(n_columns + 1);
  auto goal = goal_.head(nv_);
  goal.noalias() = joint_map * free_with_one;
  if (use_posture) goal = in.posture - goal;
  else goal = -goal;
  // the least-squares step (lstsq, rcond 1e-10) within null(Jbar) towards the goal
  auto mapped = closest_.topLeftCorner(nv_, d);
  mapped.noalias() = joint_map.rightCols(n_columns) * basis;
  closest_svd_.compute(mapped);
  const double cutoff = tol_.least_squares_rcond * closest_svd_.max_value();
  auto step = step_.head(d);
  step.setZero();
  for (Index j = 0; j < closest_svd_.size(); ++j) {
    const double s = closest_svd_.s()(j);
    if (s > cutoff) step += (closest_svd_.u().col(j).dot(goal) / s) * closest_svd_.v().col(j);
  }
  free_with_one.tail(n_columns).noalias() += basis * step;
}

bool Step::redundant_pre_chain(const Inputs& in, Index index, VectorRef qd) {
  const ConstraintPlan& plan = constraints_[index];
  const Index k = plan.rows, n_free = 6 - k, n_pre = static_cast<Index>(plan.pre.size());
  const Index n_post = static_cast<Index>(plan.post.size()), n_columns = n_free + n_post;
  const auto jacobian_a = in.frame_jacobians.middleRows(6 * index, 6);
  auto pre_jacobian = pre_jacobian_.topLeftCorner(6, n_pre);
  for (Index j = 0; j < n_pre; ++j) pre_jacobian.col(j) = jacobian_a.col(plan.pre[j]);
  pre_svd_.compute(pre_jacobian);  // J_a = U S V^T, 6 singular values
  if (pre_svd_.min_value() < tol_.pre_chain_min_singular_value) {
    event(Event::pre_chain_singular);
    return false;
  }
  // J_a^+ = V S^-1 U^T, kept in closest_ (n_pre x 6); Ad_ea = J_e[:, pre] J_a^+
  auto pre_inverse = closest_.topLeftCorner(n_pre, 6);
  square_.noalias() = pre_svd_.s().cwiseInverse().asDiagonal() * pre_svd_.u().transpose();
  pre_inverse.noalias() = pre_svd_.v() * square_;
  auto ee_pre = task_map_.topLeftCorner(6, n_pre);
  for (Index j = 0; j < n_pre; ++j) ee_pre.col(j) = in.ee_jacobian.col(plan.pre[j]);
  ad_cjm_.noalias() = ee_pre * pre_inverse;
  // Jbar = [Ad_ea S, J_post] (eq 24), rhs V_e - Ad_ea V_a0
  const auto pre_rhs = pre_rhs_of(in.terms.data() + terms_offset_[index], k);
  auto cjm = cjm_.topLeftCorner(6, n_columns);
  cjm.leftCols(n_free).noalias() = ad_cjm_ * pre_rhs.rightCols(n_free);
  for (Index j = 0; j < n_post; ++j) cjm.col(n_free + j) = in.ee_jacobian.col(plan.post[j]);
  cjm_rhs_ = in.twist;
  cjm_rhs_.noalias() -= ad_cjm_ * pre_rhs.col(0);
  factor_task(cjm, policy_);
  auto free = free_with_one_.head(n_columns);
  dls_.solve(cjm_rhs_, free);
  twist_a_ = pre_rhs.col(0);
  twist_a_.noalias() += pre_rhs.rightCols(n_free) * free.head(n_free);
  auto qd_pre = step_.head(n_pre);
  qd_pre.noalias() = pre_inverse * twist_a_;
  if (in.use_posture) {  // the posture in null(J_a): (I - V V^T) posture[pre]
    auto posture_pre = goal_.head(n_pre);
    for (Index j = 0; j < n_pre; ++j) posture_pre(j) = in.posture(plan.pre[j]);
    qd_pre += posture_pre;
    auto weights = rank_weights_.head(6);
    weights.noalias() = pre_svd_.v().transpose() * posture_pre;
    qd_pre.noalias() -= pre_svd_.v() * weights;
  }
  qd.setZero();
  for (Index j = 0; j < n_pre; ++j) qd(plan.pre[j]) = qd_pre(j);
  for (Index j = 0; j < n_post; ++j) qd(plan.post[j]) = free(n_free + j);
  twist_a_with_one_.tail(6).noalias() = pre_jacobian * qd_pre;  // what the pre-chain produces
  record_pre_chain_residual(in, index, k);
  report_task_solution(cjm, cjm_rhs_, free);
  return true;
}

}  // namespace cjm
