// One CJM step from q; see pipeline.hpp.
#include "pipeline.hpp"

#include <stdexcept>

namespace cjm {

Pipeline::Pipeline(Kinematics kinematics, Step step, Index ee_count,
                   std::vector<Index> task_entries, Vector task_scale)
    : kinematics_(std::move(kinematics)), step_(std::move(step)), ee_count_(ee_count),
      task_entries_(std::move(task_entries)), task_scale_(std::move(task_scale)) {
  const Index n_constraints = step_.constraint_count();
  if (kinematics_.jacobians().rows() != 6 * (ee_count_ + n_constraints))
    throw std::invalid_argument("the kinematics needs one frame per EE and per constraint");
  if (static_cast<Index>(task_entries_.size()) != task_scale_.size() || task_entries_.empty())
    throw std::invalid_argument("one scale per task entry, at least one entry");
  if (step_.nq() != kinematics_.nq() || step_.nv() != kinematics_.nv() ||
      step_.task_rows() != static_cast<Index>(task_entries_.size()))
    throw std::invalid_argument("the step was built for another model or task");
  for (Index entry : task_entries_)
    if (entry < 0 || entry >= 6 * ee_count_) throw std::invalid_argument("task entry out of range");
  for (Index i = 0; i < n_constraints; ++i)
    terms_size_.push_back((i + 1 < n_constraints ? step_.terms_offset(i + 1) : step_.terms_size()) -
                          step_.terms_offset(i));
  has_affine_.assign(n_constraints, false);
  affine_.resize(n_constraints);
  const Index nv = kinematics_.nv();
  q_ = Vector::Zero(kinematics_.nq());
  twist_ = Vector::Zero(6 * ee_count_);
  task_twist_ = Vector::Zero(static_cast<Index>(task_entries_.size()));
  terms_ = Vector::Zero(step_.terms_size());
  posture_ = Vector::Zero(nv);
  ee_jacobian_ = RowMatrix::Zero(task_twist_.size(), nv);
  anchors_ = RowMatrix::Zero(n_constraints, 6);
  gains_ = Vector::Zero(n_constraints);
}

void Pipeline::set_affine(Index index, AffineTerms terms) {
  if (index < 0 || index >= static_cast<Index>(affine_.size()))
    throw std::invalid_argument("constraint index out of range");
  const Index size = terms_size_[index];
  if (terms.of_x.rows() != size || terms.of_x.cols() != 3 || terms.of_f.rows() != size ||
      terms.of_f.cols() != 3 || terms.offset.size() != size ||
      terms.of_x_per_gain.rows() != size || terms.of_x_per_gain.cols() != 3 ||
      terms.offset_per_gain.size() != size)
    throw std::invalid_argument("affine terms of the wrong size");
  affine_[index] = std::move(terms);
  has_affine_[index] = true;
}

void Pipeline::prepare() {
  compute_kinematics();
  prepare_terms();
}

void Pipeline::compute_kinematics() { kinematics_.compute(q_); }

void Pipeline::prepare_terms() {
  const RowMatrix& jacobians = kinematics_.jacobians();
  for (Index r = 0; r < task_twist_.size(); ++r) {
    task_twist_(r) = task_scale_(r) * twist_(task_entries_[r]);
    ee_jacobian_.row(r) = task_scale_(r) * jacobians.row(task_entries_[r]);
  }
  const RowMatrix& placements = kinematics_.placements();
  for (Index i = 0; i < static_cast<Index>(affine_.size()); ++i) {
    if (!has_affine_[i]) continue;
    const auto placement = placements.row(ee_count_ + i);
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> rotation(placement.data());
    x_.noalias() = rotation.transpose() * (anchors_.row(i).head<3>().transpose() -
                                           placement.tail<3>().transpose());
    auto terms = terms_.segment(step_.terms_offset(i), terms_size_[i]);
    const AffineTerms& affine = affine_[i];
    terms.noalias() = affine.of_x * x_;
    terms += affine.offset;
    const double gain = gains_(i);
    if (gain != 0.0) {
      terms.noalias() += gain * (affine.of_x_per_gain * x_);
      terms += gain * affine.offset_per_gain;
    }
    const auto velocity = anchors_.row(i).tail<3>();
    if ((velocity.array() != 0.0).any()) {  // a moving anchor (AffineTerms.write's f)
      f_.noalias() = rotation.transpose() * velocity.transpose();
      terms.noalias() += affine.of_f * f_;
    }
  }
}

void Pipeline::finish(bool use_posture, bool analytical_allowed, VectorRef qd) {
  const Index frames_start = 6 * ee_count_;
  const RowMatrix& jacobians = kinematics_.jacobians();
  step_.solve(q_, task_twist_, ee_jacobian_,
              jacobians.bottomRows(jacobians.rows() - frames_start), terms_, posture_,
              use_posture, analytical_allowed, qd);
}

}  // namespace cjm
