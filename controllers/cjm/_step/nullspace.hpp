// The null space of stacked constraint rows, kept as Householder reflectors: the C++ twin
// of controllers/linalg.py's nullspace (docs/design.md sections 4.5 and 16).
//
// ``A^T = Q [R1; 0]`` (QR of the n x m transpose). A certified bound decides the common
// full-rank case without an SVD: ``sigma_min(A) >= 1 / ||R1^-1||_F``. Otherwise
// ``R1 = U_R S V_R^T`` gives A's singular values, so the rank is decided on the same
// numbers as the Python's SVD of A. The basis ``N = Q [U_c 0; 0 I]`` (``U_c`` completing
// the kept columns of ``U_R``) is never formed: products with it cost one pass of the
// reflectors.
#pragma once

#include "dense.hpp"
#include "damped.hpp"

namespace cjm {

class NullSpace {
 public:
  //! ``rank_tolerance``: singular values at or below it times ``max(1, sigma_max)``
  //! count as zero (controllers.linalg's rank_tolerance).
  NullSpace(Index max_rows, Index max_cols, double rank_tolerance)
      : rank_tolerance_(rank_tolerance), factored_(std::max<Index>(1, max_cols), std::max<Index>(1, max_rows)),
        tau_(std::max<Index>(1, std::min(max_rows, max_cols))),
        inverse_(std::max<Index>(1, max_rows), std::max<Index>(1, max_rows)),
        svd_(std::max<Index>(1, std::min(max_rows, max_cols)), std::max<Index>(1, max_rows)),
        kept_(std::max<Index>(1, max_rows)),
        kept_vectors_(std::max<Index>(1, max_rows), std::max<Index>(1, max_rows)),
        complement_(std::max<Index>(1, max_rows), std::max<Index>(1, max_rows)),
        complement_tau_(std::max<Index>(1, max_rows)),
        weights_(std::max<Index>(1, max_rows)) {}

  //! Factor ``rows`` (m x n).
  void factor(const ConstMatrixRef& rows) {
    m_ = rows.rows();
    n_ = rows.cols();
    t_ = std::min(m_, n_);
    n_kept_ = n_dropped_ = 0;
    if (m_ == 0) return;
    auto a_t = factored_.topLeftCorner(n_, m_);
    a_t = rows.transpose();
    householder_qr(a_t, tau_.head(t_));
    full_rank_ = m_ <= n_ && certified_full_rank();
    if (full_rank_) {
      n_kept_ = m_;
      return;
    }
    auto r1 = inverse_.topLeftCorner(t_, m_);  // reused as R1's storage
    r1 = a_t.topRows(t_).triangularView<Eigen::Upper>();
    svd_.compute(r1);
    const double tolerance = rank_tolerance_ * std::max(1.0, svd_.max_value());
    for (Index j = 0; j < t_; ++j)
      if (svd_.s()(j) > tolerance) kept_(n_kept_++) = j;
    n_dropped_ = t_ - n_kept_;
    // the dropped directions: an orthonormal complement of the kept left vectors in R^t
    // (the left vectors of zero singular values are not defined by the SVD)
    auto kept = kept_vectors_.topLeftCorner(t_, n_kept_);
    for (Index i = 0; i < n_kept_; ++i) kept.col(i) = svd_.u().col(kept_(i));
    householder_qr(kept, complement_tau_.head(n_kept_));
    auto complement = complement_.topLeftCorner(t_, n_dropped_);
    complement.setZero();
    complement.bottomRows(n_dropped_).setIdentity();
    apply_q(kept, complement_tau_.head(n_kept_), complement);
  }

  Index rank() const { return n_kept_; }
  //! Dimension of the null space, ``n - rank``.
  Index dimension() const { return n_ - n_kept_; }

  //! ``x = A^+ b`` (x: n).
  void pseudo_solve(const ConstVectorRef& b, VectorRef x) {
    x.setZero();
    if (m_ == 0) return;
    auto head = x.head(t_);
    if (full_rank_) {  // A = R1^T Q1^T: A^+ b = Q1 R1^-T b
      head = b;
      factored_.topLeftCorner(m_, m_).triangularView<Eigen::Upper>().transpose().solveInPlace(head);
    } else {  // A^T = (Q1 U_R) S V_R^T
      for (Index i = 0; i < n_kept_; ++i) {
        const Index j = kept_(i);
        weights_(i) = svd_.v().col(j).dot(b) / svd_.s()(j);
      }
      for (Index i = 0; i < n_kept_; ++i) head += weights_(i) * svd_.u().col(kept_(i));
    }
    apply_q(factored_.topLeftCorner(n_, m_), tau_.head(t_), x);
  }

  //! ``y = N^T x`` for each column (x: n x c, y: (n - rank) x c); ``x`` is overwritten.
  void to_null(MatrixRef x, MatrixRef y) {
    if (m_ == 0) {
      y = x;
      return;
    }
    apply_qt(factored_.topLeftCorner(n_, m_), tau_.head(t_), x);
    for (Index i = 0; i < n_dropped_; ++i)
      y.row(i).noalias() = complement_.col(i).head(t_).transpose() * x.topRows(t_);
    y.bottomRows(n_ - t_) = x.bottomRows(n_ - t_);
  }

  //! ``x = N y`` (y: n - rank, x: n).
  void from_null(const ConstVectorRef& y, VectorRef x) {
    if (m_ == 0) {
      x = y;
      return;
    }
    x.head(t_).setZero();
    for (Index i = 0; i < n_dropped_; ++i) x.head(t_) += y(i) * complement_.col(i).head(t_);
    x.tail(n_ - t_) = y.tail(n_ - t_);
    apply_q(factored_.topLeftCorner(n_, m_), tau_.head(t_), x);
  }

 private:
  //! ``1 / ||R1^-1||_F`` (a lower bound on sigma_min) above the rank tolerance with
  //! ``||R1||_F`` (an upper bound on sigma_max): full rank for the Python's rule too.
  bool certified_full_rank() {
    auto inverse = inverse_.topLeftCorner(m_, m_);
    upper_inverse(factored_, inverse);
    const double bound = 1.0 / inverse.norm();
    double largest2 = 0.0;  // ||R1||_F^2
    for (Index j = 0; j < m_; ++j) largest2 += factored_.col(j).head(j + 1).squaredNorm();
    const double largest = std::sqrt(largest2);
    return std::isfinite(bound) && bound > rank_tolerance_ * std::max(1.0, largest);
  }

  double rank_tolerance_;
  Matrix factored_;  // A^T's QR (n x m)
  Vector tau_;
  Matrix inverse_;   // R1^-1 for the certificate, else R1 for its SVD
  ThinSvd svd_;
  Eigen::Matrix<Index, Eigen::Dynamic, 1> kept_;
  Matrix kept_vectors_, complement_;  // U_R's kept columns (QR-factored); their complement
  Vector complement_tau_;
  Vector weights_;
  Index m_ = 0, n_ = 0, t_ = 0, n_kept_ = 0, n_dropped_ = 0;
  bool full_rank_ = false;
};

}  // namespace cjm
