// The plant's period called from Python (docs/design.md section 17.5): a CPython module,
// cjm_period_call, whose one function takes the period's block (plant_period.h) by address
// and the command and the configuration as buffers:
//
//     moved, reached = run(block, command, q)
//
// copies the command (nv float64) and q (nq float64) into the block's buffers, runs the
// period with the GIL released (as ctypes would: MuJoCo's step needs no Python) and returns
// the velocity moved and the configuration it takes q to as new float64 arrays; for a robot
// whose coordinates MuJoCo's are not (a planar base, a continuous joint)
//
//     run_mapped(block, command)
//
// runs it from the command in MuJoCo's dofs, the caller mapping qpos to its coordinates.
// ``identical(a, b)`` says whether two lists hold the same objects (``is``), in the same
// order: the check of the ports' objects every period, at a third of Python's cost. A vectorcall on two buffers costs a tenth of a
// ctypes call and the copies around it (teleop/plants/compiled_period.py). Anything but a
// C-contiguous float64 vector of the right length is a TypeError, which the Python side
// answers with numpy's conversions and checks.
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <string.h>

#include "plant_period.h"

// Copy ``source`` (count float64, C-contiguous) into ``target``; 0, or -1 with TypeError.
static int copy_vector(PyObject* source, double* target, int count, const char* name) {
  Py_buffer view;
  int fits = 0;
  if (PyObject_GetBuffer(source, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) == 0) {
    fits = view.itemsize == (Py_ssize_t)sizeof(double) && view.format != NULL &&
           strcmp(view.format, "d") == 0 && view.len == (Py_ssize_t)sizeof(double) * count;
    if (fits) memcpy(target, view.buf, sizeof(double) * (size_t)count);
    PyBuffer_Release(&view);
  } else {
    PyErr_Clear();  // not a buffer, or not a contiguous one: the same TypeError
  }
  if (!fits) {
    PyErr_Format(PyExc_TypeError, "%s must be %d contiguous float64 numbers", name, count);
    return -1;
  }
  return 0;
}

static PyObject* run(PyObject* module, PyObject* const* args, Py_ssize_t nargs) {
  (void)module;
  if (nargs != 3) {
    PyErr_SetString(PyExc_TypeError, "run(block, command, q) takes 3 arguments");
    return NULL;
  }
  PlantPeriod* period = (PlantPeriod*)PyLong_AsVoidPtr(args[0]);
  if (period == NULL) {
    if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "the block's address is 0");
    return NULL;
  }
  if (copy_vector(args[1], period->command, period->nv, "command") != 0 ||
      copy_vector(args[2], period->q, period->nq, "q") != 0)
    return NULL;
  npy_intp nv = period->nv, nq = period->nq;
  PyObject* moved = PyArray_SimpleNew(1, &nv, NPY_DOUBLE);
  PyObject* reached = PyArray_SimpleNew(1, &nq, NPY_DOUBLE);
  if (moved == NULL || reached == NULL) {
    Py_XDECREF(moved);
    Py_XDECREF(reached);
    return NULL;
  }
  Py_BEGIN_ALLOW_THREADS
  period->run(period);
  Py_END_ALLOW_THREADS
  memcpy(PyArray_DATA((PyArrayObject*)moved), period->moved, sizeof(double) * (size_t)nv);
  memcpy(PyArray_DATA((PyArrayObject*)reached), period->reached, sizeof(double) * (size_t)nq);
  PyObject* both = PyTuple_New(2);
  if (both == NULL) {
    Py_DECREF(moved);
    Py_DECREF(reached);
    return NULL;
  }
  PyTuple_SET_ITEM(both, 0, moved);
  PyTuple_SET_ITEM(both, 1, reached);
  return both;
}

static PyObject* run_mapped(PyObject* module, PyObject* const* args, Py_ssize_t nargs) {
  (void)module;
  if (nargs != 2) {
    PyErr_SetString(PyExc_TypeError, "run_mapped(block, command) takes 2 arguments");
    return NULL;
  }
  PlantPeriod* period = (PlantPeriod*)PyLong_AsVoidPtr(args[0]);
  if (period == NULL) {
    if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "the block's address is 0");
    return NULL;
  }
  if (copy_vector(args[1], period->command, period->nv, "command") != 0) return NULL;
  Py_BEGIN_ALLOW_THREADS
  period->run(period);
  Py_END_ALLOW_THREADS
  Py_RETURN_NONE;
}

static PyObject* identical(PyObject* module, PyObject* const* args, Py_ssize_t nargs) {
  (void)module;
  if (nargs != 2 || !PyList_Check(args[0]) || !PyList_Check(args[1])) {
    PyErr_SetString(PyExc_TypeError, "identical(a, b) takes 2 lists");
    return NULL;
  }
  const Py_ssize_t count = PyList_GET_SIZE(args[0]);
  if (PyList_GET_SIZE(args[1]) != count) Py_RETURN_FALSE;
  for (Py_ssize_t i = 0; i < count; ++i)
    if (PyList_GET_ITEM(args[0], i) != PyList_GET_ITEM(args[1], i)) Py_RETURN_FALSE;
  Py_RETURN_TRUE;
}

static PyMethodDef methods[] = {
    {"run", (PyCFunction)(void (*)(void))run, METH_FASTCALL,
     "run(block, command, q): one period of the block at this address; the velocity moved "
     "and the configuration reached."},
    {"run_mapped", (PyCFunction)(void (*)(void))run_mapped, METH_FASTCALL,
     "run_mapped(block, command): one period of the block at this address from a command "
     "in MuJoCo's dofs."},
    {"identical", (PyCFunction)(void (*)(void))identical, METH_FASTCALL,
     "identical(a, b): the two lists hold the same objects in the same order."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef definition = {PyModuleDef_HEAD_INIT, "cjm_period_call",
                                        "The plant's period called from Python.", -1, methods,
                                        NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit_cjm_period_call(void) {
  import_array();
  return PyModule_Create(&definition);
}
