// The closed loop's hot path in one call; see tick.hpp.
#include "tick.hpp"

#include "pose_row.hpp"

#include <pinocchio/spatial.hpp>

#include <chrono>
#include <cmath>
#include <stdexcept>

namespace cjm {

namespace pin = pinocchio;

namespace {

using Twist = Eigen::Matrix<double, 6, 1>;

//! The pose in a pose row (pose_row.hpp).
template <typename Row>
pin::SE3 pose_of(const Row& row) {
  return pin::SE3(Eigen::Matrix3d(row_rotation(row.data())), row_translation(row.data()));
}

//! ``pose`` into a pose row.
template <typename Row>
void write_pose(const pin::SE3& pose, Row&& row) {
  write_pose_row(pose.rotation(), pose.translation(), row.data());
}

//! teleop.loop.saturate_twist: ``twist`` scaled uniformly so that ``|v| <= max_linear``
//! and ``|w| <= max_angular``, with its tests in the same order (a NaN leaves it as it is,
//! for the step to refuse); true when it was scaled.
bool saturate(Twist& twist, double max_linear, double max_angular) {
  const double linear2 = twist.head<3>().squaredNorm(), angular2 = twist.tail<3>().squaredNorm();
  if (linear2 < 0.999 * max_linear * max_linear && angular2 < 0.999 * max_angular * max_angular)
    return false;
  const double linear = std::sqrt(linear2), angular = std::sqrt(angular2);
  // Python's min(1.0, a, b) and max(x, 1e-300): the first argument unless another is
  // strictly smaller (larger), so a NaN never wins
  double scale = 1.0;
  const double by_linear = max_linear / (1e-300 > linear ? 1e-300 : linear);
  if (by_linear < scale) scale = by_linear;
  const double by_angular = max_angular / (1e-300 > angular ? 1e-300 : angular);
  if (by_angular < scale) scale = by_angular;
  if (scale == 1.0) return false;
  twist *= scale;
  return true;
}

}  // namespace

Tick::Tick(Index ee_count, TickSettings settings) : ee_count_(ee_count), settings_(settings) {
  if (ee_count_ < 1) throw std::invalid_argument("a tick needs at least one end effector");
  if (!(settings_.dt > 0.0) || !(settings_.smoothing > 0.0 && settings_.smoothing <= 1.0))
    throw std::invalid_argument("a tick needs dt > 0 and a smoothing in (0, 1]");
  operator_targets_ = RowMatrix::Zero(ee_count_, kPoseRow);
  filtered_ = RowMatrix::Zero(ee_count_, kPoseRow);
  previous_ = RowMatrix::Zero(ee_count_, kPoseRow);
  period_ = RowMatrix::Zero(ee_count_, kPeriodRow);
}

void Tick::attach(Pipeline& pipeline) {
  if (pipeline.twist().size() != 6 * ee_count_)
    throw std::invalid_argument("the pipeline was built for another number of end effectors");
  pipeline_ = &pipeline;
  qd_ = Vector::Zero(pipeline.nv());
  next_q_ = Vector::Zero(pipeline.q().size());
  velocity_step_ = Vector::Zero(pipeline.nv());
  sensed_q_ = Vector::Zero(pipeline.q().size());
  sensed_ = false;
}

void Tick::sense() {
  if (pipeline_ == nullptr) throw std::logic_error("the tick has no pipeline attached");
  pipeline_->compute_kinematics();
  pipeline_->compute_constraint_terms();
  sensed_q_ = pipeline_->q();
  sensed_count_ = pipeline_->kinematics_count();
  sensed_ = true;
}

void Tick::set_history(bool has_filtered, bool has_previous) {
  has_filtered_ = has_filtered;
  has_previous_ = has_previous;
}

void Tick::begin() {
  if (pipeline_ == nullptr) throw std::logic_error("the tick has no pipeline attached");
  Pipeline& pipeline = *pipeline_;
  // the filter: the operator's target itself on the first period or without smoothing
  const bool smooth = has_filtered_ && settings_.smoothing != 1.0;
  for (Index i = 0; i < ee_count_; ++i) {
    if (smooth) {
      const pin::SE3 filtered = pose_of(filtered_.row(i));
      const pin::SE3 target = pose_of(operator_targets_.row(i));
      write_pose(filtered * pin::exp6(pin::log6(filtered.actInv(target)) * settings_.smoothing),
                 filtered_.row(i));
    } else {
      filtered_.row(i) = operator_targets_.row(i);
    }
  }
  has_filtered_ = true;
  period_has_previous_ = has_previous_;
  const bool sensed = sensed_ && pipeline.kinematics_count() == sensed_count_ &&
                      pipeline.q() == sensed_q_;
  sensed_ = false;
  if (!sensed) pipeline.compute_kinematics();
  const RowMatrix& placements = pipeline.placements();
  Vector& twist = pipeline.twist();
  twist_saturated_ = false;
  for (Index i = 0; i < ee_count_; ++i) {
    const pin::SE3 ee = pose_of(placements.row(i));
    const pin::SE3 target = pose_of(filtered_.row(i));
    const pin::SE3 error = ee.actInv(target);
    Twist command = settings_.kp * pin::log6(error).toVector();
    if (settings_.feed_forward && has_previous_) {
      const Twist target_twist = pin::log6(pose_of(previous_.row(i)).actInv(target)).toVector() /
                                 settings_.dt;
      command += error.toActionMatrix() * target_twist;
    }
    twist_saturated_ |= saturate(command, settings_.max_linear, settings_.max_angular);
    twist.segment<6>(6 * i) = command;
    auto period = period_.row(i);
    period.segment<kPoseRow>(kPeriodTarget) = filtered_.row(i);
    period.segment<kPoseRow>(kPeriodPrevious) = previous_.row(i);  // read when period_has_previous()
    period.segment<kPoseRow>(kPeriodPlacement) = placements.row(i);
    period.segment<6>(kPeriodTwist) = command.transpose();
  }
  previous_ = filtered_;
  has_previous_ = true;
  pipeline.compute_task_rows();
  if (!sensed) pipeline.compute_constraint_terms();
}

bool Tick::finish(bool use_posture, bool analytical_allowed) {
  const auto start = std::chrono::steady_clock::now();
  pipeline_->finish(use_posture, analytical_allowed, qd_);
  step_time_us_ = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start)
                      .count();
  return qd_.allFinite();
}

void Tick::integrate() {
  velocity_step_.noalias() = qd_ * settings_.dt;
  pipeline_->kinematics().integrate(pipeline_->q(), velocity_step_, next_q_);
}

}  // namespace cjm
