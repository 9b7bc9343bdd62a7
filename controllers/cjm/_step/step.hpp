// The compiled CJM step: the dense algebra of one step of controllers/cjm/ (the
// analytical form, the general form, the barriers' active set, saturation in the null
// space, the clip guard and the step status), in one call (docs/design.md section 16).
//
// The kinematics (kinematics.hpp) and each constraint's terms come in as arrays
// (pipeline.hpp fills them); this class does the rest with the same algorithms, the same
// damping, the same rank decisions and the same order of saturation as the Python
// reference.
#pragma once

#include <Eigen/LU>

#include <vector>

#include "damped.hpp"
#include "dense.hpp"
#include "nullspace.hpp"
#include "report.hpp"

namespace cjm {

//! Every tolerance the step decides with: controllers.cjm.tolerances.StepTolerances,
//! given by Python when the step is built (no copy of the numbers here).
struct Tolerances {
  double equality, twist, barrier, rank, pre_chain_pivot_ratio, pre_chain_min_singular_value,
      fast_path_min_sigma, least_squares_rcond, conflict_residual, rows, at_bound, box_margin,
      still_direction, release_tolerance;
};

//! One constraint: its rows and, when the analytical form may take it, its chain split.
struct ConstraintPlan {
  Index rows = 0;          // k
  bool equality = true;
  bool analytical = false;  // the EE downstream of its link, >= 6 joints before it, one EE
  std::vector<Index> pre, post;
  //! the joints on neither (off the path to the EE): set by Step from pre and post
  std::vector<Index> off;
};

//! The joint box of controllers/joint_limits.py (JointBounds.box and BoxTest).
struct JointBox {
  Vector velocity_lower, velocity_upper;  // the velocity box (+-inf where none or off)
  Vector velocity_limit;                  // inf where none (a bound below it is a position bound)
  std::vector<Index> limited_q, limited_v;
  Vector q_min, q_max;
  double position_gain = 0.0;  // limit_gain / dt
  bool position_limits = true;
  RowMatrix box_test;          // M with M [qd; q; 1] <= 0 inside the box
  //! a dt per joint (inf where none); empty: no acceleration limit (section 8.4)
  Vector acceleration_step;
  double dt = 0.0, limit_gain = 1.0;
  Vector slack;                // BoxTest.slack: the test's tolerance per joint
  //! DAMPER_BRAKING_SHARE a dt per joint: the deceleration step the braking-aware dampers
  //! count on (controllers.joint_acceleration.damper_deceleration; docs/design.md 12)
  Vector damper_step;
  //! j dt^2 per joint (inf where none); empty: no jerk limit (section 8.5)
  Vector jerk_step;
};

class Step {
 public:
  //! ``posture_target`` (nq) non-empty: every joint has one coordinate, so the posture
  //! velocity is ``posture_gain (posture_target - q)`` (pin.difference) and is computed
  //! here; empty: Python passes it to solve(). ``event_capacity``: the rows of events();
  //! -1: kEventsPerConstraint per constraint (two more) and one per collision row.
  Step(Index nq, Index nv, Index task_rows, DampingPolicy policy, bool general_only,
       std::vector<ConstraintPlan> constraints, JointBox box, double posture_gain,
       Vector posture_target, Tolerances tolerances, Index pair_capacity = 0,
       Index event_capacity = -1);

  Index nq() const { return nq_; }
  Index nv() const { return nv_; }
  Index task_rows() const { return task_rows_; }

  //! One step: ``qd`` for ``twist``. ``frame_jacobians`` stacks each constraint's
  //! 6 x nv LOCAL Jacobian; ``terms`` each constraint's flat terms buffer
  //! (controllers.cjm.analytical.terms_views); ``posture`` is read when ``use_posture``.
  void solve(const ConstVectorRef& q, const ConstVectorRef& twist,
             const Eigen::Ref<const RowMatrix>& ee_jacobian,
             const Eigen::Ref<const RowMatrix>& frame_jacobians, const ConstVectorRef& terms,
             const ConstVectorRef& posture, bool use_posture, bool analytical_allowed,
             VectorRef qd);

