// Python bindings of the compiled CJM step (pybind11): controllers.cjm._step's Pipeline
// (kinematics, terms and step in one call) and the Step it runs, and the closed loop's
// Tick around a Pipeline. controllers/cjm/compiled.py and compiled_tick.py are their only
// users (docs/design.md sections 5.1 and 16).
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cstdint>

#include "collision_bindings.hpp"
#include "damped.hpp"
#include "pipeline.hpp"
#include "pose_row.hpp"
#include "report_bindings.hpp"
#include "tick.hpp"

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

//! A read-only NumPy view of ``matrix``, owned by ``owner``.
py::array_t<double> read_only(const cjm::RowMatrix& matrix, py::handle owner) {
  auto array = view(const_cast<double*>(matrix.data()), {matrix.rows(), matrix.cols()}, owner);
  array.attr("flags").attr("writeable") = false;
  return array;
}

//! Copies a 1-D float64 array of ``size`` finite entries into ``target``; false for
//! anything else (Python then says what is wrong, as Controller.solve does).
bool load_vector(py::handle source, cjm::Vector& target) {
  if (!py::isinstance<py::array_t<double>>(source)) return false;
  const auto array = py::reinterpret_borrow<py::array_t<double>>(source);
  if (array.ndim() != 1 || array.shape(0) != target.size()) return false;
  const auto entries = array.unchecked<1>();
  for (py::ssize_t i = 0; i < entries.shape(0); ++i) target(i) = entries(i);
  return target.allFinite();
}

//! A Pipeline that also holds the constraints with a compiled form
//! (controllers/cjm/compiled_forms.py: a kind and a function giving a float64 array of
//! parameters from the constraint's fields). Before every step it reads each one's
//! ``revision`` attribute (replaced by every assignment to the constraint,
//! constraints/revision.py) and takes the parameters again only when that object
//! changed: the constraints' data read each step, with no Python loop and no method call
//! while they stay as they are (docs/design.md section 16).
struct BoundPipeline : cjm::Pipeline {
  using cjm::Pipeline::Pipeline;

  struct Source {
    Index index;
    double unit_tolerance;  // of a declared axis or normal
    py::object constraint, values;  // the constraint and its form's parameters function
    py::object revision;            // the constraint's revision when last taken
  };
  std::vector<Source> sources;
  py::str revision_name{"revision"};

  //! Constraint ``index`` computes its terms here: terms of ``kind``, parameters
  //! ``values(constraint)``.
  void declare(Index index, py::object constraint, const std::string& kind, py::object values,
               bool paper, double paper_min_a, double unit_tolerance) {
    set_form(index, cjm::terms_kind(kind), paper, paper_min_a);
    Source source{index, unit_tolerance, std::move(constraint), std::move(values), py::none()};
    load(source, source.constraint.attr(revision_name));
    sources.push_back(std::move(source));
  }

  //! Copies the parameters of ``source`` at ``revision`` in after checking them
  //! (ValueError naming the field).
  void load(Source& source, py::object revision) {
    const char* kind = cjm::kind_name(this->kind(source.index));
    const py::object parameters = source.values(source.constraint);
    if (!py::isinstance<py::array_t<double>>(parameters))
      throw std::invalid_argument(std::string(kind) +
                                  " compiled parameters must be a float64 array");
    const auto array = py::reinterpret_borrow<py::array_t<double>>(parameters);
    if (array.ndim() != 1)
      throw std::invalid_argument(std::string(kind) + " compiled parameters must be 1-D");
    const auto entries = array.unchecked<1>();
    const Index size = entries.shape(0);
    double values[cjm::kMaxParameters];
    for (Index i = 0; i < std::min(size, cjm::kMaxParameters); ++i) values[i] = entries(i);
    cjm::load_parameters(this->kind(source.index), values, size, source.unit_tolerance,
                         this->parameters(source.index));
    source.revision = std::move(revision);
  }

