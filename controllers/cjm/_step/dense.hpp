// Small dense kernels on preallocated storage, for the compiled CJM step
// (docs/design.md section 16): Householder QR, one-sided Jacobi SVD, a thin SVD built
// from the two. Every routine works in blocks of matrices allocated once, so a step
// never touches the heap.
#pragma once

#include <Eigen/Core>
#include <Eigen/Jacobi>

#include <algorithm>
#include <cmath>
#include <limits>

namespace cjm {

using Index = Eigen::Index;
using Matrix = Eigen::MatrixXd;
using Vector = Eigen::VectorXd;
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MatrixRef = Eigen::Ref<Matrix>;
using ConstMatrixRef = Eigen::Ref<const Matrix>;
using VectorRef = Eigen::Ref<Vector>;
using ConstVectorRef = Eigen::Ref<const Vector>;

//! Thrown when an SVD does not converge: the step then fails, as LAPACK's LinAlgError
//! makes the Python step fail.
struct NoConvergence {};

//! ``target <- H target`` for ``H = I - tau [1; v] [1; v]^T`` (``v``: ``length``
//! entries; ``target``: ``length + 1``). Plain loops: at a step's lengths (1-16) Eigen's
//! vectorised dot and update cost more in set-up than in arithmetic (150-300 instructions
//! a column; a saturated step with acceleration limits applies some 50 reflections).
inline void reflect(const double* __restrict v, Index length, double tau, double* __restrict target) {
  double dot = 0.0;
  for (Index i = 0; i < length; ++i) dot += v[i] * target[i + 1];
  const double w = tau * (target[0] + dot);
  target[0] -= w;
  for (Index i = 0; i < length; ++i) target[i + 1] -= w * v[i];
}

//! Householder QR in place (LAPACK dgeqr2's layout): ``a`` (p x q) becomes R on and above
//! the diagonal and each reflector's vector below it (its first entry, 1, implicit);
//! ``tau`` (min(p, q)) holds the reflectors' factors, ``H_j = I - tau_j v_j v_j^T``.
inline void householder_qr(MatrixRef a, VectorRef tau) {
  const Index p = a.rows(), q = a.cols(), t = std::min(p, q);
  for (Index j = 0; j < t; ++j) {
    auto column = a.col(j).tail(p - j);
    const double alpha = column(0);
    const double tail_norm2 = column.tail(p - j - 1).squaredNorm();
    if (tail_norm2 == 0.0) {  // already triangular in this column: H_j = I
      tau(j) = 0.0;
      continue;
    }
    const double beta = -std::copysign(std::sqrt(alpha * alpha + tail_norm2), alpha);
    tau(j) = (beta - alpha) / beta;
    column.tail(p - j - 1) /= (alpha - beta);
    column(0) = beta;
    const double* vector = a.data() + j * a.outerStride() + j + 1;
    for (Index k = j + 1; k < q; ++k) reflect(vector, p - j - 1, tau(j), a.data() + k * a.outerStride() + j);
  }
}

//! ``b <- U^-1 b`` for the upper triangle ``U`` of the leading ``t x t`` block of
//! ``factored`` (``t = b.rows()``), every column of ``b``, by back substitution. The
//! triangles here are at most a few rows: Eigen's blocked kernel for a matrix right-hand
//! side costs more than the arithmetic.
template <typename Factored, typename Rhs>
inline void upper_solve(const Factored& factored, Rhs&& b) {
  const Index t = b.rows();
  for (Index k = 0; k < b.cols(); ++k) {
    for (Index i = t - 1; i >= 0; --i) {
      double sum = b(i, k);
      for (Index j = i + 1; j < t; ++j) sum -= factored(i, j) * b(j, k);
      b(i, k) = sum / factored(i, i);
    }
  }
}

//! ``inverse <- U^-1`` (upper triangular, ``t x t``, ``t = inverse.rows()``) for the
//! upper triangle ``U`` of the leading ``t x t`` block of ``factored``: column ``k`` by
//! back substitution on ``e_k`` over its first ``k + 1`` rows.
template <typename Factored, typename Inverse>
inline void upper_inverse(const Factored& factored, Inverse&& inverse) {
  const Index t = inverse.rows();
  inverse.setZero();
  for (Index k = 0; k < t; ++k) {
    inverse(k, k) = 1.0 / factored(k, k);
    for (Index i = k - 1; i >= 0; --i) {
      double sum = 0.0;
      for (Index j = i + 1; j <= k; ++j) sum -= factored(i, j) * inverse(j, k);
      inverse(i, k) = sum / factored(i, i);
    }
  }
}

//! One reflector ``H_j`` of a factored ``qr`` applied to every column of ``b``.
inline void apply_reflector(const ConstMatrixRef& qr, double tau, Index j, MatrixRef b) {
  if (tau == 0.0) return;
  const Index length = qr.rows() - j - 1;
  const double* vector = qr.data() + j * qr.outerStride() + j + 1;
  for (Index k = 0; k < b.cols(); ++k) reflect(vector, length, tau, b.data() + k * b.outerStride() + j);
}

//! ``b <- Q^T b`` for the ``Q`` of :func:`householder_qr` (``b`` has p rows).
inline void apply_qt(const ConstMatrixRef& qr, const ConstVectorRef& tau, MatrixRef b) {
  for (Index j = 0; j < tau.size(); ++j) apply_reflector(qr, tau(j), j, b);
}

//! ``b <- Q b`` for the ``Q`` of :func:`householder_qr` (``b`` has p rows).
inline void apply_q(const ConstMatrixRef& qr, const ConstVectorRef& tau, MatrixRef b) {
  for (Index j = tau.size() - 1; j >= 0; --j) apply_reflector(qr, tau(j), j, b);
}

//! One-sided Jacobi (Hestenes): rotates the columns of ``x`` (p x q) until they are
//! orthogonal, so ``x_in = x_out v^T`` with ``v`` (q x q) orthogonal; the column norms
//! of ``x_out`` are the singular values. Accurate to the last digits of the small ones.
//! ``norms`` (q): workspace.
inline void jacobi_columns(MatrixRef x, MatrixRef v, VectorRef norms) {
  const Index q = x.cols();
  v.setIdentity();
  const double eps = std::numeric_limits<double>::epsilon();
  // a column below the rounding of the whole matrix is left alone: its singular value is
  // noise (far under the rank cut), and rotating it need not converge
  const double negligible = 64.0 * eps * eps * x.squaredNorm();
  // two columns count as orthogonal when their cosine is below eps (the closest match to
  // LAPACK's results); near a rank loss that can be below the rounding of a p-term dot
  // product and the sweeps never end (seen on sda10f_dual), so after 100 sweeps the
  // cosine need only be below sqrt(p) eps, LAPACK dgesvj's tolerance
  const double strict = eps, loose = std::sqrt(static_cast<double>(x.rows())) * eps;
  // the columns' squared norms, computed at each sweep's start and updated by each
  // rotation (``alpha - t gamma``, ``beta + t gamma``: exact in exact arithmetic)
  for (int sweep = 0; sweep < 130; ++sweep) {
    const double tolerance = sweep < 100 ? strict : loose;
    bool rotated = false;
    for (Index i = 0; i < q; ++i) norms(i) = x.col(i).squaredNorm();
    for (Index i = 0; i + 1 < q; ++i) {
      for (Index j = i + 1; j < q; ++j) {
        const double alpha = norms(i), beta = norms(j);
        const double gamma = x.col(i).dot(x.col(j));
        if (!(std::abs(gamma) > tolerance * std::sqrt(alpha * beta)) || alpha <= negligible ||
            beta <= negligible)
          continue;
        rotated = true;
        const double zeta = (beta - alpha) / (2.0 * gamma);
        // sqrt(1 + zeta^2) where zeta^2 cannot overflow (hypot's cost without its need)
        const double root = std::abs(zeta) < 1e150 ? std::sqrt(1.0 + zeta * zeta) : std::abs(zeta);
        const double t = std::copysign(1.0, zeta) / (std::abs(zeta) + root);
        const double c = 1.0 / std::sqrt(1.0 + t * t), s = c * t;
        norms(i) = alpha - t * gamma;
        norms(j) = beta + t * gamma;
        // columns i, j <- (c x_i - s x_j, s x_i + c x_j), vectorised over the rows
        const Eigen::JacobiRotation<double> rotation(c, s);
        x.applyOnTheRight(i, j, rotation);
        v.applyOnTheRight(i, j, rotation);
      }
    }
    if (!rotated) return;
  }
  throw NoConvergence{};
}

//! Storage for :class:`ThinSvd` of matrices up to ``max_rows x max_cols`` (either way).
class ThinSvd {
 public:
  ThinSvd(Index max_rows, Index max_cols) {
    const Index large = std::max<Index>(1, std::max(max_rows, max_cols));
    const Index small = std::max<Index>(1, std::min(max_rows, max_cols));
    work_.resize(large, small);
    tau_.resize(small);
    square_.resize(small, small);
    rotations_.resize(small, small);
    u_.resize(max_rows > 0 ? max_rows : 1, small);
    v_.resize(max_cols > 0 ? max_cols : 1, small);
    s_.resize(small);
    norms_.resize(small);
  }

