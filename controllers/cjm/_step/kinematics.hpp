// Pinocchio's kinematics for the compiled CJM step (docs/design.md section 16): the
// joint Jacobians, then the placement and LOCAL Jacobian of the frames the step reads.
//
// Pinocchio's templates are compiled into the extension from its headers; no Pinocchio
// library is linked, so the extension does not depend on the binary interface of the
// installed ``pin`` wheel. The model is copied from Python's pin.Model (its joints and
// the frames used); tests/test_compiled_kinematics.py holds the two equal.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "dense.hpp"

namespace cjm {

//! One joint of pin.Model (the universe excluded), as controllers/cjm/compiled.py reads it.
struct JointSpec {
  std::string kind;          // JointModel.shortname(), e.g. "JointModelRZ"
  Index parent = 0;          // model.parents
  Eigen::Matrix4d placement;  // model.jointPlacements (homogeneous), in the parent's frame
  Eigen::Vector3d axis;      // the axis of an unaligned revolute or prismatic joint
};

//! A frame: its parent joint and its placement in that joint's frame.
struct FrameSpec {
  Index parent = 0;
  Eigen::Matrix4d placement;
};

//! The JointModel kinds (shortname()) Kinematics covers.
std::vector<std::string> joint_kinds();

class Kinematics {
 public:
  //! Throws std::invalid_argument naming a joint kind it does not cover.
  Kinematics(const std::vector<JointSpec>& joints, const std::vector<FrameSpec>& frames);
  ~Kinematics();
  Kinematics(Kinematics&&) noexcept;

  Index nq() const;
  Index nv() const;

  //! ``computeJointJacobians`` at ``q``, then every frame's placement and LOCAL Jacobian.
  void compute(const ConstVectorRef& q);

  //! Pinocchio's ``integrate(model, q, v)`` into ``result`` (nq != nv for a base).
  void integrate(const ConstVectorRef& q, const ConstVectorRef& v, VectorRef result) const;

  //! The frames' LOCAL Jacobians stacked in the order given (6 per frame, nv columns).
  const RowMatrix& jacobians() const { return jacobians_; }
  //! One row per frame: its rotation (row-major) then its translation, world frame.
  const RowMatrix& placements() const { return placements_; }

  //! The joints of the model, the universe (0) included.
  Index njoints() const;
  //! Joint ``joint``'s world placement (Pinocchio's data.oMi), after compute().
  const Eigen::Matrix3d& joint_rotation(Index joint) const;
  const Eigen::Vector3d& joint_translation(Index joint) const;
  //! Every joint's column of the WORLD-frame Jacobian (Pinocchio's data.J: the velocity
  //! of the point at the world origin, then the angular velocity), after compute().
  const Eigen::Matrix<double, 6, Eigen::Dynamic>& world_jacobians() const;
  //! The velocity columns joint ``joint``'s motion depends on (its supporting joints').
  std::vector<Index> support_columns(Index joint) const;

 private:
  struct Pinocchio;  // pinocchio::Model, Data and a Jacobian buffer: kinematics.cpp only
  std::unique_ptr<Pinocchio> pinocchio_;
  RowMatrix jacobians_, placements_;
};

}  // namespace cjm