  //! The last step's report (its lists: the first counts of the arrays below), its
  //! sigma_min computed now if the step left it to the first read (settle_sigma_min).
  const Report& report() {
    settle_sigma_min();
    return report_;
  }
  RowMatrix& events() { return events_; }
  Eigen::Matrix<Index, Eigen::Dynamic, 1>& saturated_joints() { return saturated_; }
  Eigen::Matrix<Index, Eigen::Dynamic, 1>& active_barriers() { return active_barriers_; }
  Eigen::Matrix<Index, Eigen::Dynamic, 1>& saturation_joints() { return saturation_joints_; }
  //! The previous command, the acceleration limits' reference (zero at rest).
  Vector& previous() { return previous_; }
  //! The previous command minus the one before, the jerk limits' reference.
  Vector& previous_change() { return previous_change_; }
  Index terms_size() const { return terms_size_; }
  Index constraint_count() const { return static_cast<Index>(constraints_.size()); }
  //! Whether constraint ``index`` is an equality (else a one-sided barrier's rows).
  bool equality(Index index) const { return constraints_[index].equality; }
  //! Where constraint ``index``'s flat terms buffer starts in ``terms``.
  Index terms_offset(Index index) const { return terms_offset_[index]; }

  //! Each constraint's damper gap (its first row's error) and gain, written before a step
  //! with its terms (by the pipeline, or by Python for the terms it writes); an
  //! inequality's bound is braking-aware with acceleration limits (docs/design.md 12).
  Vector& damper_gaps() { return damper_gaps_; }
  Vector& damper_gains() { return damper_gains_; }
  //! controllers.joint_acceleration.braked_lower for one row ``row qd >= f - gain gap``:
  //! how much its bound rises (0 without acceleration limits).
  double damper_raise(const Eigen::Ref<const Eigen::RowVectorXd, 0, Eigen::InnerStride<>>& row,
                      double gap, double gain) const;

  //! Collision rows ``pair_rows() qd >= pair_lower()`` (docs/design.md section 18.4):
  //! The first set_pair_count() of at most pair_capacity(), written before a step by the
  //! pipeline's collision rows (Collisions::write_rows) or, for shapes it does not cover, by Python.
  RowMatrix& pair_rows() { return pair_rows_; }
  Vector& pair_lower() { return pair_lower_; }
  Index pair_capacity() const { return pair_lower_.size(); }
  void set_pair_count(Index count);
  //! The collision rows the last step held at their bound, in the order activated.
  Eigen::Matrix<Index, Eigen::Dynamic, 1>& active_pairs() { return active_pair_out_; }
  Index active_pair_count() const { return static_cast<Index>(active_pairs_.size()); }

 private:
  struct Inputs {
    const ConstVectorRef& q;
    const ConstVectorRef& twist;
    const Eigen::Ref<const RowMatrix>& ee_jacobian;
    const Eigen::Ref<const RowMatrix>& frame_jacobians;
    const ConstVectorRef& terms;
    const ConstVectorRef& posture;
    bool use_posture;
    bool analytical_allowed;
  };
  //! ``qd(s) = base + s direction`` over one saturated set (controllers/cjm/saturation.py).
  struct Split {
    double rows_residual = 0.0;
    Index task_rank = 0;
    bool task_solved = false;  // the free joints left the task a null space: dls_ holds its DLS
  };