  //! ``m = U diag(s) V^T`` with ``t = min(p, q)`` singular values (unsorted), ``U``
  //! (p x t) and ``V`` (q x t): QR of the tall orientation, then Jacobi on its R.
  void compute(const ConstMatrixRef& m) {
    factor_qr(m);
    finish();
  }

  //! The first half of :func:`compute`: the Householder QR of the tall orientation of
  //! ``m`` (``m`` itself when ``p >= q``, else ``m^T``), read through :func:`qr` and
  //! :func:`tau`; :func:`finish` then completes the SVD from it.
  void factor_qr(const ConstMatrixRef& m) {
    rows_ = m.rows();
    cols_ = m.cols();
    const Index p = tall() ? rows_ : cols_, t = size();
    auto tall_copy = work_.topLeftCorner(p, t);
    if (tall()) tall_copy = m;
    else tall_copy = m.transpose();
    householder_qr(tall_copy, tau_.head(t));
  }

  //! The second half of :func:`compute`: Jacobi on the R of :func:`factor_qr`.
  void finish() {
    const bool tall = this->tall();
    const Index p = tall ? rows_ : cols_, t = size();
    auto tall_copy = work_.topLeftCorner(p, t);
    auto tau = tau_.head(t);
    auto r = square_.topLeftCorner(t, t);
    r = tall_copy.topRows(t).triangularView<Eigen::Upper>();
    auto rotations = rotations_.topLeftCorner(t, t);
    jacobi_columns(r, rotations, norms_.head(t));  // R = (R rotations) rotations^T, R rotations = U_R S
    // the tall orientation's left vectors: Q [U_R; 0]; its right vectors: the rotations
    auto left = (tall ? u_ : v_).topLeftCorner(p, t);
    auto right = (tall ? v_ : u_).topLeftCorner(t, t);
    left.setZero();
    for (Index j = 0; j < t; ++j) {
      const double norm = r.col(j).norm();
      s_(j) = norm;
      if (norm > 0.0) left.col(j).head(t) = r.col(j) / norm;
    }
    apply_q(tall_copy, tau, left);
    right = rotations;
  }

