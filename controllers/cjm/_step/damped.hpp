// Damped least squares with the rising damping of paper eq 35: the C++ twin of
// controllers/linalg.py's DampingPolicy and damped_least_squares (docs/design.md sections
// 4.2 and 16). The decomposition is chosen by the problem (section 16, "the decomposition
// chosen by the problem"): the QR of the matrix's tall orientation solves it when a
// certified bound shows it well conditioned, the thin SVD only otherwise.
#pragma once

#include <Eigen/Eigenvalues>

#include "dense.hpp"

namespace cjm {

//! ``lambda^2 = damping^2 + max_damping^2 (1 - (sigma_min / threshold)^2)`` below the
//! threshold (controllers.linalg.DampingPolicy).
struct DampingPolicy {
  double damping = 0.0;
  double threshold = 0.01;
  double max_damping = 0.05;

  double lambda_squared(double sigma_min) const {
    double lam2 = damping * damping;
    if (sigma_min < threshold) {
      const double ratio = sigma_min / threshold;
      lam2 += max_damping * max_damping * (1.0 - ratio * ratio);
    }
    return lam2;
  }
};

//! ``x = J^T (J J^T + lambda^2 I)^-1 r`` for one or more right-hand sides, with what
//! controllers.linalg.DampedSolution reports: sigma_min, lambda, the rank (singular
//! values kept), the row space and whether the solution is exact.
//!
//! Every factorisation starts with the QR of the tall orientation, ``T = Q [R; 0]``
//! (``T = J`` when J has at least as many rows as columns, else ``J^T``). When
//! ``1 / ||R^-1||_F`` (a lower bound on sigma_min) clears the rank cut, with no constant
//! damping and ``||R||_F ||R^-1||_F <=`` kMaxConditionBound, the SVD's rank decision is
//! known without it: full rank, the row space ``I`` (tall J) or Q's first ``p`` columns
//! (wide J). sigma_min is then ``1 / sqrt(lambda_max(R^-T R^-1))``: a certified power
//! iteration, or where it would not certify soon (close smallest singular values) the
//! symmetric eigenvalue problem of size ``min(p, q)`` (Eigen's, fixed-size storage),
//! computed when asked for. If the bound is also at least the policy's threshold,
//! ``lambda = 0`` whatever sigma_min: ``x = R^-1 (Q^T r)_head`` (tall J: its least
//! squares) or ``x = Q [R^-T r; 0]`` (wide J: its minimum norm). Below the threshold
//! lambda follows sigma_min (eq 35), whether sigma_min is asked for first (the damping rows
//! of the saturation around the previous command, docs/design.md 9.1) or a solve is: that
//! solve is the damped least squares on R (damped_by_qr), no SVD. When the bound fails the
//! Jacobi SVD of R finishes the thin SVD and decides everything.
class DampedLeastSquares {
 public:
  //! Largest ``min(p, q)`` the QR path takes (its ``R^-1`` and Gram are fixed-size).
  static constexpr int kMaxQrSize = 16;
  //! Largest ``||R||_F ||R^-1||_F`` (>= the condition number) the QR path takes: its
  //! sigma_min, from the computed ``R^-1``, is then within about ``t eps kappa`` (< 1e-11)
  //! relative of the SVD's, far inside the 1e-9 the two backends are held to.
  static constexpr double kMaxConditionBound = 1e4;

  //! Singular values at or below ``rank_tolerance`` times ``max(1, sigma_max)`` count
  //! as zero (controllers.linalg's rank_tolerance).
  DampedLeastSquares(Index max_rows, Index max_cols, double rank_tolerance)
      : rank_tolerance_(rank_tolerance), svd_(max_rows, max_cols), gains_(std::max<Index>(1, std::min(max_rows, max_cols))),
        projected_(std::max<Index>(1, std::max(max_rows, max_cols)), 2),
        row_space_(std::max<Index>(1, max_cols), std::max<Index>(1, std::min(max_rows, max_cols))) {}

  //! Factor ``matrix`` (p x q) for the policy: its QR, and its SVD unless the QR's
  //! certificate decides the rank (class comment).
  void factor(const ConstMatrixRef& matrix, const DampingPolicy& policy) {
    rows_ = matrix.rows();
    cols_ = matrix.cols();
    policy_ = policy;
    svd_.factor_qr(matrix);
    svd_ready_ = false;
    damped_triangle_ready_ = false;
    if (policy.damping == 0.0 && certified_full_rank()) {
      row_space_ready_ = false;
      rank_ = svd_.size();
      if (bound_ >= policy.threshold) {  // lambda = 0 whatever sigma_min
        decision_ = Decision::undamped;
        sigma_known_ = false;
        damping_ = 0.0;
        exact_ = rank_ == rows_;
      } else {
        decision_ = Decision::open;
      }
      return;
    }
    finish_svd();
  }