  // step.cpp: the driver, the barriers' active set, the box and the clip
  void check_sizes(const Inputs& in, const VectorRef& qd) const;
  void solve_rows(const Inputs& in, VectorRef qd);
  void activate(const Inputs& in, VectorRef qd);
  //! The most violated waiting barrier, else collision row, made active; false if none.
  bool activate_worst(const ConstVectorRef& qd);
  //! controllers.cjm.general.hold_pairs_below on the gathered rows.
  void hold_pairs_below();
  void ensure_rows(const Inputs& in);
  void gather_active_rows();
  double barrier_violation(Index index, const ConstVectorRef& qd) const;
  bool box_contains(const ConstVectorRef& q, const ConstVectorRef& qd);
  void compute_box(const ConstVectorRef& q);
  //! controllers.joint_acceleration.braking_speed at ``gain``.
  double braking_speed(double distance, double step, double gain) const;
  //! controllers.joint_acceleration.braking_speed at ``gain`` and period ``dt``.
  static double braking_speed(double distance, double step, double gain, double dt);
  //! The fallback of a failed step: zero, or with acceleration limits the command
  //! nearest zero inside the box.
  void stop(const ConstVectorRef& q, VectorRef qd);
  void clip(VectorRef qd);
  //! clip(), then the stop command if that left a non-finite entry.
  void clip_finite(const ConstVectorRef& q, VectorRef qd);
  void report(Status status);
  //! ``event`` recorded in events(); past its last row it is counted as dropped (the
  //! status never depends on the record), and a failure, whose words replace the
  //! message, takes the last row.
  void event(Event event, double a = 0.0, double b = 0.0, double c = 0.0);
  void report_task_solution(const ConstMatrixRef& matrix, const ConstVectorRef& rhs,
                            const ConstVectorRef& x);
  //! The report's sigma_min from the DLS that left it to the first read (an undamped QR
  //! solve decides without it; its power iteration was a quarter of the dual robot's step
  //! and a fifth of the saturation around the previous command: docs/design.md 16): dls_
  //! (report_task_solution) or walk_dls_ (saturate). Called before that DLS factors again
  //! and by report().
  void settle_sigma_min() {
    if (sigma_min_source_ == nullptr) return;
    report_.sigma_min = sigma_min_source_->sigma_min();
    sigma_min_source_ = nullptr;
    if (sigma_min_event_ >= 0 && events_(sigma_min_event_, 0) == static_cast<double>(Event::task_missed))
      events_(sigma_min_event_, 1) = report_.sigma_min;  // not overwritten by a failure
    sigma_min_event_ = -1;
  }
  //! dls_.factor, the report's sigma_min settled first if dls_ still owes it.
  void factor_task(const ConstMatrixRef& matrix, const DampingPolicy& policy) {
    if (sigma_min_source_ == &dls_) settle_sigma_min();
    dls_.factor(matrix, policy);
  }
  void write_report();

  // analytical.cpp
  bool analytical(const Inputs& in, Index index, VectorRef qd);
  bool square_pre_chain(const Inputs& in, Index index, VectorRef qd);
  bool redundant_pre_chain(const Inputs& in, Index index, VectorRef qd);
  void closest_to_posture(const Inputs& in, Index n_columns, bool use_posture);
  //! ``max |C v_c - b|`` of constraint ``index`` (k rows) for the pre-chain's twist,
  //! already in ``twist_a_with_one_.tail(6)``; the analytical form's residual and method.
  void record_pre_chain_residual(const Inputs& in, Index index, Index k);

  // general.cpp
  void general(const Inputs& in, VectorRef qd);
  //! The rows ``rows_ qd = rows_rhs`` exactly over the free joints, then ``task qd ~ twist``.
  //! ``factored``: every joint free, the task J_e and the damping rows D of
  //! task_damping_rows, null_ holding the rows' factor and ``factored`` the DLS of J_e N
  //! decided by its QR (full rank): [J_e N; D N] is J_e N undamped (D empty) or damped by
  //! its lambda (D N = lambda V_r^T), so that DLS solves this call's problem.
  Split solve_over_free(const ConstVectorRef& rows_rhs, const Eigen::Ref<const RowMatrix>& task,
                        const ConstVectorRef& twist, const DampingPolicy& policy,
                        DampedLeastSquares* factored = nullptr);

  // saturation.cpp
  void saturate(const Inputs& in, VectorRef qd);
  //! ``qd`` = sns_qd_ and the report of the saturation that gave it.
  void report_saturation(VectorRef qd);
  void saturate_in_null_space(const Inputs& in);
  double task_scale_limit(const ConstVectorRef& base, const ConstVectorRef& direction,
                          Index& critical) const;
  double gap_to_bound(double bound, double base, double noise) const;
  void saturation_result(const Inputs& in, double task_scale, double rows_scale,
                         Index limiting_joint, const Split& split);
  void scale_rows(const Inputs& in);

