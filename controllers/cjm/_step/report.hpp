// What one compiled CJM step reports (docs/design.md section 16): its status, method and
// figures, and how many joints, barriers and events its lists hold. Each field is named
// once, in CJM_STEP_REPORT below: Report declares them from it and the bindings
// (report_bindings.hpp) give Python the same names from it (controllers/cjm/compiled.py reads them
// into a controllers.cjm.report.StepReport).
#pragma once

#include <limits>

#include "dense.hpp"

namespace cjm {

//! controllers.base.StepStatus, best to worst.
enum class Status : int { ok = 0, scaled, least_squares, constraint_degraded, failed };

//! SolveInfo.method (controllers.cjm.report.METHODS by code).
enum class Method : int { none = 0, analytical, general, saturated };

//! What happened in a step, in order; Python words them into SolveInfo.message
//! (controllers.cjm.report.Event has the same codes).
enum class Event : int {
  pre_chain_singular = 1,  // the note replaces the message, as in the Python
  task_residual,           // a: damping, b: twist residual
  conflict,                // a: rank, b: rows, c: least-squares residual
  no_free_joint,
  rows_scaled,             // a: the rows' scale
  task_missed,             // a: sigma_min, b: damping; the joints: saturation_joints()
  task_scaled,             // a: limiting joint, b: task scale
  clipped,                 // a: largest change; the joints: saturated_joints()
  residual,                // a: equality residual
  no_convergence,          // failed
  non_finite,              // failed
  pair_conflict = 14,      // a: collision row, b: shortfall below the rows before it
};

//! The report's fields, each once: FIELD(type, name, value before a step, what it holds).
#define CJM_STEP_REPORT(FIELD)                                                              \
  FIELD(Status, status, Status::ok, "StepStatus by its order, best to worst")               \
  FIELD(Method, method, Method::none, "SolveInfo.method by code (0: none)")                 \
  FIELD(double, sigma_min, std::numeric_limits<double>::quiet_NaN(),                        \
        "the smallest singular value of the task's DLS (NaN: none)")                        \
  FIELD(double, damping, 0.0, "the DLS damping used")                                       \
  FIELD(double, scale, 1.0, "the factor (<= 1) applied to the task")                        \
  FIELD(double, equality_residual, 0.0, "max |A qd - b| over the equality rows held")       \
  FIELD(Index, saturated_count, 0, "the joints held at a limit, saturated_joints[:count]") \
  FIELD(Index, active_barrier_count, 0,                                                     \
        "the barriers held as equalities, active_barriers[:count]")                         \
  FIELD(Index, event_count, 0, "the events recorded, events[:count]")                       \
  FIELD(Index, saturation_joint_count, 0,                                                   \
        "the joints a saturated step held when it missed the task, saturation_joints[:count]") \
  FIELD(Index, dropped_event_count, 0, "the events past the last row of events")

struct Report {
#define CJM_DECLARE_FIELD(type, name, initial, doc) type name = initial;
  CJM_STEP_REPORT(CJM_DECLARE_FIELD)
#undef CJM_DECLARE_FIELD
};

}  // namespace cjm