  //! ``x`` for each column of ``rhs`` (at most 2): the class's triangular solves when
  //! lambda is 0 after the QR alone, else ``V diag(gains) U^T rhs`` after the SVD.
  void solve(const ConstMatrixRef& rhs, MatrixRef x) {
    const Index t = svd_.size();
    decide();  // an open decision on the certified sigma_min, as when it is asked for first
    if (decision_ == Decision::undamped) {
      const auto r = svd_.qr().topRows(t).triangularView<Eigen::Upper>();
      if (svd_.tall()) {  // J = Q [R; 0]: x = R^-1 (Q^T r)_head
        auto projected = projected_.topLeftCorner(rows_, rhs.cols());
        projected = rhs;
        apply_qt(svd_.qr(), svd_.tau(), projected);
        x = projected.topRows(t);
        upper_solve(svd_.qr(), x);
      } else {  // J^T = Q [R; 0]: x = Q [R^-T r; 0]
        x.topRows(t) = rhs;
        r.transpose().solveInPlace(x.topRows(t));
        x.bottomRows(cols_ - t).setZero();
        apply_q(svd_.qr(), svd_.tau(), x);
      }
      return;
    }
    if (decision_ == Decision::damped) {
      damped_by_qr(rhs, x);
      return;
    }
    auto projected = projected_.topLeftCorner(t, rhs.cols());
    projected.noalias() = svd_.u().transpose() * rhs;
    projected = gains_.head(t).asDiagonal() * projected;
    x.noalias() = svd_.v() * projected;
  }

  //! The smallest singular value kept.
  double sigma_min() {
    decide();
    if (!sigma_known_) {
      sigma_min_ = certified_sigma_min();
      sigma_known_ = true;
    }
    return sigma_min_;
  }
  //! lambda (0 when the solution is the plain least squares / minimum norm).
  double damping() {
    decide();
    return damping_;
  }
  //! Whether sigma_min() is still to compute and nothing decided needs it (the undamped
  //! QR solve): it can wait until it is read.
  bool sigma_min_deferrable() const { return decision_ == Decision::undamped && !sigma_known_; }
  //! Whether lambda is 0 with the QR's rank decision (the solve R's triangular one,
  //! whatever the policy's threshold): a policy without damping factors to the same solve.
  bool undamped_by_qr() const { return decision_ == Decision::undamped; }
  Index rank() const { return rank_; }
  bool exact() {
    decide();
    return exact_;
  }
  //! Whether the last factorisation has needed no SVD so far.
  bool by_qr() const { return !svd_ready_; }
  //! An orthonormal basis of the row space (as columns): the right singular vectors with
  //! a kept singular value after the SVD's decision, else ``I`` (tall J) or Q's first
  //! ``p`` columns (wide J), formed at the first call.
  auto row_space() {
    if (!row_space_ready_) {
      auto basis = row_space_.topLeftCorner(cols_, rank_);
      basis.setZero();
      basis.topRows(rank_).setIdentity();
      if (!svd_.tall()) apply_q(svd_.qr(), svd_.tau(), basis);
      row_space_ready_ = true;
    }
    return row_space_.topLeftCorner(cols_, rank_);
  }

  //! ``b <- (J^T J + lambda^2 I)^-1 b`` for each column, J tall (``J = Q1 R``) with the
  //! figures decided on the QR: the normal equations on ``R`` undamped, on damped_by_qr's
  //! ``R2`` damped (their condition at most kMaxConditionBound squared). False, ``b``
  //! untouched, for a wide J or after the SVD.
  bool gram_solve(MatrixRef b) {
    decide();
    if (!svd_.tall() || decision_ == Decision::svd) return false;
    if (decision_ == Decision::damped) {
      build_damped_triangle();
      normal_solve(damped_triangle_, b);
    } else {
      normal_solve(svd_.qr(), b);
    }
    return true;
  }

 private:
  using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxQrSize, kMaxQrSize>;

  //! What decided the figures: the SVD; the QR with lambda = 0; the QR with lambda still
  //! to come from sigma_min (open) or come from it and positive (damped).
  enum class Decision { svd, undamped, open, damped };