  //! Each declared constraint's parameters, taken again when its revision was replaced
  //! (and the obstacles' centres and velocities); whether any was.
  bool read_sources() {
    bool changed = false;
    for (Source& source : sources) {
      PyObject* current = PyObject_GetAttr(source.constraint.ptr(), revision_name.ptr());
      if (current == nullptr) throw py::error_already_set();
      py::object held = py::reinterpret_steal<py::object>(current);
      if (current != source.revision.ptr()) {
        load(source, std::move(held));
        changed = true;
      }
    }
    return collision_sources.read(collisions()) || changed;
  }

  cjm_collision::CollisionSources collision_sources;  // with compiled collision rows
};

//! The step into a new array (the GIL released while it runs).
py::array_t<double> finish(BoundPipeline& pipeline, bool use_posture, bool analytical_allowed) {
  py::array_t<double> qd(pipeline.nv());
  Eigen::Map<cjm::Vector> qd_map(qd.mutable_data(), qd.size());
  py::gil_scoped_release release;
  pipeline.finish(use_posture, analytical_allowed, qd_map);
  return qd;
}


//! A period's outcome: the step ran and its command is finite (TICK_STEPPED), the twist
//! was not finite so it did not run (TICK_REFUSED: Python asks the controller, which says
//! why), or its command is not finite (TICK_NOT_FINITE).
enum TickOutcome { kTickStepped = 0, kTickRefused = 1, kTickNotFinite = 2 };

//! A new float64 array holding ``matrix``.
template <typename Matrix>
py::array_t<double> copied(const Matrix& matrix, std::vector<py::ssize_t> shape) {
  py::array_t<double> array(shape);
  std::copy(matrix.data(), matrix.data() + matrix.size(), array.mutable_data());
  return array;
}

//! A Tick bound to the BoundPipeline it runs (kept alive while attached).
struct BoundTick : cjm::Tick {
  using cjm::Tick::Tick;

  py::object pipeline_object;        // keeps the attached pipeline alive
  BoundPipeline* bound = nullptr;    // that pipeline (read without the GIL)
  py::str homogeneous{"homogeneous"};

  BoundPipeline& pipeline() { return *bound; }

  void attach_object(py::object pipeline) {
    BoundPipeline& attached = pipeline.cast<BoundPipeline&>();
    attach(attached);
    bound = &attached;
    pipeline_object = std::move(pipeline);
  }

  //! The targets (a sequence of pin.SE3, one per EE, checked by Python) and q copied in,
  //! the declared constraints' parameters read; false unless q is a finite float64 vector of
  //! the pipeline's nq.
  bool load(py::handle targets, py::handle q) {
    if (!load_vector(q, pipeline().q())) return false;
    const auto poses = py::reinterpret_borrow<py::sequence>(targets);
    cjm::RowMatrix& rows = operator_targets();
    if (static_cast<Index>(poses.size()) != rows.rows())
      throw std::invalid_argument("one target pose per end effector");
    for (Index i = 0; i < rows.rows(); ++i) {
      const auto matrix = py::array_t<double, py::array::forcecast>(
          poses[static_cast<size_t>(i)].attr(homogeneous));
      const auto entries = matrix.unchecked<2>();
      for (py::ssize_t r = 0; r < 3; ++r) {
        for (py::ssize_t c = 0; c < 3; ++c) rows(i, 3 * r + c) = entries(r, c);
        rows(i, 9 + r) = entries(r, 3);
      }
    }
    if (pipeline().read_sources()) forget_sensed();
    return true;
  }

  //! finish() and, when the command is finite and ``integrate_q``, integrate().
  TickOutcome step(bool use_posture, bool analytical_allowed, bool integrate_q) {
    if (!finish(use_posture, analytical_allowed)) return kTickNotFinite;
    if (integrate_q) integrate();
    return kTickStepped;
  }

  //! (outcome, qd or None, next q or None, the period's copy, the step's time in us,
  //! whether the caps scaled a twist, whether the period had a previous target).
  py::tuple result(TickOutcome outcome, bool integrate_q) {
    const Index ee_count = period().rows();
    return py::make_tuple(
        static_cast<int>(outcome),
        outcome == kTickRefused ? py::object(py::none()) : py::object(copied(qd(), {qd().size()})),
        outcome == kTickStepped && integrate_q ? py::object(copied(next_q(), {next_q().size()}))
                                               : py::object(py::none()),
        copied(period(), {ee_count, period().cols()}),
        outcome == kTickRefused ? 0.0 : step_time_us(), twist_saturated(), period_has_previous());
  }
};

}  // namespace

