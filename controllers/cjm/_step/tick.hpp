// The closed loop's hot path in one call (docs/design.md sections 5.1 and 16): for every
// end effector i, on a Pipeline whose q() holds the sensed configuration,
//
//   T*_f,i <- T*_f,i exp6(alpha log6(T*_f,i^-1 T*_i))       target smoothing (alpha = 1: none)
//   V_e,i   = K_p log6(T_e,i^-1 T*_f,i) + Ad_(T_e,i^-1 T*_f,i) log6(T*_f,i,prev^-1 T*_f,i) / dt
//   V_e,i  <- V_e,i min(1, v_max / |v|, w_max / |w|)         the speed caps, direction kept
//   qd      = the CJM step of the pipeline                   (begin(), then finish())
//   q+      = integrate(model, q, qd dt)                     Pinocchio's, any joint kind covered
//
// the same operations as teleop/loop/closed_loop.py's TeleopLoop.advance, the readable
// reference (tests/test_compiled_tick.py holds the two equal). Poses are rows of 12: the
// rotation row-major, then the translation (Kinematics::placements()'s layout).
#pragma once

#include "pipeline.hpp"

namespace cjm {

//! teleop.loop.LoopConfig's numbers, as the tick uses them.
struct TickSettings {
  double dt = 1e-3;           // control period (s)
  double kp = 20.0;           // pose gain (1/s)
  double max_linear = 0.25;   // speed caps (m/s, rad/s)
  double max_angular = 1.5;
  double smoothing = 1.0;     // alpha = 1 - exp(-dt / tau); 1: no smoothing (tau = 0)
  bool feed_forward = true;
};

class Tick {
 public:
  Tick(Index ee_count, TickSettings settings);

  //! The pipeline the next periods run (a controller rebuilds its step when its
  //! constraints change; the filter's state stays here). Throws on another EE count.
  void attach(Pipeline& pipeline);

  //! The operator's targets of this period, one row of 12 per EE (written before begin()).
  RowMatrix& operator_targets() { return operator_targets_; }
  //! The kinematics at the pipeline's q() and the declared constraints' terms and
  //! violations (Pipeline::violations()): what the loop's supervisor measures before the
  //! period's targets are known (docs/design.md 5.2). begin() at the same q() reuses them.
  void sense();
  //! What sense() computed is stale (the constraints' parameters were read anew).
  void forget_sensed() { sensed_ = false; }
  //! Filter, kinematics at the pipeline's q() (unless sense() computed them at this q()),
  //! twists into its twist(), the task rows and declared terms; a constraint that declares
  //! none may then have its terms written before finish().
  void begin();
  //! The step into qd(); false when it is not finite (then no integration either).
  bool finish(bool use_posture, bool analytical_allowed);
  //! ``integrate(model, q, qd dt)`` into next_q().
  void integrate();

  const Vector& qd() const { return qd_; }
  const Vector& next_q() const { return next_q_; }
  //! Per EE: the filtered target, the previous period's (when period_has_previous()), the EE's
  //! placement at q and its commanded twist after the caps (12 + 12 + 12 + 6 entries):
  //! what the loop's measures read.
  const RowMatrix& period() const { return period_; }
  bool period_has_previous() const { return period_has_previous_; }
  //! Whether the speed caps scaled some EE's twist down this period.
  bool twist_saturated() const { return twist_saturated_; }
  //! The filter's state: the filtered targets (when has_filtered()) and the previous
  //! period's (when has_previous()), writable, so that the loop's Python path and this
  //! one hand it over (set_history() says which rows hold poses).
  RowMatrix& filtered() { return filtered_; }
  RowMatrix& previous() { return previous_; }
  bool has_filtered() const { return has_filtered_; }
  bool has_previous() const { return has_previous_; }
  void set_history(bool has_filtered, bool has_previous);
  //! How long finish() took (us): the step, as the loop reports it.
  double step_time_us() const { return step_time_us_; }

 private:
  Index ee_count_;
  TickSettings settings_;
  Pipeline* pipeline_ = nullptr;
  RowMatrix operator_targets_, filtered_, previous_, period_;
  bool has_filtered_ = false, has_previous_ = false, period_has_previous_ = false;
  bool twist_saturated_ = false;
  bool sensed_ = false;  // sense() ran at sensed_q_ and begin() has not used it yet
  unsigned long sensed_count_ = 0;  // the pipeline's kinematics_count() after sense()
  Vector qd_, next_q_, velocity_step_, sensed_q_;
  double step_time_us_ = 0.0;
};

}  // namespace cjm