  //! The class's test on the R of the QR (``R^-1`` and its norm kept for sigma_min).
  bool certified_full_rank() {
    const Index t = svd_.size();
    if (t == 0 || t > kMaxQrSize) return false;
    inverse_.resize(t, t);  // fixed-size storage: no heap
    upper_inverse(svd_.qr(), inverse_);
    inverse_norm_ = inverse_.norm();
    double largest2 = 0.0;  // ||R||_F^2 (>= sigma_max^2)
    for (Index j = 0; j < t; ++j) largest2 += svd_.qr().col(j).head(j + 1).squaredNorm();
    const double largest = std::sqrt(largest2);
    bound_ = 1.0 / inverse_norm_;  // <= sigma_min
    return std::isfinite(bound_) && bound_ > rank_tolerance_ * std::max(1.0, largest) &&
           largest * inverse_norm_ <= kMaxConditionBound;
  }

  //! An open decision taken on the certified sigma_min: eq 35's lambda.
  void decide() {
    if (decision_ != Decision::open) return;
    sigma_min_ = certified_sigma_min();
    sigma_known_ = true;
    const double lam2 = policy_.lambda_squared(sigma_min_);
    damping_ = std::sqrt(lam2);
    exact_ = lam2 == 0.0 && rank_ == rows_;
    decision_ = lam2 == 0.0 ? Decision::undamped : Decision::damped;
  }

  //! The damped solve on the QR alone (full rank certified, lambda > 0): ``x`` minimises
  //! ``|J x - r|^2 + lambda^2 |x|^2``, which is ``V diag(s / (s^2 + lambda^2)) U^T r``
  //! (docs/design.md 4.2) without the SVD. Tall J (``J = Q1 R``): ``x = u``; wide J
  //! (``J = R^T Q1^T``): ``x = Q [u; 0]``; ``u`` solves ``(M^T M + lambda^2 I) u = M^T y``
  //! with ``M = R, y = Q1^T r`` (tall) or ``M = R^T, y = r`` (wide). It is solved in the
  //! order-reversed coordinates when wide (``P`` reverses the order: ``P R^T P`` is upper
  //! triangular, and ``u = P u~`` with ``(M~^T M~ + lambda^2 I) u~ = M~^T P y``), so ``M~``
  //! is upper triangular either way. ``M~^T M~ + lambda^2 I = R2^T R2``, R2 the triangle of
  //! the QR of ``[M~; lambda I]``, each row of ``lambda I`` rotated into ``M~`` by Givens
  //! rotations (the structure of MINPACK's qrsolv: t (t + 1) / 2 rotations, no work on the
  //! zeros that a Householder QR of the stack, 8.3k instructions a solve, spent most of
  //! its arithmetic on); the semi-normal equations on R2 and one step of refinement on their
  //! residual (Bjorck's corrected semi-normal equations: within about ``eps kappa`` of the
  //! SVD's gains, where the plain QR of the stack loses ``eps kappa^2 |residual| / |x|``
  //! when the residual dominates, as it does damped). Saves the Jacobi SVD of each damped
  //! general step (issue 32: fast-lateral with acceleration limits).
  void damped_by_qr(const ConstMatrixRef& rhs, MatrixRef x) {
    const Index t = svd_.size(), c = rhs.cols();
    const bool tall = svd_.tall();
    const auto& qr = svd_.qr();
    const auto& m = triangle_;
    const auto& r2 = damped_triangle_;
    build_damped_triangle();
    auto y = small_rhs_.topLeftCorner(t, c);
    if (tall) {
      auto projected = projected_.topLeftCorner(rows_, c);
      projected = rhs;
      apply_qt(qr, svd_.tau(), projected);
      y = projected.topRows(t);
    } else {
      for (Index k = 0; k < c; ++k)
        for (Index i = 0; i < t; ++i) y(i, k) = rhs(t - 1 - i, k);
    }
    auto u = solution_.topLeftCorner(t, c);
    auto normal = normal_rhs_.topLeftCorner(t, c);
    auto residual = residual_.topLeftCorner(t, c);
    for (Index k = 0; k < c; ++k)  // M~^T y
      for (Index j = 0; j < t; ++j) {
        double sum = 0.0;
        for (Index i = 0; i <= j; ++i) sum += m(i, j) * y(i, k);
        normal(j, k) = sum;
      }
    normal_solve(r2, normal);
    u = normal;
    for (Index k = 0; k < c; ++k) {  // the refinement: M~^T (y - M~ u) - lambda^2 u
      for (Index i = 0; i < t; ++i) {
        double sum = y(i, k);
        for (Index j = i; j < t; ++j) sum -= m(i, j) * u(j, k);
        residual(i, k) = sum;
      }
      for (Index j = 0; j < t; ++j) {
        double sum = -damping_ * damping_ * u(j, k);
        for (Index i = 0; i <= j; ++i) sum += m(i, j) * residual(i, k);
        normal(j, k) = sum;
      }
    }
    normal_solve(r2, normal);
    u += normal;
    if (tall) {
      x.topRows(t) = u;
    } else {
      for (Index k = 0; k < c; ++k)
        for (Index i = 0; i < t; ++i) x(i, k) = u(t - 1 - i, k);
      x.bottomRows(cols_ - t).setZero();
      apply_q(qr, svd_.tau(), x);
    }
  }

