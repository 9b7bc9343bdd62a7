// Damped least squares with the rising damping of paper eq 35, through one thin SVD: the
// C++ twin of controllers/linalg.py's DampingPolicy and damped_least_squares
// (docs/design.md sections 4.2 and 16).
#pragma once

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
class DampedLeastSquares {
 public:
  //! Singular values at or below ``rank_tolerance`` times ``max(1, sigma_max)`` count
  //! as zero (controllers.linalg's rank_tolerance).
  DampedLeastSquares(Index max_rows, Index max_cols, double rank_tolerance)
      : rank_tolerance_(rank_tolerance), svd_(max_rows, max_cols), gains_(std::max<Index>(1, std::min(max_rows, max_cols))),
        projected_(std::max<Index>(1, std::min(max_rows, max_cols)), 2),
        row_space_(std::max<Index>(1, max_cols), std::max<Index>(1, std::min(max_rows, max_cols))) {}

  //! Factor ``matrix`` (p x q) and set the gains of the policy.
  void factor(const ConstMatrixRef& matrix, const DampingPolicy& policy) {
    svd_.compute(matrix);
    rows_ = matrix.rows();
    const auto s = svd_.s();
    const double tolerance = rank_tolerance_ * std::max(1.0, svd_.max_value());
    // sigma_min: the smallest value kept (a direction not seen at all is not damped)
    sigma_min_ = 0.0;
    for (Index j = 0; j < s.size(); ++j) {
      if (s(j) > tolerance) sigma_min_ = sigma_min_ == 0.0 ? s(j) : std::min(sigma_min_, s(j));
    }
    const double lam2 = policy.lambda_squared(sigma_min_);
    damping_ = std::sqrt(lam2);
    rank_ = 0;
    for (Index j = 0; j < s.size(); ++j) {
      const bool keep = s(j) > tolerance;
      gains_(j) = keep ? s(j) / (s(j) * s(j) + lam2) : 0.0;
      if (keep) row_space_.col(rank_++).head(matrix.cols()) = svd_.v().col(j);
    }
    exact_ = lam2 == 0.0 && rank_ == rows_;
  }

  //! ``x = V diag(gains) U^T rhs`` for each column of ``rhs`` (at most 2).
  void solve(const ConstMatrixRef& rhs, MatrixRef x) {
    const Index t = svd_.size();
    auto projected = projected_.topLeftCorner(t, rhs.cols());
    projected.noalias() = svd_.u().transpose() * rhs;
    projected = gains_.head(t).asDiagonal() * projected;
    x.noalias() = svd_.v() * projected;
  }

  double sigma_min() const { return sigma_min_; }
  double damping() const { return damping_; }
  Index rank() const { return rank_; }
  bool exact() const { return exact_; }
  //! Right singular vectors with a kept singular value (as columns).
  auto row_space() const { return row_space_.topLeftCorner(svd_.v().rows(), rank_); }

 private:
  double rank_tolerance_;
  ThinSvd svd_;
  Vector gains_;
  Matrix projected_, row_space_;
  Index rows_ = 0, rank_ = 0;
  double sigma_min_ = 0.0, damping_ = 0.0;
  bool exact_ = false;
};

}  // namespace cjm
