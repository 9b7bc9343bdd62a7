// What one compiled CJM step reports (docs/design.md section 16): its status, method and
// figures, and how many joints, barriers and events its lists hold. Each field is named
// once, in CJM_STEP_REPORT below: Report declares them from it and the bindings
// (report_bindings.hpp) give Python the same names from it (controllers/cjm/compiled.py reads them
// into a controllers.cjm.report.StepReport).
#pragma once

#include <limits>

#include "dense.hpp"

namespace cjm {

//! The codes Python reads (report_bindings.hpp binds each list as a dict name -> code, and
//! controllers/cjm/compiled.py checks them against controllers.cjm.report at import): each
//! name and code is written once, here.
//! controllers.base.StepStatus by its order, best to worst: STATUS(name), codes from 0.
#define CJM_STATUSES(STATUS) \
  STATUS(ok) STATUS(scaled) STATUS(least_squares) STATUS(constraint_degraded) STATUS(failed)
//! SolveInfo.method (controllers.cjm.report.METHODS by code; none: ""): METHOD(name), from 0.
#define CJM_METHODS(METHOD) METHOD(none) METHOD(analytical) METHOD(general) METHOD(saturated)
//! What happened in a step, in order: EVENT(name, code); Python words them into
//! SolveInfo.message (controllers.cjm.report.Event has the same names and codes, and two
//! codes of its own, 12 and 13, that the Python step alone records).
#define CJM_EVENTS(EVENT)                                                                   \
  EVENT(pre_chain_singular, 1) /* the note replaces the message, as in the Python */        \
  EVENT(task_residual, 2)      /* a: damping, b: twist residual */                          \
  EVENT(conflict, 3)           /* a: rank, b: rows, c: least-squares residual */            \
  EVENT(no_free_joint, 4)                                                                   \
  EVENT(rows_scaled, 5)        /* a: the rows' scale */                                     \
  EVENT(task_missed, 6)        /* a: sigma_min, b: damping; joints: saturation_joints() */  \
  EVENT(task_scaled, 7)        /* a: limiting joint, b: task scale */                       \
  EVENT(clipped, 8)            /* a: largest change; the joints: saturated_joints() */      \
  EVENT(residual, 9)           /* a: equality residual */                                   \
  EVENT(no_convergence, 10)    /* failed */                                                 \
  EVENT(non_finite, 11)        /* failed */                                                 \
  EVENT(pair_conflict, 14)     /* a: collision row, b: shortfall below the rows before it */

#define CJM_ENUMERATOR(name) name,
#define CJM_CODED_ENUMERATOR(name, code) name = code,
enum class Status : int { CJM_STATUSES(CJM_ENUMERATOR) };
enum class Method : int { CJM_METHODS(CJM_ENUMERATOR) };
enum class Event : int { CJM_EVENTS(CJM_CODED_ENUMERATOR) };
#undef CJM_CODED_ENUMERATOR
#undef CJM_ENUMERATOR

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
