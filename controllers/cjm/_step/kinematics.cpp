// Pinocchio's kinematics for the compiled step; see kinematics.hpp.
#include "kinematics.hpp"
#include "pose_row.hpp"

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/multibody.hpp>

#include <cmath>
#include <stdexcept>

namespace cjm {

namespace pin = pinocchio;

struct Kinematics::Pinocchio {
  pin::Model model;
  pin::Data data;
  std::vector<pin::FrameIndex> frames;
  pin::Data::Matrix6x jacobian;
};

namespace {

using Axis = Eigen::Vector3d;
using JointFactory = pin::JointModel (*)(const Axis&);

//! The joint kinds covered, by JointModel.shortname().
const std::vector<std::pair<std::string, JointFactory>>& joint_factories() {
  static const std::vector<std::pair<std::string, JointFactory>> factories = {
      {"JointModelRX", [](const Axis&) -> pin::JointModel { return pin::JointModelRX(); }},
      {"JointModelRY", [](const Axis&) -> pin::JointModel { return pin::JointModelRY(); }},
      {"JointModelRZ", [](const Axis&) -> pin::JointModel { return pin::JointModelRZ(); }},
      {"JointModelRevoluteUnaligned",
       [](const Axis& axis) -> pin::JointModel { return pin::JointModelRevoluteUnaligned(axis); }},
      {"JointModelRUBX", [](const Axis&) -> pin::JointModel { return pin::JointModelRUBX(); }},
      {"JointModelRUBY", [](const Axis&) -> pin::JointModel { return pin::JointModelRUBY(); }},
      {"JointModelRUBZ", [](const Axis&) -> pin::JointModel { return pin::JointModelRUBZ(); }},
      {"JointModelRevoluteUnboundedUnaligned",
       [](const Axis& axis) -> pin::JointModel {
         return pin::JointModelRevoluteUnboundedUnaligned(axis);
       }},
      {"JointModelPX", [](const Axis&) -> pin::JointModel { return pin::JointModelPX(); }},
      {"JointModelPY", [](const Axis&) -> pin::JointModel { return pin::JointModelPY(); }},
      {"JointModelPZ", [](const Axis&) -> pin::JointModel { return pin::JointModelPZ(); }},
      {"JointModelPrismaticUnaligned",
       [](const Axis& axis) -> pin::JointModel { return pin::JointModelPrismaticUnaligned(axis); }},
      {"JointModelPlanar", [](const Axis&) -> pin::JointModel { return pin::JointModelPlanar(); }},
      {"JointModelFreeFlyer", [](const Axis&) -> pin::JointModel { return pin::JointModelFreeFlyer(); }},
      {"JointModelSpherical", [](const Axis&) -> pin::JointModel { return pin::JointModelSpherical(); }},
      {"JointModelTranslation",
       [](const Axis&) -> pin::JointModel { return pin::JointModelTranslation(); }},
  };
  return factories;
}

pin::JointModel joint_model(const JointSpec& joint) {
  const bool unaligned = joint.kind.size() > 9 && joint.kind.substr(joint.kind.size() - 9) == "Unaligned";
  if (unaligned && !(std::abs(joint.axis.norm() - 1.0) <= 1e-9))
    throw std::invalid_argument("the axis of a joint of kind " + joint.kind + " must be a unit vector");
  for (const auto& [kind, factory] : joint_factories())
    if (kind == joint.kind) return factory(joint.axis);
  throw std::invalid_argument("the compiled CJM step does not cover joints of kind " + joint.kind);
}

}  // namespace

Kinematics::Kinematics(const std::vector<JointSpec>& joints, const std::vector<FrameSpec>& frames)
    : pinocchio_(std::make_unique<Pinocchio>()) {
  pin::Model& model = pinocchio_->model;
  for (size_t i = 0; i < joints.size(); ++i) {
    const JointSpec& joint = joints[i];
    if (joint.parent < 0 || joint.parent > static_cast<Index>(i))
      throw std::invalid_argument("a joint's parent must come before it");
    model.addJoint(static_cast<pin::JointIndex>(joint.parent), joint_model(joint),
                   pin::SE3(joint.placement), "joint_" + std::to_string(i + 1));
  }
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameSpec& frame = frames[i];
    if (frame.parent < 0 || frame.parent >= static_cast<Index>(model.njoints))
      throw std::invalid_argument("a frame's parent joint is out of range");
    pinocchio_->frames.push_back(model.addFrame(pin::Frame(
        "frame_" + std::to_string(i), static_cast<pin::JointIndex>(frame.parent),
        pin::SE3(frame.placement), pin::OP_FRAME)));
  }
  pinocchio_->data = pin::Data(model);
  pinocchio_->jacobian = pin::Data::Matrix6x::Zero(6, model.nv);
  jacobians_ = RowMatrix::Zero(6 * static_cast<Index>(frames.size()), model.nv);
  placements_ = RowMatrix::Zero(static_cast<Index>(frames.size()), kPoseRow);
}

std::vector<std::string> joint_kinds() {
  std::vector<std::string> kinds;
  for (const auto& entry : joint_factories()) kinds.push_back(entry.first);
  return kinds;
}

Kinematics::~Kinematics() = default;
Kinematics::Kinematics(Kinematics&&) noexcept = default;

Index Kinematics::nq() const { return pinocchio_->model.nq; }
Index Kinematics::nv() const { return pinocchio_->model.nv; }

Index Kinematics::njoints() const { return pinocchio_->model.njoints; }

const Eigen::Matrix3d& Kinematics::joint_rotation(Index joint) const {
  return pinocchio_->data.oMi[static_cast<size_t>(joint)].rotation();
}

const Eigen::Vector3d& Kinematics::joint_translation(Index joint) const {
  return pinocchio_->data.oMi[static_cast<size_t>(joint)].translation();
}

const Eigen::Matrix<double, 6, Eigen::Dynamic>& Kinematics::world_jacobians() const {
  return pinocchio_->data.J;
}

std::vector<Index> Kinematics::support_columns(Index joint) const {
  const pin::Model& model = pinocchio_->model;
  if (joint < 0 || joint >= model.njoints) throw std::invalid_argument("joint index out of range");
  std::vector<Index> columns;
  for (const pin::JointIndex support : model.supports[static_cast<size_t>(joint)]) {
    if (support == 0) continue;
    for (int v = 0; v < model.nvs[support]; ++v) columns.push_back(model.idx_vs[support] + v);
  }
  return columns;
}

void Kinematics::compute(const ConstVectorRef& q) {
  const pin::Model& model = pinocchio_->model;
  pin::Data& data = pinocchio_->data;
  pin::computeJointJacobians(model, data, q);
  for (size_t i = 0; i < pinocchio_->frames.size(); ++i) {
    const pin::FrameIndex frame = pinocchio_->frames[i];
    const pin::SE3& placement = pin::updateFramePlacement(model, data, frame);
    pinocchio_->jacobian.setZero();  // getFrameJacobian writes the supporting columns only
    pin::getFrameJacobian(model, data, frame, pin::LOCAL, pinocchio_->jacobian);
    jacobians_.middleRows(6 * static_cast<Index>(i), 6) = pinocchio_->jacobian;
    write_pose_row(placement.rotation(), placement.translation(),
                   placements_.row(static_cast<Index>(i)).data());
  }
}

void Kinematics::integrate(const ConstVectorRef& q, const ConstVectorRef& v,
                           VectorRef result) const {
  pin::integrate(pinocchio_->model, q, v, result);
}

}  // namespace cjm
