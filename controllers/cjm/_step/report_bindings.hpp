// The Python type of the compiled step's report (report.hpp), for module.cpp: a named
// tuple whose fields are CJM_STEP_REPORT's, a step's report as one, and the codes of its
// statuses, methods and events (CJM_STATUSES, CJM_METHODS, CJM_EVENTS) as dicts.
#pragma once

#include <pybind11/pybind11.h>
#include <structmember.h>

#include <iterator>

#include "report.hpp"

namespace cjm_report {

//! ``type``'s fields read by name as fast as __slots__: a struct sequence's members are
//! T_OBJECT, whose reads CPython (3.11+) does not specialize (compiled.py's nine reads a step
//! took 270 ns, issue 37's regression, against 55 ns); T_OBJECT_EX reads the same object here,
//! every field of a report being set, and is specialized.
inline void read_as_slots(PyTypeObject* type) {
  for (PyMemberDef* member = type->tp_members; member->name != nullptr; ++member) {
    member->type = T_OBJECT_EX;
  }
}

//! Python's type of a step's report: a named tuple (a C struct sequence) whose fields are
//! CJM_STEP_REPORT's, made once. Reading a field by name costs what a tuple's item does.
inline PyTypeObject* report_type() {
  static PyStructSequence_Field fields[] = {
#define CJM_REPORT_FIELD(type, name, initial, doc) {#name, doc},
      CJM_STEP_REPORT(CJM_REPORT_FIELD)
#undef CJM_REPORT_FIELD
      {nullptr, nullptr}};
  static PyStructSequence_Desc description{
      "controllers.cjm._step.Report", "What one compiled step reports (report.hpp).", fields,
      static_cast<int>(std::size(fields) - 1)};
  static PyTypeObject* const type = [] {
    PyTypeObject* const made = PyStructSequence_NewType(&description);
    if (made == nullptr) throw pybind11::error_already_set();
    read_as_slots(made);
    return made;
  }();
  return type;
}

inline PyObject* to_python(double value) { return PyFloat_FromDouble(value); }
inline PyObject* to_python(cjm::Index value) { return PyLong_FromSsize_t(value); }
inline PyObject* to_python(cjm::Status value) { return PyLong_FromLong(static_cast<long>(value)); }
inline PyObject* to_python(cjm::Method value) { return PyLong_FromLong(static_cast<long>(value)); }

//! ``report`` as a new Report (report_type()).
inline pybind11::object report_of(const cjm::Report& report) {
  auto result = pybind11::reinterpret_steal<pybind11::object>(PyStructSequence_New(report_type()));
  if (!result) throw pybind11::error_already_set();
  Py_ssize_t index = 0;
#define CJM_REPORT_ITEM(type, name, initial, doc)                 \
  if (PyObject* item = to_python(report.name)) {                  \
    PyStructSequence_SetItem(result.ptr(), index++, item);        \
  } else {                                                        \
    throw pybind11::error_already_set();                          \
  }
  CJM_STEP_REPORT(CJM_REPORT_ITEM)
#undef CJM_REPORT_ITEM
  return result;
}

//! Binds Report (report_type()) and the codes from report.hpp's lists, each a dict name ->
//! code: STATUSES, METHODS and EVENTS (controllers/cjm/compiled.py checks them at import).
inline void bind(pybind11::module_& module) {
  module.attr("Report") = pybind11::reinterpret_borrow<pybind11::object>(
      reinterpret_cast<PyObject*>(report_type()));
  pybind11::dict statuses, methods, events;
#define CJM_STATUS_CODE(name) statuses[#name] = static_cast<int>(cjm::Status::name);
#define CJM_METHOD_CODE(name) methods[#name] = static_cast<int>(cjm::Method::name);
#define CJM_EVENT_CODE(name, code) events[#name] = static_cast<int>(cjm::Event::name);
  CJM_STATUSES(CJM_STATUS_CODE)
  CJM_METHODS(CJM_METHOD_CODE)
  CJM_EVENTS(CJM_EVENT_CODE)
#undef CJM_EVENT_CODE
#undef CJM_METHOD_CODE
#undef CJM_STATUS_CODE
  module.attr("STATUSES") = statuses;
  module.attr("METHODS") = methods;
  module.attr("EVENTS") = events;
}

}  // namespace cjm_report