#ifndef CJM_SOURCES_DIGEST  // setup.py defines it: controllers/cjm/extension_sources.py
#define CJM_SOURCES_DIGEST ""
#endif

PYBIND11_MODULE(_step, module) {
  module.doc() = "The compiled CJM step (docs/design.md section 16).";
  module.attr("SOURCES_DIGEST") = CJM_SOURCES_DIGEST;

  module.def(
      "damped_least_squares",
      [](const cjm::Matrix& matrix, const cjm::Matrix& rhs, double damping, double threshold,
         double max_damping, double rank_tolerance, bool solve) {
        if (rhs.rows() != matrix.rows() || rhs.cols() < 1 || rhs.cols() > 2)
          throw py::value_error("rhs must have the matrix's rows and 1 or 2 columns");
        cjm::DampedLeastSquares dls(matrix.rows(), matrix.cols(), rank_tolerance);
        dls.factor(matrix, cjm::DampingPolicy{damping, threshold, max_damping});
        py::object solution = py::none();
        if (solve) {
          cjm::Matrix x(matrix.cols(), rhs.cols());
          dls.solve(rhs, x);
          solution = py::cast(x);
        }
        const double sigma_min = dls.sigma_min(), damped = dls.damping();
        const bool exact = dls.exact();
        const cjm::Matrix row_space = dls.row_space();
        return py::make_tuple(solution, sigma_min, damped, dls.rank(), exact, row_space,
                              dls.by_qr());
      },
      py::arg("matrix"), py::arg("rhs"), py::arg("damping"), py::arg("threshold"),
      py::arg("max_damping"), py::arg("rank_tolerance"), py::arg("solve") = true,
      "The step's damped least squares of one matrix (tests): (x, sigma_min, damping, rank, "
      "exact, row space as columns, whether no SVD was needed). ``solve=False``: the "
      "figures alone, asked for before any solve (x is None), as the saturation around "
      "the previous command asks for its damping rows.");

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
                       double position_gain, bool position_limits, cjm::RowMatrix box_test,
                       cjm::Vector acceleration_step, double dt, double limit_gain,
                       cjm::Vector slack, cjm::Vector damper_step, cjm::Vector jerk_step) {
             return cjm::JointBox{std::move(velocity_lower), std::move(velocity_upper),
                                  std::move(velocity_limit), std::move(limited_q),
                                  std::move(limited_v), std::move(q_min), std::move(q_max),
                                  position_gain, position_limits, std::move(box_test),
                                  std::move(acceleration_step), dt, limit_gain, std::move(slack),
                                  std::move(damper_step), std::move(jerk_step)};
           }),
           py::arg("velocity_lower"), py::arg("velocity_upper"), py::arg("velocity_limit"),
           py::arg("limited_q"), py::arg("limited_v"), py::arg("q_min"), py::arg("q_max"),
           py::arg("position_gain"), py::arg("position_limits"), py::arg("box_test"),
           py::arg("acceleration_step"), py::arg("dt"), py::arg("limit_gain"), py::arg("slack"),
           py::arg("damper_step") = cjm::Vector(), py::arg("jerk_step") = cjm::Vector(),
           "``acceleration_step`` (a dt per joint) empty: no acceleration limit; "
           "``damper_step`` its share the braking-aware dampers count on (the same size); "
           "``jerk_step`` (j dt^2 per joint) empty: no jerk limit.");

  py::class_<cjm::Tolerances>(module, "Tolerances")
      .def(py::init([](double equality, double twist, double barrier, double rank,
                       double pre_chain_pivot_ratio, double pre_chain_min_singular_value,
                       double fast_path_min_sigma, double least_squares_rcond,
                       double conflict_residual, double rows, double at_bound, double box_margin,
                       double still_direction, double release_tolerance) {
             return cjm::Tolerances{equality, twist, barrier, rank, pre_chain_pivot_ratio,
                                    pre_chain_min_singular_value, fast_path_min_sigma,
                                    least_squares_rcond, conflict_residual, rows, at_bound,
                                    box_margin, still_direction, release_tolerance};
           }),
           py::arg("equality"), py::arg("twist"), py::arg("barrier"), py::arg("rank"),
           py::arg("pre_chain_pivot_ratio"), py::arg("pre_chain_min_singular_value"),
           py::arg("fast_path_min_sigma"), py::arg("least_squares_rcond"),
           py::arg("conflict_residual"), py::arg("rows"), py::arg("at_bound"),
           py::arg("box_margin"), py::arg("still_direction"), py::arg("release_tolerance"),
           "controllers.cjm.tolerances.StepTolerances, field by field.");

  py::class_<cjm::Step>(module, "Step")
      .def(py::init([](Index nq, Index nv, Index task_rows, double damping, double threshold,
                       double max_damping, bool general_only,
                       std::vector<cjm::ConstraintPlan> constraints, cjm::JointBox box,
                       double posture_gain, cjm::Vector posture_target,
                       cjm::Tolerances tolerances, Index pair_capacity, Index event_capacity) {
             return new cjm::Step(nq, nv, task_rows, cjm::DampingPolicy{damping, threshold, max_damping},
                                  general_only, std::move(constraints), std::move(box),
                                  posture_gain, std::move(posture_target), tolerances,
                                  pair_capacity, event_capacity);
           }),
           py::arg("nq"), py::arg("nv"), py::arg("task_rows"), py::arg("damping"),
           py::arg("threshold"), py::arg("max_damping"), py::arg("general_only"),
           py::arg("constraints"), py::arg("box"), py::arg("posture_gain"),
           py::arg("posture_target"), py::arg("tolerances"), py::arg("pair_capacity") = 0,
           py::arg("event_capacity") = -1)
      .def_property_readonly(
          "report", [](cjm::Step& step) { return cjm_report::report_of(step.report()); },
          "The last step's Report (its fields: report.hpp's CJM_STEP_REPORT).")
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
      })
      .def_property_readonly("previous", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.previous().data(), {step.previous().size()}, self);
      }, "The previous command (writable): the acceleration limits' reference.")
      .def_property_readonly("previous_change", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.previous_change().data(), {step.previous_change().size()}, self);
      }, "The previous command minus the one before (writable): the jerk limits' reference.")
      .def_property_readonly("pair_rows", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.pair_rows().data(), {step.pair_rows().rows(), step.pair_rows().cols()}, self);
      }, "The collision rows (writable, pair_capacity x nv): ``pair_rows qd >= pair_lower``.")
      .def_property_readonly("pair_lower", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.pair_lower().data(), {step.pair_lower().size()}, self);
      }, "The collision rows' bounds (writable, pair_capacity).")
      .def_property_readonly("damper_gaps", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.damper_gaps().data(), {step.damper_gaps().size()}, self);
      }, "Each constraint's damper gap (writable): Python writes it with the terms it writes.")
      .def_property_readonly("damper_gains", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.damper_gains().data(), {step.damper_gains().size()}, self);
      }, "Each constraint's damper gain (writable), as damper_gaps.")
      .def_property_readonly("pair_capacity", &cjm::Step::pair_capacity)
      .def("set_pair_count", &cjm::Step::set_pair_count, py::arg("count"),
           "How many of pair_rows the next step holds (ValueError beyond the capacity).")
      .def_property_readonly("active_pairs", [](py::object self) {
        auto& step = self.cast<cjm::Step&>();
        return view(step.active_pairs().data(), {step.active_pairs().size()}, self);
      })
      .def_property_readonly("active_pair_count", &cjm::Step::active_pair_count);

  py::class_<BoundPipeline>(module, "Pipeline")
      .def(py::init([](std::vector<std::tuple<std::string, Index, Eigen::Matrix4d, Eigen::Vector3d>> joints,
                       std::vector<std::tuple<Index, Eigen::Matrix4d>> frames, const cjm::Step& step,
                       Index ee_count, std::vector<Index> task_entries, cjm::Vector task_scale) {
             std::vector<cjm::JointSpec> joint_specs;
             for (auto& [kind, parent, placement, axis] : joints)
               joint_specs.push_back(cjm::JointSpec{kind, parent, placement, axis});
             std::vector<cjm::FrameSpec> frame_specs;
             for (auto& [parent, placement] : frames)
               frame_specs.push_back(cjm::FrameSpec{parent, placement});
             return new BoundPipeline(cjm::Kinematics(joint_specs, frame_specs), step, ee_count,
                                      std::move(task_entries), std::move(task_scale));
           }),
           py::arg("joints"), py::arg("frames"), py::arg("step"), py::arg("ee_count"),
           py::arg("task_entries"), py::arg("task_scale"),
           "``joints``: (kind, parent, placement 4x4, axis) per joint of pin.Model after the "
           "universe; ``frames``: (parent joint, placement 4x4), the EE frames then one per "
           "constraint; ``step`` is copied.")
      .def("declare", &BoundPipeline::declare, py::arg("index"), py::arg("constraint"),
           py::arg("kind"), py::arg("values"), py::arg("paper"), py::arg("paper_min_a"),
           py::arg("unit_tolerance"),
           "Constraint ``index``'s terms of ``kind`` computed here from the parameters "
           "``values(constraint)`` (taken again whenever its ``revision`` is replaced); "
           "``paper``: a hole's structure matrix in the paper's parametrisation where "
           "|p| >= ``paper_min_a``; a declared axis or normal within ``unit_tolerance`` of "
           "unit norm. ValueError for a bad declaration, naming the field.")
      .def("load", [](BoundPipeline& pipeline, py::handle q, py::handle twist) {
             return load_vector(q, pipeline.q()) && load_vector(twist, pipeline.twist());
           }, py::arg("q"), py::arg("twist"),
           "Copies q and the stacked twist in: false unless both are finite float64 vectors "
           "of the right sizes.")
      .def("prepare", [](BoundPipeline& pipeline) {
             pipeline.read_sources();
             py::gil_scoped_release release;
             pipeline.prepare();
           },
           "The declared constraints' parameters read (when replaced), then the kinematics, "
           "the task rows and the declared terms at the loaded q.")
      .def("finish", &finish, py::arg("use_posture"), py::arg("analytical_allowed"),
           "The step, after prepare() and the terms Python writes: a new qd.")
      .def("solve", [](BoundPipeline& pipeline, py::handle q, py::handle twist, bool use_posture,
                       bool analytical_allowed) -> py::object {
             if (!load_vector(q, pipeline.q()) || !load_vector(twist, pipeline.twist()))
               return py::none();
             pipeline.read_sources();
             {
               py::gil_scoped_release release;
               pipeline.prepare();
             }
             return finish(pipeline, use_posture, analytical_allowed);
           }, py::arg("q"), py::arg("twist"), py::arg("use_posture"), py::arg("analytical_allowed"),
           "load, prepare and finish in one call; None when load() would be false.")
      .def("time_steps", [](BoundPipeline& pipeline, const cjm::RowMatrix& configurations,
                            const cjm::RowMatrix& twists, bool use_posture) {
             if (configurations.cols() != pipeline.q().size() ||
                 twists.cols() != pipeline.twist().size() || twists.rows() != configurations.rows())
               throw std::invalid_argument("time_steps needs one q (nq) and one stacked twist per step");
             if (!configurations.allFinite() || !twists.allFinite())
               throw std::invalid_argument("time_steps needs finite configurations and twists");
             pipeline.read_sources();
             py::array_t<std::int64_t> nanoseconds(configurations.rows());
             std::int64_t* times = nanoseconds.mutable_data();
             cjm::Vector qd(pipeline.nv());
             {
               py::gil_scoped_release release;
               for (Index i = 0; i < configurations.rows(); ++i) {
                 const auto start = std::chrono::steady_clock::now();
                 pipeline.q() = configurations.row(i).transpose();
                 pipeline.twist() = twists.row(i).transpose();
                 pipeline.prepare();
                 pipeline.finish(use_posture, true, qd);
                 times[i] = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                std::chrono::steady_clock::now() - start).count();
               }
             }
             return nanoseconds;
           }, py::arg("configurations"), py::arg("twists"), py::arg("use_posture"),
           "The C++ floor: per-step nanoseconds of load, prepare and finish (the one-call "
           "step of solve) over ``configurations`` (steps x nq) and ``twists`` (steps x "
           "stacked twist), in a C++ loop with the GIL released; the anchors read once.")
      .def("set_collisions", &cjm_collision::set_collisions<BoundPipeline>, py::arg("body_joints"),
           py::arg("body_placements"), py::arg("body_kinds"), py::arg("body_dimensions"),
           py::arg("obstacles"), py::arg("obstacle_kinds"), py::arg("obstacle_dimensions"),
           py::arg("obstacle_rotations"), py::arg("pairs"), py::arg("pair_names"), py::arg("safety_distance"),
           py::arg("detection_distance"), py::arg("gain"),
           "The collision rows measured in prepare() (docs/design.md section 18.4).")
      .def("clear_collisions", [](BoundPipeline& pipeline) {
             pipeline.set_collisions(nullptr);
             pipeline.collision_sources = {};
           }, "No collision rows measured here (Python writes them, if any).")
      .def("collision_views", &cjm_collision::collision_views<BoundPipeline>,
           "(row pairs, distances, witnesses, (count, minimum distance, its pair)).")
      .def("collision_report", &cjm_collision::collision_report<BoundPipeline>,
           "The last step's collision rows as CollisionRows' fields, copied.")
      .def_property_readonly("step", [](BoundPipeline& pipeline) -> cjm::Step& { return pipeline.step(); },
                             py::return_value_policy::reference_internal)
      .def_property_readonly("q", [](py::object self) {
        auto& vector = self.cast<BoundPipeline&>().q();
        return view(vector.data(), {vector.size()}, self);
      })
      .def_property_readonly("terms", [](py::object self) {
        auto& vector = self.cast<BoundPipeline&>().terms();
        return view(vector.data(), {vector.size()}, self);
      })
      .def_property_readonly("posture", [](py::object self) {
        auto& vector = self.cast<BoundPipeline&>().posture();
        return view(vector.data(), {vector.size()}, self);
      })
      .def_property_readonly("paper_form", &BoundPipeline::paper_form,
                             "False when the last step found the paper's form undefined.")
      .def_property_readonly("placements", [](py::object self) {
        return read_only(self.cast<BoundPipeline&>().placements(), self);
      })
      .def_property_readonly("jacobians", [](py::object self) {
        return read_only(self.cast<BoundPipeline&>().jacobians(), self);
      });

  py::class_<BoundTick>(module, "Tick")
      .def(py::init([](py::object pipeline, Index ee_count, double dt, double kp,
                       double max_linear, double max_angular, double smoothing,
                       bool feed_forward) {
             auto tick = std::make_unique<BoundTick>(
                 ee_count, cjm::TickSettings{dt, kp, max_linear, max_angular, smoothing, feed_forward});
             tick->attach_object(std::move(pipeline));
             return tick;
           }),
           py::arg("pipeline"), py::arg("ee_count"), py::arg("dt"), py::arg("kp"),
           py::arg("max_linear"), py::arg("max_angular"), py::arg("smoothing"),
           py::arg("feed_forward"),
           "The loop's hot path on ``pipeline`` (tick.hpp): ``smoothing`` is "
           "``alpha = 1 - exp(-dt / tau)``, 1 for none.")
      .def("attach", &BoundTick::attach_object, py::arg("pipeline"),
           "Run the next periods on ``pipeline`` (a rebuilt step's); the filter's state stays.")
      .def("run", [](BoundTick& tick, py::handle targets, py::handle q, bool use_posture,
                     bool integrate_q) -> py::object {
             if (!tick.load(targets, q)) return py::none();
             TickOutcome outcome;
             {
               py::gil_scoped_release release;
               tick.begin();
               outcome = tick.pipeline().twist().allFinite()
                             ? tick.step(use_posture, true, integrate_q)
                             : kTickRefused;
             }
             return tick.result(outcome, integrate_q);
           }, py::arg("targets"), py::arg("q"), py::arg("use_posture"), py::arg("integrate"),
           "One period in one call (every constraint declares a compiled form): None when q is not "
           "a finite float64 vector of nq (nothing ran), else (outcome, qd, next q, period, "
           "step time in us, twist saturated, period had a previous target).")
      .def("sense", [](BoundTick& tick, py::handle q) -> py::object {
             if (!load_vector(q, tick.pipeline().q())) return py::none();
             tick.pipeline().read_sources();
             {
               py::gil_scoped_release release;
               tick.sense();
             }
             const cjm::Vector& violations = tick.pipeline().violations();
             return copied(violations, {violations.size()});
           }, py::arg("q"),
           "The kinematics at q and the declared constraints' terms, which the next run() or "
           "start() at the same q reuses: None when q is not a finite float64 vector of nq, "
           "else each constraint's violation (m; NaN where Python writes its terms).")
      .def("start", [](BoundTick& tick, py::handle targets, py::handle q) -> py::object {
             if (!tick.load(targets, q)) return py::none();
             bool finite = false;
             {
               py::gil_scoped_release release;
               tick.begin();
               finite = tick.pipeline().twist().allFinite();
             }
             return py::bool_(finite);
           }, py::arg("targets"), py::arg("q"),
           "The period up to the step (filter, kinematics, twists, task rows, declared terms): "
           "None when q is not a finite float64 vector of nq, else whether the twist is finite.")
      .def("end", [](BoundTick& tick, bool use_posture, bool analytical_allowed,
                     bool integrate_q) {
             TickOutcome outcome;
             {
               py::gil_scoped_release release;
               outcome = tick.step(use_posture, analytical_allowed, integrate_q);
             }
             return tick.result(outcome, integrate_q);
           }, py::arg("use_posture"), py::arg("analytical_allowed"), py::arg("integrate"),
           "The step after start() (and the terms Python writes): run()'s tuple.")
      .def("refused", [](BoundTick& tick) { return tick.result(kTickRefused, false); },
           "run()'s tuple for a period start() found a twist that is not finite in.")
      .def_property_readonly("twist", [](py::object self) {
        BoundTick& tick = self.cast<BoundTick&>();
        auto& vector = tick.pipeline().twist();
        return view(vector.data(), {vector.size()}, tick.pipeline_object);
      }, "The stacked twist of the period (after the caps).")
      .def_property_readonly("filtered", [](py::object self) {
        auto& matrix = self.cast<BoundTick&>().filtered();
        return view(matrix.data(), {matrix.rows(), matrix.cols()}, self);
      }, "The filtered targets (writable rows of 12), valid when has_filtered.")
      .def_property_readonly("previous", [](py::object self) {
        auto& matrix = self.cast<BoundTick&>().previous();
        return view(matrix.data(), {matrix.rows(), matrix.cols()}, self);
      }, "The previous period's filtered targets (writable rows of 12), valid when has_previous.")
      .def_property_readonly("has_filtered", &BoundTick::has_filtered)
      .def_property_readonly("has_previous", &BoundTick::has_previous)
      .def("set_history", &BoundTick::set_history, py::arg("has_filtered"), py::arg("has_previous"),
           "Which of filtered and previous hold poses (after writing them).");
  // the pose rows and the tick's period row (pose_row.hpp), for controllers/cjm/pose_rows.py
  module.attr("POSE_ROW") = cjm::kPoseRow;
  module.attr("POSE_TRANSLATION") = cjm::kPoseTranslation;
  module.attr("PERIOD_TARGET") = cjm::kPeriodTarget;
  module.attr("PERIOD_PREVIOUS") = cjm::kPeriodPrevious;
  module.attr("PERIOD_PLACEMENT") = cjm::kPeriodPlacement;
  module.attr("PERIOD_TWIST") = cjm::kPeriodTwist;
  module.attr("PERIOD_ROW") = cjm::kPeriodRow;
  module.attr("TICK_STEPPED") = static_cast<int>(kTickStepped);
  module.attr("TICK_REFUSED") = static_cast<int>(kTickRefused);
  module.attr("TICK_NOT_FINITE") = static_cast<int>(kTickNotFinite);

  cjm_report::bind(module);
  module.attr("JOINT_KINDS") = cjm::joint_kinds();
  cjm_collision::bind(module);
}
