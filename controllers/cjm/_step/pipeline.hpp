// One CJM step from q (docs/design.md section 16): Pinocchio's kinematics
// (kinematics.hpp), the terms of the constraints with an affine form, the task weighting,
// then the dense step (step.hpp), on buffers allocated once.
//
// A step from Python is one call when every constraint has an affine form
// (Constraint.affine_anchor, a hole); otherwise Python writes the other constraints'
// terms from the placements between prepare() and finish().
#pragma once

#include <vector>

#include "kinematics.hpp"
#include "step.hpp"

namespace cjm {

//! A constraint's terms as ``offset + of_x x + of_f f + K (offset_per_gain +
//! of_x_per_gain x)`` with ``x = R^T (point - t)`` and ``f = R^T velocity`` in its link's
//! frame and ``K`` its gain (controllers.cjm.analytical.AffineTerms).
struct AffineTerms {
  RowMatrix of_x, of_f, of_x_per_gain;  // terms_size x 3
  Vector offset, offset_per_gain;
};

class Pipeline {
 public:
  //! ``kinematics`` holds the EE frames first, then one frame per constraint.
  //! ``task_entries``/``task_scale``: the entries of the stacked twist the task keeps and
  //! their ``W^1/2`` (all entries with scale 1 when unweighted).
  Pipeline(Kinematics kinematics, Step step, Index ee_count, std::vector<Index> task_entries,
           Vector task_scale);

  //! Constraint ``index``'s affine map; without one, Python writes its terms.
  void set_affine(Index index, AffineTerms terms);

  //! The kinematics at q(), the task rows and the affine terms: compute_kinematics(),
  //! then prepare_terms().
  void prepare();
  //! The kinematics at q(): the frames' placements and Jacobians.
  void compute_kinematics();
  //! The task rows and the affine terms, after compute_kinematics() (and twist() set).
  void prepare_terms();
  //! The step into ``qd``, after prepare() (and Python's terms).
  void finish(bool use_posture, bool analytical_allowed, VectorRef qd);

  Index nv() const { return kinematics_.nv(); }
  Vector& q() { return q_; }
  Vector& twist() { return twist_; }
  Vector& terms() { return terms_; }
  Vector& posture() { return posture_; }
  //! Per constraint: its world anchor point, then its world velocity (affine ones only).
  RowMatrix& anchors() { return anchors_; }
  //! Per constraint: its drift-feedback gain (affine ones only; with the anchors, read
  //! from the constraint before every step by the bindings).
  Vector& gains() { return gains_; }
  const RowMatrix& placements() const { return kinematics_.placements(); }
  const RowMatrix& jacobians() const { return kinematics_.jacobians(); }
  Step& step() { return step_; }
  const Kinematics& kinematics() const { return kinematics_; }

 private:
  Kinematics kinematics_;
  Step step_;
  Index ee_count_;
  std::vector<Index> task_entries_;
  Vector task_scale_;
  std::vector<Index> terms_size_;  // per constraint (its buffer starts at step_.terms_offset)
  std::vector<bool> has_affine_;
  std::vector<AffineTerms> affine_;
  Vector q_, twist_, task_twist_, terms_, posture_, gains_;
  RowMatrix ee_jacobian_, anchors_;
  Eigen::Vector3d x_, f_;
};

}  // namespace cjm
