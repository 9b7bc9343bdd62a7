// One CJM step from q; see pipeline.hpp.
#include "pipeline.hpp"
#include "terms_layout.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

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
  forms_.resize(n_constraints);
  const Index nv = kinematics_.nv();
  q_ = Vector::Zero(kinematics_.nq());
  twist_ = Vector::Zero(6 * ee_count_);
  task_twist_ = Vector::Zero(static_cast<Index>(task_entries_.size()));
  terms_ = Vector::Zero(step_.terms_size());
  posture_ = Vector::Zero(nv);
  violations_ = Vector::Constant(n_constraints, std::numeric_limits<double>::quiet_NaN());
  ee_jacobian_ = RowMatrix::Zero(task_twist_.size(), nv);
}

void Pipeline::set_form(Index index, TermsKind kind, bool paper, double paper_min_a) {
  if (index < 0 || index >= static_cast<Index>(forms_.size()))
    throw std::invalid_argument("constraint index out of range");
  if (terms_size_[index] != terms_size(kind_rows(kind)))
    throw std::invalid_argument(std::string("a ") + kind_name(kind) + " has " +
                                std::to_string(kind_rows(kind)) +
                                " rows: the step was built with another number");
  if (paper && kind != TermsKind::hole)
    throw std::invalid_argument("the paper's parametrisation is compiled for a hole only");
  Form& form = forms_[index];
  form.declared = true;
  form.kind = kind;
  form.paper = paper;
  form.paper_min_a = paper_min_a;
}

void Pipeline::set_collisions(std::unique_ptr<Collisions> collisions) {
  if (collisions && collisions->pair_count() > step_.pair_capacity())
    throw std::invalid_argument("more collision pairs than the step's pair capacity");
  collisions_ = std::move(collisions);
}

void Pipeline::prepare() {
  compute_kinematics();
  compute_terms();
}

void Pipeline::compute_kinematics() {
  ++kinematics_count_;
  kinematics_.compute(q_);
  if (collisions_) collisions_->write_rows(kinematics_, step_);
}

void Pipeline::compute_task_rows() {
  const RowMatrix& jacobians = kinematics_.jacobians();
  for (Index r = 0; r < task_twist_.size(); ++r) {
    task_twist_(r) = task_scale_(r) * twist_(task_entries_[r]);
    ee_jacobian_.row(r) = task_scale_(r) * jacobians.row(task_entries_[r]);
  }
}

void Pipeline::compute_constraint_terms() {
  const RowMatrix& placements = kinematics_.placements();
  paper_form_ = true;
  for (Index i = 0; i < static_cast<Index>(forms_.size()); ++i) {
    const Form& form = forms_[i];
    if (!form.declared) continue;
    const double* placement = placements.row(ee_count_ + i).data();
    const Rotation rotation = row_rotation(placement);
    const Translation translation = row_translation(placement);
    double& gap = step_.damper_gaps()(i);
    double error_norm = 0.0;
    paper_form_ &= write_terms(form.kind, form.parameters, rotation, translation, form.paper,
                               form.paper_min_a, terms_.data() + step_.terms_offset(i), gap,
                               error_norm);
    violations_(i) = step_.equality(i) ? error_norm : std::max(0.0, -gap);
    step_.damper_gains()(i) = declared_gain(form.kind, form.parameters);
  }
}

void Pipeline::finish(bool use_posture, bool analytical_allowed, VectorRef qd) {
  const Index frames_start = 6 * ee_count_;
  const RowMatrix& jacobians = kinematics_.jacobians();
  step_.solve(q_, task_twist_, ee_jacobian_,
              jacobians.bottomRows(jacobians.rows() - frames_start), terms_, posture_,
              use_posture, analytical_allowed && paper_form_, qd);
}

}  // namespace cjm