  // saturation_walk.cpp: with acceleration limits (docs/design.md section 9.1)
  void saturate_around_previous(const Inputs& in);
  //! Whether the last period left a warm start that this period may take: the previous
  //! command still the one it sent, the equalities alone as the rows (no barrier, no
  //! collision row).
  bool warm_start_applies() const;
  //! The warm start in place of the unsaturated form (docs/design.md 9.1): where the last
  //! period's saturation held joints and was undamped, the rows and the box of this
  //! period built and saturate_from_held taken if it is undamped too; true when accepted.
  bool saturate_before_the_form(const Inputs& in);
  //! The warm start: the last period's held joints held again at the same sides of this
  //! box and the rows-exact damped task solved over the others; true (sns_qd_ and the
  //! walk's figures set) when that point satisfies level 2's end conditions and the
  //! optimum is unique (``J_e N`` of full column rank). ``undamped_only``: not tried
  //! where this period's lambda is positive or walk_optimum_fits_box.
  bool saturate_from_held(const Inputs& in, bool undamped_only);
  //! What held_optimum_on_triangle decided.
  enum class Decided { accepted, refused, undecided };
  //! saturate_from_held's point and its conditions on the QR of J_e N that walk_dls_
  //! holds (docs/design.md 9.1), walk_point_ set when accepted; undecided where that QR
  //! does not decide (the SVD took over, rows of deficient rank, held joints whose rows
  //! of N are dependent beyond the rank cut): the reference's solve decides.
  Decided held_optimum_on_triangle(const Inputs& in);
  //! qd0_ = A^+ b, walk_residual_ = V - J_e qd0_ (task_rows) and task_x_'s first column
  //! y_0 = walk_dls_'s least squares of J_e N y = that residual (null_.dimension() rows).
  void unconstrained_optimum(const Inputs& in);
  //! Whether the walk's unconstrained optimum ``qd_0 + N y`` (``y`` walk_dls_'s least
  //! squares of J_e N y = V - J_e qd_0, the general form's command) fits the box, the rows
  //! of full rank: then the unsaturated form runs first (docs/design.md 9.1).
  bool walk_optimum_fits_box(const Inputs& in);
  //! Whether every free joint of ``point`` is inside the box.
  bool free_in_box(const ConstVectorRef& point) const;
  //! The next period's warm start from this period's saturation around the previous
  //! command and the command ``qd`` sent (none after any other step, a failed one, or
  //! rows that did not hold).
  void remember_held(const ConstVectorRef& qd);
  //! Level 1: walk_point_ moved in the box towards the rows; the fraction of the rows'
  //! starting residual removed (1: they hold).
  double walk_to_rows();
  //! The held joint whose release reduces the rows' residual (-1: none).
  Index wrong_side(const ConstVectorRef& residual);
  //! controllers.optimization.task_damping: the damping rows D of the whole problem in
  //! walk_task_ below the task (their count), walk_damping_, and walk_sigma_min_ unless
  //! walk_dls_ decided undamped by its QR (walk_sigma_deferred_: the report's read
  //! computes it).
  Index task_damping_rows(const Inputs& in);
  //! walk_task_ = [J_e; D] and walk_rhs_ = [V; 0]: their row count.
  Index stack_walk_task(const Inputs& in);
  //! The held joint whose release reduces the damped task's error under the rows (-1:
  //! none). ``null_`` holds the factor of the free joints' rows: solve_over_free's, the
  //! walk having reached its goal over the same free joints.
  Index task_wrong_side(const Eigen::Ref<const RowMatrix>& task, const ConstVectorRef& task_rhs);
  //! The held joint at a bound whose -gradient points into its box most, beyond tolerance.
  Index inward(const ConstVectorRef& gradient, double tolerance) const;
  //! walk_point_ moved towards walk_goal_ until a free joint reaches its bound (that
  //! joint, -1: the goal reached).
  Index walk();
  void walk_result(const Inputs& in, double rows_scale, Index limiting_joint);

  // problem
  Index nq_, nv_, task_rows_;
  DampingPolicy policy_;
  Tolerances tol_;
  bool general_only_;
  std::vector<ConstraintPlan> constraints_;
  std::vector<Index> row_offset_, terms_offset_, equalities_, barriers_;
  Index total_rows_ = 0, terms_size_ = 0;
  JointBox box_;
  double posture_gain_;
  Vector posture_target_, posture_velocity_;

  // the step's state: its report and the lists the report counts
  Report report_;
  std::vector<Index> active_, waiting_, active_pairs_;
  RowMatrix events_;
  Eigen::Matrix<Index, Eigen::Dynamic, 1> saturated_, active_barriers_, saturation_joints_, clip_joints_;