  //! damped_by_qr's M~ and R2, once a factorisation.
  void build_damped_triangle() {
    if (damped_triangle_ready_) return;
    damped_triangle_ready_ = true;
    const Index t = svd_.size();
    const bool tall = svd_.tall();
    const auto& qr = svd_.qr();
    auto& m = triangle_;  // M~, its upper triangle only
    for (Index j = 0; j < t; ++j)
      for (Index i = 0; i <= j; ++i) m(i, j) = tall ? qr(i, j) : qr(t - 1 - j, t - 1 - i);
    auto& r2 = damped_triangle_;
    for (Index j = 0; j < t; ++j)
      for (Index i = 0; i <= j; ++i) r2(i, j) = m(i, j);
    auto& row = rotated_row_;
    for (Index k = 0; k < t; ++k) {  // the row lambda e_k^T, rotated into R2 from column k on
      row(k) = damping_;
      for (Index l = k + 1; l < t; ++l) row(l) = 0.0;
      for (Index j = k; j < t; ++j) {
        const double lower = row(j);
        if (lower == 0.0) continue;
        // no hypot: R2's diagonal is at least sigma_min(R), certified above the rank cut,
        // and lambda at most max_damping: the squares neither overflow nor underflow
        const double upper = r2(j, j), length = std::sqrt(upper * upper + lower * lower);
        const double cosine = upper / length, sine = lower / length;
        r2(j, j) = length;
        for (Index l = j + 1; l < t; ++l) {
          const double above = r2(j, l), below = row(l);
          r2(j, l) = cosine * above + sine * below;
          row(l) = cosine * below - sine * above;
        }
      }
    }
  }

  //! ``b <- (R2^T R2)^-1 b`` for the upper triangle R2 of ``factored``'s leading block.
  template <typename Factored, typename Rhs>
  static void normal_solve(const Factored& factored, Rhs& b) {
    const Index t = b.rows();
    for (Index k = 0; k < b.cols(); ++k)  // R2^T z = b, forward
      for (Index i = 0; i < t; ++i) {
        double sum = b(i, k);
        for (Index j = 0; j < i; ++j) sum -= factored(j, i) * b(j, k);
        b(i, k) = sum / factored(i, i);
      }
    upper_solve(factored, b);
  }

  //! The Jacobi SVD of R finishes the thin SVD and decides every figure.
  void finish_svd() {
    svd_.finish();
    svd_ready_ = true;
    decision_ = Decision::svd;
    sigma_known_ = true;
    row_space_ready_ = true;
    const auto s = svd_.s();
    const double tolerance = rank_tolerance_ * std::max(1.0, svd_.max_value());
    // sigma_min: the smallest value kept (a direction not seen at all is not damped)
    sigma_min_ = 0.0;
    for (Index j = 0; j < s.size(); ++j) {
      if (s(j) > tolerance) sigma_min_ = sigma_min_ == 0.0 ? s(j) : std::min(sigma_min_, s(j));
    }
    const double lam2 = policy_.lambda_squared(sigma_min_);
    damping_ = std::sqrt(lam2);
    rank_ = 0;
    for (Index j = 0; j < s.size(); ++j) {
      const bool keep = s(j) > tolerance;
      gains_(j) = keep ? s(j) / (s(j) * s(j) + lam2) : 0.0;
      if (keep) row_space_.col(rank_++).head(cols_) = svd_.v().col(j);
    }
    exact_ = lam2 == 0.0 && rank_ == rows_;
  }

