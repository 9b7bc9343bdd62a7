// The layout of one constraint's flat terms buffer of k rows (docs/design.md section 16):
// ``pre_rhs = [V_a0, S]`` (6 x (7 - k), column-major) then
// ``residual_rows = [-b, C [I, -hat(p)]]`` (k x 7, row-major). The one description on the
// C++ side; controllers.cjm.analytical.terms_views is the Python reference's (the step
// built from Python checks each constraint's offset against it: compiled.py).
#pragma once

#include <Eigen/Core>

#include "dense.hpp"

namespace cjm {

//! Doubles in the terms of a constraint of ``k`` rows.
inline Index terms_size(Index k) { return 6 * (7 - k) + 7 * k; }

//! ``pre_rhs`` (6 x (7 - k)) and ``residual_rows`` (k x 7) in the terms at ``terms``.
inline Eigen::Map<const Matrix> pre_rhs_of(const double* terms, Index k) {
  return Eigen::Map<const Matrix>(terms, 6, 7 - k);
}
inline Eigen::Map<const RowMatrix> residual_rows_of(const double* terms, Index k) {
  return Eigen::Map<const RowMatrix>(terms + 6 * (7 - k), k, 7);
}
inline Eigen::Map<Matrix> pre_rhs_of(double* terms, Index k) {
  return Eigen::Map<Matrix>(terms, 6, 7 - k);
}
inline Eigen::Map<RowMatrix> residual_rows_of(double* terms, Index k) {
  return Eigen::Map<RowMatrix>(terms + 6 * (7 - k), k, 7);
}

}  // namespace cjm