  Index size() const { return std::min(rows_, cols_); }
  //! Whether the factored matrix has at least as many rows as columns (its QR is its own).
  bool tall() const { return rows_ >= cols_; }
  //! The QR of :func:`factor_qr` in dgeqr2's layout (``max(p, q) x min(p, q)``).
  auto qr() const { return work_.topLeftCorner(std::max(rows_, cols_), size()); }
  auto tau() const { return tau_.head(size()); }
  auto u() const { return u_.topLeftCorner(rows_, size()); }
  auto v() const { return v_.topLeftCorner(cols_, size()); }
  auto s() const { return s_.head(size()); }
  double max_value() const { return size() ? s().maxCoeff() : 0.0; }
  double min_value() const { return size() ? s().minCoeff() : 0.0; }

 private:
  Matrix work_, square_, rotations_, u_, v_;
  Vector tau_, s_, norms_;
  Index rows_ = 0, cols_ = 0;
};

//! The Cholesky factor ``L`` of the symmetric positive definite ``matrix`` (its lower
//! triangle read) in place of its lower triangle; false at a pivot that is not positive
//! and finite. The matrices here are a few rows: no blocking, no allocation.
template <typename Square>
inline bool cholesky_in_place(Square&& matrix) {
  const Index n = matrix.rows();
  for (Index j = 0; j < n; ++j) {
    double pivot = matrix(j, j);
    for (Index k = 0; k < j; ++k) pivot -= matrix(j, k) * matrix(j, k);
    if (!(pivot > 0.0) || !std::isfinite(pivot)) return false;
    const double diagonal = std::sqrt(pivot);
    matrix(j, j) = diagonal;
    for (Index i = j + 1; i < n; ++i) {
      double sum = matrix(i, j);
      for (Index k = 0; k < j; ++k) sum -= matrix(i, k) * matrix(j, k);
      matrix(i, j) = sum / diagonal;
    }
  }
  return true;
}

//! ``b <- (L L^T)^-1 b`` for the lower triangle ``L`` of ``factor`` (cholesky_in_place).
template <typename Factor, typename Rhs>
inline void cholesky_solve(const Factor& factor, Rhs&& b) {
  const Index n = b.rows();
  for (Index i = 0; i < n; ++i) {  // L z = b
    double sum = b(i);
    for (Index k = 0; k < i; ++k) sum -= factor(i, k) * b(k);
    b(i) = sum / factor(i, i);
  }
  for (Index i = n - 1; i >= 0; --i) {  // L^T x = z
    double sum = b(i);
    for (Index k = i + 1; k < n; ++k) sum -= factor(k, i) * b(k);
    b(i) = sum / factor(i, i);
  }
}

//! ``|L^-1|_F^2`` for the lower triangle ``L`` of ``factor`` (cholesky_in_place), its
//! inverse's columns built in ``scratch`` (n x n): ``1 /`` it is at most the smallest
//! eigenvalue of ``L L^T``.
template <typename Factor, typename Scratch>
inline double lower_inverse_norm2(const Factor& factor, Scratch&& scratch) {
  const Index n = factor.rows();
  double sum = 0.0;
  for (Index k = 0; k < n; ++k) {
    for (Index i = k; i < n; ++i) {
      double value = i == k ? 1.0 : 0.0;
      for (Index j = k; j < i; ++j) value -= factor(i, j) * scratch(j, k);
      scratch(i, k) = value / factor(i, i);
      sum += scratch(i, k) * scratch(i, k);
    }
  }
  return sum;
}

}  // namespace cjm