  // workspace, allocated once
  Matrix all_rows_, rows_;     // every constraint's rows; the active ones
  RowMatrix pair_rows_;        // the collision rows (pair_capacity x nv)
  Vector pair_lower_, pair_rhs_;  // their bounds; the bounds held (lowered in a conflict)
  Index pair_count_ = 0;
  Eigen::Matrix<Index, Eigen::Dynamic, 1> active_pair_out_;
  NullSpace null_first_, null_second_;  // the two levels of a conflict
  Matrix second_t_, second_null_t_, second_null_;
  Vector first_qd_, second_x_;
  Vector all_rhs_, rhs_;
  Vector damper_gaps_, damper_gains_;  // per constraint
  Index row_count_ = 0;  // rows of the active set in rows_
  bool rows_ready_ = false;
  NullSpace null_;
  DampedLeastSquares dls_;
  //! the DLS whose sigma_min report_.sigma_min still is (settle_sigma_min); null: none
  DampedLeastSquares* sigma_min_source_ = nullptr;
  //! the events_ row (task_missed) whose sigma_min settle_sigma_min writes; -1: none
  Index sigma_min_event_ = -1;
  Matrix task_t_, task_null_t_, task_null_, task_rhs_, task_x_;  // (J N)^T and its solves
  bool accelerating_ = false;  // acceleration limits on
  Vector previous_;  // the acceleration limits' reference
  Vector previous_change_;  // the jerk limits' reference
  bool jerking_ = false;  // jerk limits on
  Vector qd0_, delta_, lower_, upper_, box_lower_, box_upper_, stacked_, scratch_rows_, rows_scratch_;
  Vector free_x_, posture_null_, rank_weights_;
  Matrix columns_, task_columns_;  // rows and J over the free joints (SNS)
  // SNS
  Eigen::Array<bool, Eigen::Dynamic, 1> free_, best_free_;
  Vector held_, best_held_, base_, direction_, sns_qd_;
  // saturation around the previous command
  Vector walk_point_, walk_goal_, walk_move_, walk_rhs_, walk_residual_, gradient_, reduced_,
      gradient_free_, walk_rows_rhs_;
  Vector walk_reach_;  // walk()'s ratio test per joint, computed once
  RowMatrix walk_task_;  // [J_e; D]
  //! null_ holds walk_to_rows's factor of the rows over every joint (task_damping_rows's)
  bool null_holds_rows_ = false;
  //! the DLS of J_e N that decides D, apart from dls_ so that its sigma_min can wait
  DampedLeastSquares walk_dls_;
  double walk_sigma_min_ = 0.0, walk_damping_ = 0.0;
  bool walk_sigma_deferred_ = false;  // walk_sigma_min_ is walk_dls_'s, computed when read
  double sns_task_scale_ = 1.0, sns_rows_scale_ = 1.0;
  double sns_sigma_min_ = 0.0, sns_damping_ = 0.0;  // of the task's DLS that gave sns_qd_
  bool sns_sigma_deferred_ = false;  // sns_sigma_min_ is walk_dls_'s, computed when read
  Index sns_limiting_ = -1;
  //! the warm start (saturate_from_held): whether the last period left one, its held
  //! joints (-1 at the lower bound, +1 the upper, 0 free) and the joint that limited the task
  bool warm_start_ = false;
  Eigen::Matrix<Index, Eigen::Dynamic, 1> held_side_, held_joints_;
  Index held_limiting_ = -1, held_count_ = 0;
  bool held_undamped_ = false;  // its lambda was 0
  bool warm_tried_ = false;  // this period decided on the warm start already
  Vector held_command_;  // the command sent with them: a previous command written since ends it
  // held_optimum_on_triangle: E_H, N_H^T, M^-1 N_H^T, N_H M^-1 N_H^T (its Cholesky factor in
  // place), w
  Matrix held_unit_, held_null_t_, held_weighted_, held_gram_;
  Vector held_multipliers_;
  bool sns_missed_ = false;
  // analytical
  Eigen::PartialPivLU<Eigen::Matrix<double, 6, 6>> lu_pre_, lu_cjm_;
  Eigen::Matrix<double, 6, 6> square_;
  Matrix pre_jacobian_, joint_map_, task_map_, cjm_, ad_cjm_, basis_qr_, basis_, closest_;
  Eigen::Matrix<double, 6, 1> cjm_rhs_;
  Vector free_with_one_, twist_a_, twist_a_with_one_, basis_tau_, goal_, step_;
  ThinSvd pre_svd_, closest_svd_;
};

}  // namespace cjm
