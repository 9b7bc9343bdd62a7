// Joint limits with acceleration limits: saturation around the previous command
// (controllers/cjm/saturation_walk.py, docs/design.md section 9.1). Every point is reached
// by walking from the previous command inside the box: the rows first (an active-set
// bounded least squares, exact whenever the box allows it), then the damped twist (the
// same active set on [J_e; D], D the CJM's damping rows of the whole problem).
#include "step.hpp"

namespace cjm {

void Step::saturate_around_previous(const Inputs& in) {
  if (!warm_tried_ && warm_start_applies() && saturate_from_held(in, false)) return;
  walk_point_ = previous_.cwiseMax(lower_).cwiseMin(upper_);
  for (Index j = 0; j < nv_; ++j)  // outside beyond rounding: held at its bound (step 0)
    free_(j) = previous_(j) >= lower_(j) - tol_.box_margin * (1.0 + std::abs(lower_(j))) &&
               previous_(j) <= upper_(j) + tol_.box_margin * (1.0 + std::abs(upper_(j)));
  const double rows_scale = walk_to_rows();
  const Index m = row_count_;
  auto rows_rhs = walk_rows_rhs_.head(m);  // the task keeps the rows' least residual
  if (rows_scale < 1.0) {
    rows_rhs.noalias() = rows_.topRows(m) * walk_point_;
  } else {
    rows_rhs = rhs_.head(m);
  }
  const Index p = stack_walk_task(in);
  // the first solve over every joint is task_damping_rows's own problem: [J_e N; D N] is
  // J_e N alone, or (D N = lambda V_r^T) J_e N damped by lambda (4.2), whose DLS
  // walk_dls_ holds when its QR decided it (full rank): taken with null_, not factored
  // again (a fifth of the walk undamped; damped, the QR of the stacked rows and more)
  const bool factored = null_.dimension() > 0 && walk_dls_.by_qr();
  Index limiting_joint = -1;
  {
    const auto task = walk_task_.topRows(p);
    const auto task_rhs = walk_rhs_.head(p);
    const DampingPolicy undamped{0.0, 0.0, 0.0};  // the damping is in the task's rows
    for (Index iteration = 0; iteration <= 3 * nv_; ++iteration) {
      if (free_.any()) {
        for (Index j = 0; j < nv_; ++j) held_(j) = free_(j) ? 0.0 : walk_point_(j);
        const bool first = factored && iteration == 0 && free_.all();
        const Split split = solve_over_free(rows_rhs, task, task_rhs, undamped,
                                            first ? &walk_dls_ : nullptr);
        if (split.rows_residual > tol_.rows) break;  // the held joints leave the rows no freedom
        walk_goal_ = base_ + direction_;
        const Index joint = walk();
        if (joint >= 0) {
          free_(joint) = false;
          if (limiting_joint < 0) limiting_joint = joint;
          continue;
        }
      }
      const Index joint = task_wrong_side(task, task_rhs);  // null_: the free columns' factor
      if (joint < 0) break;  // the box's optimum
      free_(joint) = true;
    }
  }
  sns_qd_ = walk_point_;
  walk_result(in, rows_scale, limiting_joint);
}

bool Step::warm_start_applies() const {
  return warm_start_ && barriers_.empty() && pair_count_ == 0 &&
         (previous_.array() == held_command_.array()).all();
}

bool Step::saturate_before_the_form(const Inputs& in) {
  // only where the walk's point is the unsaturated form's when that fits the box: a held
  // joint (with none, the walk's end is the general form's, which the analytical form's
  // damping need not be) and lambda = 0 (the analytical form's command is then the
  // general form's, where the analytical form is undamped too: section 9.1)
  if (!warm_start_applies() || held_count_ == 0 || !held_undamped_) return false;
  ensure_rows(in);
  gather_active_rows();
  compute_box(in.q);
  return saturate_from_held(in, true);
}

bool Step::saturate_from_held(const Inputs& in, bool undamped_only) {
  null_holds_rows_ = false;
  const Index p = stack_walk_task(in);
  const Index d = null_.dimension();
  if (d == 0 || walk_dls_.rank() < d) return false;  // not unique: the walk's path decides
  if (undamped_only && (walk_damping_ > 0.0 || walk_optimum_fits_box(in))) return false;
  warm_tried_ = true;
  for (Index j = 0; j < nv_; ++j) {
    free_(j) = held_side_(j) == 0;
    held_(j) = held_side_(j) < 0 ? lower_(j) : held_side_(j) > 0 ? upper_(j) : 0.0;
  }
  const Decided decided = held_optimum_on_triangle(in);
  if (decided == Decided::refused) return false;
  if (decided == Decided::undecided) {  // the reference's solve over the free joints
    const auto task = walk_task_.topRows(p);
    const auto task_rhs = walk_rhs_.head(p);
    const DampingPolicy undamped{0.0, 0.0, 0.0};  // the damping is in the task's rows
    const Split split = solve_over_free(rhs_.head(row_count_), task, task_rhs, undamped);
    if (split.rows_residual > tol_.rows) return false;
    walk_goal_ = base_ + direction_;
    if (!free_in_box(walk_goal_)) return false;
    walk_point_ = walk_goal_;
    if (task_wrong_side(task, task_rhs) >= 0) return false;  // null_: the free columns' factor
  }
  sns_qd_ = walk_point_;
  Index limiting_joint = held_limiting_;  // the previous period's while it is held
  if (limiting_joint >= 0 && free_(limiting_joint)) limiting_joint = -1;
  for (Index j = 0; j < nv_ && limiting_joint < 0; ++j)  // else the first held
    if (!free_(j)) limiting_joint = j;
  walk_result(in, 1.0, limiting_joint);
  return true;
}

Step::Decided Step::held_optimum_on_triangle(const Inputs& in) {
  // With qd = qd_0 + N y (qd_0 = A^+ b), the task is |J_e N y - r|^2 + lambda^2 |y|^2
  // (r = V - J_e qd_0; D N = lambda V^T with V square, J_e N of full column rank), whose
  // Gram matrix M = R^T R + lambda^2 I comes from walk_dls_'s QR; the held joints are the
  // rows N_H y = beta_H - qd_0,H. So y = y_0 - M^-1 N_H^T w with y_0 walk_dls_'s solve and
  // (N_H M^-1 N_H^T) w = N_H y_0 - (beta_H - qd_0,H), and N^T g = -N_H^T w makes -w the
  // held joints' reduced gradients (g = J_e^T (J_e qd - V) + D^T D qd)
  const Index m = row_count_, d = null_.dimension();
  Index h = 0;
  for (Index j = 0; j < nv_; ++j)
    if (!free_(j)) held_joints_(h++) = j;
  if (null_.rank() < m || h > d) return Decided::undecided;
  unconstrained_optimum(in);
  auto residual = walk_residual_.head(task_rows_);
  auto y = task_x_.topLeftCorner(d, 1);
  auto multipliers = held_multipliers_.head(h);
  if (h > 0) {
    auto unit_columns = held_unit_.topLeftCorner(nv_, h);  // E_H, overwritten by to_null
    unit_columns.setZero();
    for (Index k = 0; k < h; ++k) unit_columns(held_joints_(k), k) = 1.0;
    auto held_null_t = held_null_t_.topLeftCorner(d, h);  // N_H^T
    null_.to_null(unit_columns, held_null_t);
    auto weighted = held_weighted_.topLeftCorner(d, h);  // M^-1 N_H^T
    weighted = held_null_t;
    if (!walk_dls_.gram_solve(weighted)) return Decided::undecided;
    auto gram = held_gram_.topLeftCorner(h, h);
    gram.noalias() = held_null_t.transpose() * weighted;
    // N_H of full row rank (no held column outside the free ones': column_outside) and w
    // accurate: the Gram matrix's lambda_min, at least 1 / |L^-1|_F^2, at least its trace
    // over the square of the DLS's condition bound (it is C^T C, C = R^-T N_H^T)
    const double trace = gram.trace();
    constexpr double kGramConditionBound =
        DampedLeastSquares::kMaxConditionBound * DampedLeastSquares::kMaxConditionBound;
    if (!cholesky_in_place(gram) ||
        !(kGramConditionBound / lower_inverse_norm2(gram, held_unit_.topLeftCorner(h, h)) >= trace))
      return Decided::undecided;
    multipliers.noalias() = held_null_t.transpose() * y;
    for (Index k = 0; k < h; ++k) multipliers(k) -= held_(held_joints_(k)) - qd0_(held_joints_(k));
    cholesky_solve(gram, multipliers);
    y.noalias() -= weighted * multipliers;
  }
  null_.from_null(y.col(0), delta_);
  walk_point_ = qd0_ + delta_;
  for (Index k = 0; k < h; ++k) walk_point_(held_joints_(k)) = held_(held_joints_(k));
  if (!free_in_box(walk_point_)) return Decided::refused;
  if (m > 0) {  // the held entries set to their bounds: the rows to their tolerance
    auto rows_residual = rows_scratch_.head(m);
    rows_residual.noalias() = rows_.topRows(m) * walk_point_;
    rows_residual -= rhs_.head(m);
    if (rows_residual.cwiseAbs().maxCoeff() > tol_.rows) return Decided::undecided;
  }
  if (h == 0) return Decided::accepted;
  residual.noalias() = in.ee_jacobian * walk_point_;
  residual -= in.twist;
  gradient_.noalias() = in.ee_jacobian.transpose() * residual;
  // D^T D qd = lambda^2 N V V^T N^T qd = lambda^2 N y (V square, N^T qd_0 = 0)
  gradient_ += (walk_damping_ * walk_damping_) * delta_;
  reduced_.setZero();
  for (Index k = 0; k < h; ++k) reduced_(held_joints_(k)) = -multipliers(k);
  const double tolerance = tol_.release_tolerance * (1.0 + gradient_.cwiseAbs().maxCoeff());
  return inward(reduced_, tolerance) < 0 ? Decided::accepted : Decided::refused;
}

void Step::unconstrained_optimum(const Inputs& in) {
  null_.pseudo_solve(rhs_.head(row_count_), qd0_);
  auto residual = walk_residual_.head(task_rows_);
  residual = in.twist;
  residual.noalias() -= in.ee_jacobian * qd0_;
  walk_dls_.solve(residual, task_x_.topLeftCorner(null_.dimension(), 1));
}

bool Step::walk_optimum_fits_box(const Inputs& in) {
  if (null_.rank() < row_count_) return false;
  unconstrained_optimum(in);
  null_.from_null(task_x_.col(0).head(null_.dimension()), delta_);
  walk_goal_ = qd0_ + delta_;
  return (walk_goal_.array() >= lower_.array()).all() && (walk_goal_.array() <= upper_.array()).all();
}

bool Step::free_in_box(const ConstVectorRef& point) const {
  for (Index j = 0; j < nv_; ++j)
    if (free_(j) && !(point(j) >= lower_(j) && point(j) <= upper_(j))) return false;
  return true;
}

void Step::remember_held(const ConstVectorRef& qd) {
  warm_start_ = accelerating_ && report_.method == Method::saturated &&
                report_.status != Status::failed && sns_rows_scale_ >= 1.0 && free_.any();
  if (!warm_start_) return;
  held_count_ = 0;
  for (Index j = 0; j < nv_; ++j) {
    held_side_(j) = free_(j) ? 0 : sns_qd_(j) - lower_(j) <= upper_(j) - sns_qd_(j) ? -1 : 1;
    held_count_ += held_side_(j) != 0;
  }
  held_limiting_ = sns_limiting_;
  held_undamped_ = sns_damping_ == 0.0;
  held_command_ = qd;
}

Index Step::stack_walk_task(const Inputs& in) {
  const Index damping_count = task_damping_rows(in);
  walk_task_.topRows(task_rows_) = in.ee_jacobian;
  walk_rhs_.head(task_rows_) = in.twist;
  walk_rhs_.segment(task_rows_, damping_count).setZero();
  return task_rows_ + damping_count;
}

Index Step::task_damping_rows(const Inputs& in) {
  const Index m = row_count_;
  if (!null_holds_rows_) null_.factor(rows_.topRows(m));  // else walk_to_rows's, bit for bit
  const Index d = null_.dimension();
  walk_sigma_min_ = std::numeric_limits<double>::quiet_NaN();
  walk_sigma_deferred_ = false;
  walk_damping_ = 0.0;
  if (d == 0) return 0;
  auto task_t = task_t_.topLeftCorner(nv_, task_rows_);
  task_t = in.ee_jacobian.transpose();
  auto task_null_t = task_null_t_.topLeftCorner(d, task_rows_);
  null_.to_null(task_t, task_null_t);
  auto task_null = task_null_.topLeftCorner(task_rows_, d);
  task_null = task_null_t.transpose();
  if (sigma_min_source_ == &walk_dls_) settle_sigma_min();
  walk_dls_.factor(task_null, policy_);
  walk_damping_ = walk_dls_.damping();
  walk_sigma_deferred_ = walk_dls_.sigma_min_deferrable();
  if (!walk_sigma_deferred_) walk_sigma_min_ = walk_dls_.sigma_min();
  if (walk_damping_ == 0.0) return 0;
  const Index rank = walk_dls_.rank();
  for (Index k = 0; k < rank; ++k) {  // D = lambda V_r^T N^T, one row per kept direction
    null_.from_null(walk_dls_.row_space().col(k), delta_);
    walk_task_.row(task_rows_ + k) = walk_damping_ * delta_.transpose();
  }
  return rank;
}

Index Step::task_wrong_side(const Eigen::Ref<const RowMatrix>& task,
                            const ConstVectorRef& task_rhs) {
  auto residual = walk_residual_.head(task.rows());
  residual.noalias() = task * walk_point_;
  residual -= task_rhs;
  gradient_.noalias() = task.transpose() * residual;
  reduced_ = gradient_;
  const Index m = row_count_;
  Index n_free = 0;
  for (Index j = 0; j < nv_; ++j) {
    if (!free_(j)) continue;
    columns_.col(n_free).head(m) = rows_.col(j).head(m);
    gradient_free_(n_free++) = gradient_(j);
  }
  if (m > 0) {  // g_i + a_i^T mu = g_i - (A_F^+ a_i)^T g_F
    // a column the free ones cannot give (|A_F A_F^+ a_i - a_i|_2 above the rank cut of
    // [A_F a_i], rank max(1, |a_j|_2)): the joint cannot move alone while the rows hold,
    // its reduced gradient is not defined and releasing it would hold it again at once
    // (controllers.cjm.saturation_walk.column_outside)
    double free_largest = 0.0;
    for (Index f = 0; f < n_free; ++f)
      free_largest = std::max(free_largest, columns_.col(f).head(m).norm());
    auto weights = free_x_.head(n_free);
    auto reached = rows_scratch_.head(m);
    for (Index j = 0; j < nv_; ++j) {
      if (free_(j)) continue;
      reached.setZero();
      if (n_free > 0) {
        null_.pseudo_solve(rows_.col(j).head(m), weights);
        reduced_(j) -= weights.dot(gradient_free_.head(n_free));
        reached.noalias() = columns_.topLeftCorner(m, n_free) * weights;
      }
      const double largest = std::max(free_largest, rows_.col(j).head(m).norm());
      reached -= rows_.col(j).head(m);
      if (reached.norm() > tol_.rank * std::max(1.0, largest)) reduced_(j) = 0.0;
    }
  }
  return inward(reduced_, tol_.release_tolerance * (1.0 + gradient_.cwiseAbs().maxCoeff()));
}

Index Step::inward(const ConstVectorRef& gradient, double tolerance) const {
  // a joint without room in its box beyond rounding is never released: the walk would
  // hold it again at once; of joints within the tolerance of the most, the first
  // (controllers.cjm.saturation_walk._inward)
  const double noise = walk_point_.cwiseAbs().maxCoeff();
  auto slope = [&](Index j) {
    if (free_(j)) return -std::numeric_limits<double>::infinity();
    if (walk_point_(j) >= upper_(j) && gap_to_bound(lower_(j), walk_point_(j), noise) < 0.0)
      return gradient(j);
    if (walk_point_(j) <= lower_(j) && gap_to_bound(upper_(j), walk_point_(j), noise) > 0.0)
      return -gradient(j);
    return -std::numeric_limits<double>::infinity();
  };
  double most = -std::numeric_limits<double>::infinity();
  for (Index j = 0; j < nv_; ++j) most = std::max(most, slope(j));
  if (!(most > tolerance)) return -1;
  for (Index j = 0; j < nv_; ++j)
    if (slope(j) >= most - tolerance) return j;
  return -1;
}

double Step::walk_to_rows() {
  const Index m = row_count_;
  null_holds_rows_ = false;
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
      null_holds_rows_ = n_free == nv_;
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
  auto gradient = delta_.head(nv_);  // of |rows qd - rhs|^2 / 2: -rows^T residual
  gradient.noalias() = -(rows_.topRows(row_count_).transpose() * residual);
  return inward(gradient, tol_.rows);
}

Index Step::walk() {
  // of joints whose reaches tie to at_bound, the first stops the walk
  // (controllers.cjm.saturation_walk._walk)
  walk_move_ = walk_goal_ - walk_point_;
  const double noise = walk_point_.cwiseAbs().maxCoeff();
  const double still = std::max(tol_.still_direction, tol_.at_bound * walk_move_.cwiseAbs().maxCoeff());
  auto reach = [&](Index j) {
    const double move = walk_move_(j);
    if (!free_(j) || !(std::abs(move) > still)) return std::numeric_limits<double>::infinity();
    const double side = move > 0.0 ? upper_(j) : lower_(j);
    return std::max(gap_to_bound(side, walk_point_(j), noise) / move, 0.0);
  };
  double smallest = 1.0, fraction = 1.0, bound = 0.0;
  Index joint = -1;
  for (Index j = 0; j < nv_; ++j) {
    walk_reach_(j) = reach(j);
    smallest = std::min(smallest, walk_reach_(j));
  }
  for (Index j = 0; j < nv_ && joint < 0; ++j) {
    const double r = walk_reach_(j);
    if (r < 1.0 && r <= smallest + tol_.at_bound) {
      fraction = r;
      joint = j;
      bound = walk_move_(j) > 0.0 ? upper_(j) : lower_(j);
    }
  }
  for (Index j = 0; j < nv_; ++j)
    if (free_(j)) walk_point_(j) += fraction * walk_move_(j);
  if (joint >= 0) walk_point_(joint) = bound;
  walk_point_ = walk_point_.cwiseMax(lower_).cwiseMin(upper_);
  return joint;
}

void Step::walk_result(const Inputs& in, double rows_scale, Index limiting_joint) {
  // controllers.cjm.saturation_walk._walk_result: a met twist is s = 1, not its share
  // J qd . V / |V|^2, which is 1 only up to rounding
  auto achieved = scratch_rows_.head(task_rows_);
  achieved.noalias() = in.ee_jacobian * sns_qd_;
  const double tolerance = tol_.twist * (1.0 + in.twist.cwiseAbs().maxCoeff());
  const double twist_norm = in.twist.squaredNorm();
  double task_scale = 1.0;
  if ((achieved - in.twist).cwiseAbs().maxCoeff() > tolerance && twist_norm > 0.0) {
    task_scale = std::min(std::max(achieved.dot(in.twist) / twist_norm, 0.0), 1.0);
  }
  achieved -= task_scale * in.twist;
  sns_missed_ = achieved.cwiseAbs().maxCoeff() > tolerance;
  sns_task_scale_ = task_scale;
  sns_rows_scale_ = rows_scale;
  sns_limiting_ = limiting_joint;
  sns_sigma_min_ = walk_sigma_min_;
  sns_sigma_deferred_ = walk_sigma_deferred_;
  sns_damping_ = walk_damping_;
}

}  // namespace cjm
