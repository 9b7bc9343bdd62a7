// The driver of the compiled step: controllers.base.Controller.solve and the CJM's
// barriers' active set (controllers/cjm/controller.py), the joint box and the clip guard
// (controllers/joint_limits.py), the status (docs/design.md sections 8, 12 and 16).
#include "step.hpp"

#include "terms_layout.hpp"

#include <stdexcept>
#include <string>

namespace cjm {

namespace {
constexpr Index kEventsPerConstraint = 8;
}  // namespace

Step::Step(Index nq, Index nv, Index task_rows, DampingPolicy policy, bool general_only,
           std::vector<ConstraintPlan> constraints, JointBox box, double posture_gain,
           Vector posture_target, Tolerances tolerances, Index pair_capacity,
           Index event_capacity)
    : nq_(nq), nv_(nv), task_rows_(task_rows), policy_(policy), tol_(tolerances),
      general_only_(general_only),
      constraints_(std::move(constraints)), box_(std::move(box)), posture_gain_(posture_gain),
      posture_target_(std::move(posture_target)),
      null_first_(0, 0, tolerances.rank), null_second_(0, 0, tolerances.rank),
      null_(0, 0, tolerances.rank), dls_(0, 0, tolerances.rank), walk_dls_(0, 0, tolerances.rank), pre_svd_(6, std::max<Index>(nv, 6)), closest_svd_(nv, nv + 7) {
  if (nq < 1 || nv < 1 || task_rows < 1)
    throw std::invalid_argument("nq, nv and the task rows must be positive");
  for (Index i = 0; i < static_cast<Index>(constraints_.size()); ++i) {
    const ConstraintPlan& plan = constraints_[i];
    if (plan.rows < 1 || plan.rows > 3)
      throw std::invalid_argument("a constraint has 1 to 3 rows");
    row_offset_.push_back(total_rows_);
    terms_offset_.push_back(terms_size_);
    total_rows_ += plan.rows;
    terms_size_ += cjm::terms_size(plan.rows);
    (plan.equality ? equalities_ : barriers_).push_back(i);
    for (Index j : plan.pre) if (j < 0 || j >= nv) throw std::invalid_argument("pre index out of range");
    for (Index j : plan.post) if (j < 0 || j >= nv) throw std::invalid_argument("post index out of range");
  }
  for (ConstraintPlan& plan : constraints_) {
    plan.off.clear();
    if (!plan.analytical) continue;
    for (Index j = 0; j < nv; ++j)
      if (std::find(plan.pre.begin(), plan.pre.end(), j) == plan.pre.end() &&
          std::find(plan.post.begin(), plan.post.end(), j) == plan.post.end())
        plan.off.push_back(j);
  }
  const Index n_constraints = static_cast<Index>(constraints_.size());
  if (pair_capacity < 0) throw std::invalid_argument("pair_capacity must be >= 0");
  const Index m = std::max<Index>(1, total_rows_ + pair_capacity);
  if (box_.velocity_lower.size() != nv || box_.velocity_upper.size() != nv ||
      box_.velocity_limit.size() != nv || box_.q_min.size() != static_cast<Index>(box_.limited_q.size()) ||
      box_.q_max.size() != box_.q_min.size() || box_.limited_v.size() != box_.limited_q.size() ||
      (box_.box_test.rows() > 0 && box_.box_test.cols() != nv + nq + 1) ||
      (box_.acceleration_step.size() != 0 &&
       (box_.acceleration_step.size() != nv || box_.slack.size() != nv || !(box_.dt > 0.0) ||
        !(box_.limit_gain > 0.0))) ||
      box_.damper_step.size() != box_.acceleration_step.size() ||
      (box_.jerk_step.size() != 0 &&
       (box_.jerk_step.size() != nv || box_.acceleration_step.size() == 0)))
    throw std::invalid_argument("joint box of the wrong size");
  if (posture_target_.size() != 0 && (posture_target_.size() != nq || nq != nv))
    throw std::invalid_argument("a posture target needs nq == nv and one entry per joint");
  posture_velocity_.resize(nv);
  accelerating_ = box_.acceleration_step.size() != 0;
  previous_ = Vector::Zero(nv);
  previous_change_ = Vector::Zero(nv);
  jerking_ = box_.jerk_step.size() != 0;
  damper_gaps_ = Vector::Zero(n_constraints);
  damper_gains_ = Vector::Zero(n_constraints);
  active_.reserve(n_constraints);
  waiting_.reserve(n_constraints);
  if (event_capacity == 0 || event_capacity < -1)
    throw std::invalid_argument("event_capacity must be positive (or -1: the default)");
  events_ = RowMatrix::Zero(
      event_capacity > 0 ? event_capacity : kEventsPerConstraint * (n_constraints + 2) + pair_capacity,
      4);
  pair_rows_ = RowMatrix::Zero(pair_capacity, nv);
  pair_lower_ = Vector::Zero(pair_capacity);
  pair_rhs_ = Vector::Zero(pair_capacity);
  active_pairs_.reserve(pair_capacity);
  active_pair_out_.resize(std::max<Index>(1, pair_capacity));
  if (pair_capacity > 0) {
    null_first_ = NullSpace(std::max<Index>(1, total_rows_), nv, tol_.rank);
    null_second_ = NullSpace(pair_capacity, nv, tol_.rank);
    second_t_.resize(nv, pair_capacity);
    second_null_t_.resize(nv, pair_capacity);
    second_null_.resize(pair_capacity, nv);
    first_qd_.resize(nv);
    second_x_.resize(std::max(nv, pair_capacity));
  }
  saturated_.resize(nv);
  clip_joints_.resize(nv);
  saturation_joints_.resize(nv);
  active_barriers_.resize(std::max<Index>(1, n_constraints));
  all_rows_.resize(m, nv);
  rows_.resize(m, nv);
  all_rhs_.resize(m);
  rhs_.resize(m);
  null_ = NullSpace(m, nv, tol_.rank);
  // the saturation around the previous command solves [J_e; D] (at most 2 task_rows rows)
  dls_ = DampedLeastSquares(2 * task_rows, std::max<Index>(nv + 7, 8), tol_.rank);
  walk_dls_ = DampedLeastSquares(task_rows, std::max<Index>(nv, 1), tol_.rank);
  task_t_.resize(nv, 2 * task_rows);
  task_null_t_.resize(nv, 2 * task_rows);
  task_null_.resize(2 * task_rows, nv);
  task_rhs_.resize(2 * task_rows, 2);
  walk_task_.resize(2 * task_rows, nv);
  walk_rhs_.resize(2 * task_rows);
  walk_residual_.resize(2 * task_rows);
  walk_rows_rhs_.resize(m);
  task_x_.resize(nv + 7, 2);
  for (Vector* v : {&qd0_, &delta_, &lower_, &upper_, &box_lower_, &box_upper_, &free_x_,
                    &posture_null_, &held_, &best_held_, &base_, &direction_, &sns_qd_,
                    &walk_point_, &walk_goal_, &walk_move_, &walk_reach_, &gradient_, &reduced_,
                    &gradient_free_})
    v->resize(nv);
  stacked_.resize(std::max<Index>(box_.box_test.rows(), 1));
  scratch_rows_.resize(std::max(m, task_rows));
  rows_scratch_.resize(m);
  rank_weights_.resize(nv);
  columns_.resize(m, nv);
  task_columns_.resize(2 * task_rows, nv);
  free_.resize(nv);
  held_side_ = Eigen::Matrix<Index, Eigen::Dynamic, 1>::Zero(nv);
  held_joints_.resize(nv);
  held_command_.resize(nv);
  held_unit_.resize(nv, nv);
  held_null_t_.resize(nv, nv);
  held_weighted_.resize(nv, nv);
  held_gram_.resize(nv, nv);
  held_multipliers_.resize(nv);
  best_free_.resize(nv);
  pre_jacobian_.resize(6, nv);
  joint_map_.resize(nv, nv + 7);
  task_map_.resize(6, nv + 7);
  cjm_.resize(6, nv + 7);
  ad_cjm_.resize(6, 6);
  basis_qr_.resize(nv + 7, 6);
  basis_.resize(nv + 7, nv + 7);
  closest_.resize(nv, nv + 7);
  free_with_one_.resize(nv + 8);
  twist_a_.resize(6);
  twist_a_with_one_.resize(7);
  basis_tau_.resize(6);
  goal_.resize(nv);
  step_.resize(nv + 7);
}

void Step::check_sizes(const Inputs& in, const VectorRef& qd) const {
  const Index n = static_cast<Index>(constraints_.size());
  if (in.q.size() != nq_ || in.twist.size() != task_rows_ || in.ee_jacobian.rows() != task_rows_ ||
      in.ee_jacobian.cols() != nv_ || qd.size() != nv_ || in.terms.size() != terms_size_ ||
      (n > 0 && (in.frame_jacobians.rows() != 6 * n || in.frame_jacobians.cols() != nv_)) ||
      (in.use_posture && in.posture.size() != nv_))
    throw std::invalid_argument("compiled CJM step: an input has the wrong size");
}

void Step::solve(const ConstVectorRef& q, const ConstVectorRef& twist,
                 const Eigen::Ref<const RowMatrix>& ee_jacobian,
                 const Eigen::Ref<const RowMatrix>& frame_jacobians, const ConstVectorRef& terms,
                 const ConstVectorRef& posture, bool use_posture, bool analytical_allowed,
                 VectorRef qd) {
  if (q.size() != nq_) throw std::invalid_argument("compiled CJM step: q has the wrong size");
  const bool posture_from_q = use_posture && posture_target_.size() != 0;
  if (posture_from_q) posture_velocity_ = posture_gain_ * (posture_target_ - q);
  const ConstVectorRef posture_used(posture_from_q ? ConstVectorRef(posture_velocity_) : posture);
  const Inputs in{q, twist, ee_jacobian, frame_jacobians, terms, posture_used, use_posture,
                  analytical_allowed};
  check_sizes(in, qd);
  report_ = Report();
  sigma_min_source_ = nullptr;
  sigma_min_event_ = -1;
  rows_ready_ = false;
  active_.assign(equalities_.begin(), equalities_.end());
  active_pairs_.clear();
  pair_rhs_.head(pair_count_) = pair_lower_.head(pair_count_);
  warm_tried_ = false;
  try {
    if (saturate_before_the_form(in)) {
      report_saturation(qd);
      clip_finite(q, qd);
    } else {
      solve_rows(in, qd);
      if (!barriers_.empty() || pair_count_ > 0) activate(in, qd);
      if (!qd.allFinite()) {
        report_.status = Status::failed;
        event(Event::non_finite);
        stop(q, qd);
      } else if (!box_contains(q, qd)) {
        if (!accelerating_) compute_box(q);  // with acceleration limits box_contains computed it
        saturate(in, qd);
        clip_finite(q, qd);
      }
    }
  } catch (const NoConvergence&) {
    report_.status = Status::failed;
    event(Event::no_convergence);
    stop(q, qd);
  }
  remember_held(qd);
  previous_change_ = qd - previous_;
  previous_ = qd;
  if (report_.status != Status::failed && report_.equality_residual > tol_.equality) {
    report(Status::constraint_degraded);
    event(Event::residual, report_.equality_residual);
  }
  write_report();
}

// -- rows and forms ---------------------------------------------------------------------

void Step::solve_rows(const Inputs& in, VectorRef qd) {
  // a braking-aware barrier's bound needs its joint-space row: the general form
  if (active_.size() == 1 && active_pairs_.empty() && !general_only_ && in.analytical_allowed &&
      !(accelerating_ && !constraints_[active_[0]].equality) && analytical(in, active_[0], qd))
    return;
  general(in, qd);
}

void Step::set_pair_count(Index count) {
  if (count < 0 || count > pair_capacity())
    throw std::invalid_argument("more collision rows than the step's capacity");
  pair_count_ = count;
}

void Step::activate(const Inputs& in, VectorRef qd) {
  ensure_rows(in);
  while (activate_worst(qd)) solve_rows(in, qd);
}

bool Step::activate_worst(const ConstVectorRef& qd) {
  Index worst = -1;
  double worst_violation = -std::numeric_limits<double>::infinity();
  for (Index i : barriers_) {
    if (std::find(active_.begin(), active_.end(), i) != active_.end()) continue;
    const double violation = barrier_violation(i, qd);
    if (violation > worst_violation || worst < 0) {
      worst_violation = violation;
      worst = i;
    }
  }
  if (worst >= 0 && worst_violation > 0.0) {
    active_.push_back(worst);
    return true;
  }
  worst = -1;
  for (Index i = 0; i < pair_count_; ++i) {
    if (std::find(active_pairs_.begin(), active_pairs_.end(), i) != active_pairs_.end()) continue;
    const double violation = pair_lower_(i) - pair_rows_.row(i).dot(qd) -
                             tol_.barrier * (1.0 + pair_rows_.row(i).cwiseAbs().dot(qd.cwiseAbs()));
    if (violation > worst_violation || worst < 0) {
      worst_violation = violation;
      worst = i;
    }
  }
  if (worst >= 0 && worst_violation > 0.0) {
    active_pairs_.push_back(worst);
    return true;
  }
  return false;
}

void Step::ensure_rows(const Inputs& in) {
  if (rows_ready_) return;
  for (Index i = 0; i < static_cast<Index>(constraints_.size()); ++i) {
    const Index k = constraints_[i].rows;
    const auto residual_rows = residual_rows_of(in.terms.data() + terms_offset_[i], k);
    all_rows_.middleRows(row_offset_[i], k).noalias() =
        residual_rows.rightCols(6) * in.frame_jacobians.middleRows(6 * i, 6);
    all_rhs_.segment(row_offset_[i], k) = -residual_rows.col(0);
    if (!constraints_[i].equality)
      all_rhs_(row_offset_[i]) +=
          damper_raise(all_rows_.row(row_offset_[i]), damper_gaps_(i), damper_gains_(i));
  }
  rows_ready_ = true;
}

void Step::gather_active_rows() {
  Index m = 0;
  for (Index i : active_) {
    const Index k = constraints_[i].rows;
    rows_.middleRows(m, k) = all_rows_.middleRows(row_offset_[i], k);
    rhs_.segment(m, k) = all_rhs_.segment(row_offset_[i], k);
    m += k;
  }
  for (Index i : active_pairs_) {
    rows_.row(m) = pair_rows_.row(i);
    rhs_(m) = pair_rhs_(i);
    ++m;
  }
  row_count_ = m;
}

double Step::barrier_violation(Index index, const ConstVectorRef& qd) const {
  // beyond the rounding of the product (python_step.PythonStep._barrier_violation)
  const Index row = row_offset_[index];
  const double scale = 1.0 + all_rows_.row(row).cwiseAbs().dot(qd.cwiseAbs());
  return all_rhs_(row) - all_rows_.row(row).dot(qd) - tol_.barrier * scale;
}

// -- the joint box ----------------------------------------------------------------------

bool Step::box_contains(const ConstVectorRef& q, const ConstVectorRef& qd) {
  if (accelerating_) {  // the braking bound is not affine in q: the exact box
    compute_box(q);
    for (Index i = 0; i < nv_; ++i)
      if (!(qd(i) >= lower_(i) - box_.slack(i) && qd(i) <= upper_(i) + box_.slack(i))) return false;
    return true;
  }
  const Index rows = box_.box_test.rows();
  if (rows == 0) return true;
  auto stacked = stacked_.head(rows);
  stacked.noalias() = box_.box_test.leftCols(nv_) * qd;
  stacked.noalias() += box_.box_test.middleCols(nv_, nq_) * q;
  stacked += box_.box_test.col(nv_ + nq_);
  return stacked.maxCoeff() <= 0.0;
}

void Step::compute_box(const ConstVectorRef& q) {
  lower_ = box_.velocity_lower;
  upper_ = box_.velocity_upper;
  if (box_.position_limits) {
    for (size_t i = 0; i < box_.limited_q.size(); ++i) {
      const Index v = box_.limited_v[i];
      const double q_i = q(box_.limited_q[i]);
      const double below = box_.q_min(i) - q_i, above = box_.q_max(i) - q_i;
      double low = below * box_.position_gain, high = above * box_.position_gain;
      if (accelerating_ && std::isfinite(box_.acceleration_step(v))) {  // braking-aware
        if (below <= 0.0) low = -braking_speed(-below, box_.acceleration_step(v), box_.limit_gain);
        if (above >= 0.0) high = braking_speed(above, box_.acceleration_step(v), box_.limit_gain);
      }
      lower_(v) = std::max(lower_(v), low);
      upper_(v) = std::min(upper_(v), high);
    }
  }
  // past a limit the position bound points back; never faster than the velocity limit
  lower_ = lower_.cwiseMin(box_.velocity_upper);
  upper_ = upper_.cwiseMax(box_.velocity_lower);
  upper_ = upper_.cwiseMax(lower_);
  if (!accelerating_) return;
  // controllers.joint_acceleration.acceleration_box: where it misses, it gives way
  for (Index i = 0; i < nv_; ++i) {
    const double step = box_.acceleration_step(i);
    double low = previous_(i) - step, high = previous_(i) + step;
    if (low > upper_(i) || high < lower_(i)) {
      low = high = std::min(std::max(std::min(std::max(lower_(i), low), high), lower_(i)), upper_(i));
    }
    lower_(i) = std::max(lower_(i), low);
    upper_(i) = std::min(upper_(i), high);
  }
  if (!jerking_) return;
  // controllers.joint_acceleration.jerk_box: the change brakes towards a velocity limit;
  // where the window misses the box, it gives way
  for (Index i = 0; i < nv_; ++i) {
    const double centre = previous_(i) + previous_change_(i), step = box_.jerk_step(i);
    double low = centre - step, high = centre + step;
    const double limit = box_.velocity_upper(i);
    if (std::isfinite(limit)) {
      high = std::min(high, previous_(i) + braking_speed(std::max(limit - previous_(i), 0.0),
                                                         step, 1.0, 1.0));
      low = std::max(low, previous_(i) - braking_speed(std::max(limit + previous_(i), 0.0),
                                                       step, 1.0, 1.0));
      low = std::min(low, high);
    }
    if (low > upper_(i) || high < lower_(i)) {
      low = high = std::min(std::max(std::min(std::max(lower_(i), low), high), lower_(i)), upper_(i));
    }
    lower_(i) = std::max(lower_(i), low);
    upper_(i) = std::min(upper_(i), high);
  }
}

double Step::braking_speed(double distance, double step, double gain) const {
  return braking_speed(distance, step, gain, box_.dt);
}

double Step::braking_speed(double distance, double step, double gain, double dt) {
  const double c = 1.0 / gain;
  const double scaled = distance / (step * dt);
  double k = std::floor(std::max(std::sqrt(std::max(2.0 * scaled + c - c * c, 0.0)) - c, 0.0));
  const double x_0 = scaled / c;
  const double x_k = (scaled + k * (k - 1.0) / 2.0 + k * c) / (k + c);
  k = k + 1.0;
  const double x_next = (scaled + k * (k - 1.0) / 2.0 + k * c) / (k + c);
  // rounded down (ROUNDING_MARGIN), 0 below the smallest normal double, as in Python
  const double bound = step * std::min(std::min(x_0, x_k), x_next) *
                       (1.0 - 8.0 * std::numeric_limits<double>::epsilon());
  return bound < std::numeric_limits<double>::min() ? 0.0 : bound;
}

double Step::damper_raise(const Eigen::Ref<const Eigen::RowVectorXd, 0, Eigen::InnerStride<>>& row,
                          double gap, double gain) const {
  if (!accelerating_ || !(gap > 0.0) || !(gain > 0.0)) return 0.0;
  double step = 0.0;  // a_n dt: the share of sum_i |r_i| a_i dt
  for (Index i = 0; i < nv_; ++i)
    if (row(i) != 0.0) step += std::abs(row(i)) * box_.damper_step(i);
  if (!(step > 0.0) || !std::isfinite(step)) return 0.0;
  return std::max(0.0, gain * gap - braking_speed(gap, step, gain * box_.dt));
}

void Step::stop(const ConstVectorRef& q, VectorRef qd) {
  // the command nearest zero inside the box: zero unless a joint past its limit must
  // come back, or the acceleration limits cannot stop at once
  compute_box(q);
  for (Index i = 0; i < nv_; ++i) qd(i) = std::min(std::max(0.0, lower_(i)), upper_(i));
}

void Step::clip_finite(const ConstVectorRef& q, VectorRef qd) {
  clip(qd);
  if (!qd.allFinite()) {  // clipping passes a NaN through
    report_.status = Status::failed;
    event(Event::non_finite);
    stop(q, qd);
  }
}

void Step::clip(VectorRef qd) {
  const double largest = qd.cwiseAbs().maxCoeff();
  double change = 0.0;
  Index clipped = 0;
  for (Index i = 0; i < nv_; ++i) {
    const double value = std::min(std::max(qd(i), lower_(i)), upper_(i));
    change = std::max(change, std::abs(value - qd(i)));
    if (value != qd(i)) clip_joints_(clipped++) = i;
    qd(i) = value;
  }
  if (change > tol_.equality * (1.0 + largest)) {
    report(Status::constraint_degraded);
    event(Event::clipped, change);
    saturated_.head(clipped) = clip_joints_.head(clipped);
    report_.saturated_count = clipped;
    Index m = 0;
    for (Index i : equalities_) {
      const Index k = constraints_[i].rows;
      scratch_rows_.segment(m, k).noalias() = all_rows_.middleRows(row_offset_[i], k) * qd;
      scratch_rows_.segment(m, k) -= all_rhs_.segment(row_offset_[i], k);
      m += k;
    }
    if (m > 0) report_.equality_residual = scratch_rows_.head(m).cwiseAbs().maxCoeff();
  }
}

// -- the report -------------------------------------------------------------------------

void Step::report(Status status) {
  if (static_cast<int>(status) > static_cast<int>(report_.status)) report_.status = status;
}

void Step::event(Event event, double a, double b, double c) {
  if (report_.event_count < events_.rows()) {
    events_.row(report_.event_count++) << static_cast<double>(event), a, b, c;
    return;
  }
  ++report_.dropped_event_count;
  if (event == Event::no_convergence || event == Event::non_finite)
    events_.row(report_.event_count - 1) << static_cast<double>(event), a, b, c;
}

void Step::report_task_solution(const ConstMatrixRef& matrix, const ConstVectorRef& rhs,
                                const ConstVectorRef& x) {
  report_.damping = dls_.damping();
  if (dls_.sigma_min_deferrable()) {
    sigma_min_source_ = &dls_;
  } else {
    report_.sigma_min = dls_.sigma_min();
  }
  if (dls_.exact()) return;
  auto achieved = scratch_rows_.head(matrix.rows());
  achieved.noalias() = matrix * x;
  achieved -= rhs;
  const double residual = matrix.rows() ? achieved.cwiseAbs().maxCoeff() : 0.0;
  const double scale = rhs.size() ? rhs.cwiseAbs().maxCoeff() : 0.0;
  if (residual > tol_.twist * (1.0 + scale)) {
    report(Status::least_squares);
    event(Event::task_residual, report_.damping, residual);
  }
}

void Step::write_report() {
  for (size_t i = 0; i < active_pairs_.size(); ++i) active_pair_out_(i) = active_pairs_[i];
  Index barrier_count = 0;
  for (Index i : active_)
    if (!constraints_[i].equality) active_barriers_(barrier_count++) = i;
  report_.active_barrier_count = barrier_count;
}

}  // namespace cjm
