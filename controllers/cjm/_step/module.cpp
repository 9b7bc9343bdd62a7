// Python bindings of the compiled CJM step (pybind11): controllers.cjm._step.Step.
// controllers/cjm/compiled.py is its only user (docs/design.md section 16).
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "step.hpp"

namespace py = pybind11;
using cjm::Index;

namespace {

//! A NumPy view of storage owned by ``owner`` (kept alive by the view).
template <typename Scalar>
py::array_t<Scalar> view(Scalar* data, std::vector<py::ssize_t> shape, py::handle owner) {
  std::vector<py::ssize_t> strides(shape.size(), sizeof(Scalar));
  for (size_t i = shape.size(); i-- > 1;) strides[i - 1] = strides[i] * shape[i];
  return py::array_t<Scalar>(shape, strides, data, owner);
}

}  // namespace

PYBIND11_MODULE(_step, module) {
  module.doc() = "The compiled CJM step (docs/design.md section 16).";

  py::class_<cjm::ConstraintPlan>(module, "ConstraintPlan")
      .def(py::init([](Index rows, bool equality, bool analytical, std::vector<Index> pre,
                       std::vector<Index> post) {
             return cjm::ConstraintPlan{rows, equality, analytical, std::move(pre), std::move(post)};
           }),
           py::arg("rows"), py::arg("equality"), py::arg("analytical"), py::arg("pre"),
           py::arg("post"));

  py::class_<cjm::JointBox>(module, "JointBox")
      .def(py::init([](cjm::Vector velocity_lower, cjm::Vector velocity_upper,
                       cjm::Vector velocity_limit, std::vector<Index> limited_q,
                       std::vector<Index> limited_v, cjm::Vector q_min, cjm::Vector q_max,
                       double position_gain, bool position_limits, cjm::RowMatrix box_test) {
             return cjm::JointBox{std::move(velocity_lower), std::move(velocity_upper),
                                  std::move(velocity_limit), std::move(limited_q),
                                  std::move(limited_v), std::move(q_min), std::move(q_max),
                                  position_gain, position_limits, std::move(box_test)};
           }),
           py::arg("velocity_lower"), py::arg("velocity_upper"), py::arg("velocity_limit"),
           py::arg("limited_q"), py::arg("limited_v"), py::arg("q_min"), py::arg("q_max"),
           py::arg("position_gain"), py::arg("position_limits"), py::arg("box_test"));

  py::class_<cjm::Step>(module, "Step")
      .def(py::init([](Index nq, Index nv, Index task_rows, double damping, double threshold,
                       double max_damping, bool general_only,
                       std::vector<cjm::ConstraintPlan> constraints, cjm::JointBox box,
                       double posture_gain, cjm::Vector posture_target) {
             return new cjm::Step(nq, nv, task_rows, cjm::DampingPolicy{damping, threshold, max_damping},
                                  general_only, std::move(constraints), std::move(box),
                                  posture_gain, std::move(posture_target));
           }),
           py::arg("nq"), py::arg("nv"), py::arg("task_rows"), py::arg("damping"),
           py::arg("threshold"), py::arg("max_damping"), py::arg("general_only"),
           py::arg("constraints"), py::arg("box"), py::arg("posture_gain"),
           py::arg("posture_target"))
      .def("set_policy", [](cjm::Step& step, double damping, double threshold, double max_damping) {
             step.set_policy(cjm::DampingPolicy{damping, threshold, max_damping});
           }, py::arg("damping"), py::arg("threshold"), py::arg("max_damping"))
      .def("solve", &cjm::Step::solve, py::arg("q"), py::arg("twist"), py::arg("ee_jacobian"),
           py::arg("frame_jacobians"), py::arg("terms"), py::arg("posture"),
           py::arg("use_posture"), py::arg("analytical_allowed"), py::arg("qd").noconvert(),
           py::call_guard<py::gil_scoped_release>(),
           "One step into ``qd``; read report, events and the joint lists afterwards.")
      .def_property_readonly("terms_size", &cjm::Step::terms_size)
      .def_property_readonly("report", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.report().data(), {step.report().size()}, self);
      })
      .def_property_readonly("events", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.events().data(), {step.events().rows(), step.events().cols()}, self);
      })
      .def_property_readonly("saturated_joints", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.saturated_joints().data(), {step.saturated_joints().size()}, self);
      })
      .def_property_readonly("active_barriers", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.active_barriers().data(), {step.active_barriers().size()}, self);
      })
      .def_property_readonly("saturation_joints", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.saturation_joints().data(), {step.saturation_joints().size()}, self);
      });

  py::dict fields;
  fields["status"] = static_cast<int>(cjm::kStatus);
  fields["method"] = static_cast<int>(cjm::kMethod);
  fields["sigma_min"] = static_cast<int>(cjm::kSigmaMin);
  fields["damping"] = static_cast<int>(cjm::kDamping);
  fields["scale"] = static_cast<int>(cjm::kScale);
  fields["equality_residual"] = static_cast<int>(cjm::kEqualityResidual);
  fields["saturated_count"] = static_cast<int>(cjm::kSaturatedCount);
  fields["active_barrier_count"] = static_cast<int>(cjm::kActiveBarrierCount);
  fields["event_count"] = static_cast<int>(cjm::kEventCount);
  fields["saturation_joint_count"] = static_cast<int>(cjm::kSaturationJointCount);
  module.attr("REPORT_FIELDS") = fields;

  py::dict events;
  events["pre_chain_singular"] = static_cast<int>(cjm::Event::pre_chain_singular);
  events["task_residual"] = static_cast<int>(cjm::Event::task_residual);
  events["conflict"] = static_cast<int>(cjm::Event::conflict);
  events["no_free_joint"] = static_cast<int>(cjm::Event::no_free_joint);
  events["rows_scaled"] = static_cast<int>(cjm::Event::rows_scaled);
  events["task_missed"] = static_cast<int>(cjm::Event::task_missed);
  events["task_scaled"] = static_cast<int>(cjm::Event::task_scaled);
  events["clipped"] = static_cast<int>(cjm::Event::clipped);
  events["residual"] = static_cast<int>(cjm::Event::residual);
  events["no_convergence"] = static_cast<int>(cjm::Event::no_convergence);
  events["non_finite"] = static_cast<int>(cjm::Event::non_finite);
  module.attr("EVENTS") = events;
}