  //! ``1 / sqrt(lambda_max(R^-T R^-1))`` from the ``R^-1`` of :func:`certified_full_rank`.
  double certified_sigma_min() {
    gram_.noalias() = inverse_.transpose() * inverse_;  // R^-T R^-1: eigenvalues 1 / sigma_i^2
    double largest_eigenvalue = power_iteration(inverse_norm_ * inverse_norm_);
    if (!(largest_eigenvalue > 0.0)) {  // not certified: the symmetric eigenvalue problem
      eigen_.compute(gram_, Eigen::EigenvaluesOnly);
      largest_eigenvalue = eigen_.eigenvalues()(gram_.rows() - 1);
    }
    return 1.0 / std::sqrt(largest_eigenvalue);
  }

  //! The largest eigenvalue of ``gram_`` (symmetric positive definite, ``trace`` its
  //! trace) by power iteration, certified by Kato and Temple's bound: for a unit ``v``,
  //! ``rho = v^T G v`` and ``e = |G v - rho v|``, every other eigenvalue is at most
  //! ``trace - lambda_max <= trace - rho``, so when ``2 rho > trace``
  //! ``rho <= lambda_max <= rho + e^2 / (2 rho - trace)``. It stops when that width is
  //! below kPowerWidth relative, and gives up (0) when the residual's contraction
  //! would not get there within kMaxPowerSteps.
  double power_iteration(double trace) {
    const Index t = gram_.rows();
    Index start = 0;
    gram_.diagonal().maxCoeff(&start);
    auto v = power_vector_.head(t);
    auto w = power_product_.head(t);
    v = gram_.col(start) / gram_.col(start).norm();
    double previous = 0.0;
    for (int step = 0; step < kMaxPowerSteps; ++step) {
      w.noalias() = gram_ * v;
      const double rho = v.dot(w);
      const double gap = 2.0 * rho - trace;
      v = w - rho * v;  // the residual, in place
      const double residual2 = v.squaredNorm();
      const double target = kPowerWidth * rho * std::max(gap, 0.0);
      if (gap > 0.0 && residual2 <= target) return rho;
      if (step >= 3 && residual2 > 0.0 && previous > 0.0) {  // steps left at this contraction
        const double contraction = residual2 / previous;
        if (!(contraction < 1.0) ||
            (gap > 0.0 && step + std::log(target / residual2) / std::log(contraction) > kMaxPowerSteps))
          return 0.0;
      }
      previous = residual2;
      v = w / w.norm();
    }
    return 0.0;
  }

  //! Relative width of the certified interval at which the power iteration stops, 100
  //! ulps (sigma_min's relative error is half of it; the step's own tolerances come from
  //! controllers/cjm/tolerances.py, this is the algorithm's accuracy).
  static constexpr double kPowerWidth = 100.0 * std::numeric_limits<double>::epsilon();
  static constexpr int kMaxPowerSteps = 40;

  double rank_tolerance_;
  DampingPolicy policy_;
  ThinSvd svd_;
  Vector gains_;
  Matrix projected_, row_space_;
  //! damped_by_qr's M~ and R2 (t x t, upper triangles), read some 250 times a solve:
  //! fixed-size storage, not selected from the QR at each read
  Eigen::Matrix<double, kMaxQrSize, kMaxQrSize> triangle_, damped_triangle_;
  Eigen::Matrix<double, kMaxQrSize, 1> rotated_row_;  // a row of lambda I being rotated in
  //! damped_by_qr's y, u, its normal equations' right-hand side and residual (t x c)
  Eigen::Matrix<double, kMaxQrSize, 2> small_rhs_, solution_, normal_rhs_, residual_;
  SmallMatrix inverse_, gram_;
  Eigen::SelfAdjointEigenSolver<SmallMatrix> eigen_{kMaxQrSize};
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxQrSize, 1> power_vector_{kMaxQrSize},
      power_product_{kMaxQrSize};
  Index rows_ = 0, cols_ = 0, rank_ = 0;
  double sigma_min_ = 0.0, damping_ = 0.0;
  double inverse_norm_ = 0.0, bound_ = 0.0;  // ||R^-1||_F and 1 / ||R^-1||_F
  Decision decision_ = Decision::svd;
  bool exact_ = false, svd_ready_ = false, row_space_ready_ = true, sigma_known_ = true;
  bool damped_triangle_ready_ = false;  // triangle_ and damped_triangle_ of this factorisation
};

}  // namespace cjm
