// One CJM step from q (docs/design.md section 16): Pinocchio's kinematics
// (kinematics.hpp), the task weighting, each constraint's terms from what it declares
// (terms.hpp), then the dense step (step.hpp), on buffers allocated once.
//
// A step from Python is one call when every constraint declares a compiled form
// (controllers/cjm/compiled_forms.py: holes, planes, barriers, point locks); a constraint type
// that declares none has its terms written by Python from the placements between
// prepare() and finish().
#pragma once

#include <memory>
#include <vector>

#include "collision.hpp"
#include "kinematics.hpp"
#include "step.hpp"
#include "terms.hpp"

namespace cjm {

class Pipeline {
 public:
  //! ``kinematics`` holds the EE frames first, then one frame per constraint.
  //! ``task_entries``/``task_scale``: the entries of the stacked twist the task keeps and
  //! their ``W^1/2`` (all entries with scale 1 when unweighted).
  Pipeline(Kinematics kinematics, Step step, Index ee_count, std::vector<Index> task_entries,
           Vector task_scale);

  //! Constraint ``index`` declares terms of ``kind`` (its parameters: parameters(index));
  //! ``paper``: a hole's structure matrix in the paper's parametrisation where |p| >=
  //! ``paper_min_a``. Without a declared kind, Python writes the constraint's terms.
  void set_form(Index index, TermsKind kind, bool paper, double paper_min_a);
  //! Constraint ``index``'s declared kind (set_form first).
  TermsKind kind(Index index) const { return forms_[index].kind; }
  //! Where the declared parameters of constraint ``index`` are copied (load_parameters).
  Parameters& parameters(Index index) { return forms_[index].parameters; }

  //! The kinematics at q(), then the task rows and the declared terms.
  void prepare();
  //! Pinocchio's kinematics at q(): placements() and jacobians().
  void compute_kinematics();
  //! How many times compute_kinematics() ran: what a caller that keeps its results
  //! between calls compares (Tick::sense()).
  unsigned long kinematics_count() const { return kinematics_count_; }
  //! The weighted task rows and every declared constraint's terms, after the kinematics.
  void compute_terms() {
    compute_task_rows();
    compute_constraint_terms();
  }
  //! The weighted task rows from twist(), after the kinematics.
  void compute_task_rows();
  //! Every declared constraint's terms and violation(), after the kinematics (they do
  //! not depend on the twist).
  void compute_constraint_terms();
  //! Each declared constraint's violation at the last kinematics (m):
  //! constraints.base.Constraint.violation, ``|e|`` for an equality, the penetration
  //! ``max(0, -e)`` for an inequality (constraints.barrier.Barrier.violation); NaN for a
  //! constraint whose terms Python writes.
  const Vector& violations() const { return violations_; }
  //! The step into ``qd``, after prepare() (and Python's terms); the analytical form only
  //! when ``analytical_allowed`` and paper_form().
  void finish(bool use_posture, bool analytical_allowed, VectorRef qd);
  //! False when the last prepare() found the paper's form undefined (null-space terms
  //! written instead: the analytical form does not run, as in the Python step).
  bool paper_form() const { return paper_form_; }

  Index nv() const { return kinematics_.nv(); }
  Vector& q() { return q_; }
  Vector& twist() { return twist_; }
  Vector& terms() { return terms_; }
  Vector& posture() { return posture_; }
  const RowMatrix& placements() const { return kinematics_.placements(); }
  const RowMatrix& jacobians() const { return kinematics_.jacobians(); }
  Step& step() { return step_; }
  const Kinematics& kinematics() const { return kinematics_; }

  //! The collision rows prepare() writes into the step's pair buffer after the
  //! kinematics (docs/design.md section 18.4); none: Python writes them, if any.
  void set_collisions(std::unique_ptr<Collisions> collisions);
  Collisions* collisions() { return collisions_.get(); }

 private:
  Kinematics kinematics_;
  Step step_;
  Index ee_count_;
  std::vector<Index> task_entries_;
  Vector task_scale_;
  std::vector<Index> terms_size_;  // per constraint (its buffer starts at step_.terms_offset)
  struct Form {
    bool declared = false;
    TermsKind kind = TermsKind::hole;
    bool paper = false;
    double paper_min_a = 0.0;
    Parameters parameters = Parameters::Zero();
  };
  std::vector<Form> forms_;
  bool paper_form_ = true;
  unsigned long kinematics_count_ = 0;
  Vector q_, twist_, task_twist_, terms_, posture_, violations_;
  RowMatrix ee_jacobian_;
  std::unique_ptr<Collisions> collisions_;
};

}  // namespace cjm
