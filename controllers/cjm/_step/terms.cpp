// Each constraint's per-step terms; see terms.hpp.
#include "terms.hpp"
#include "terms_layout.hpp"

#include <cmath>
#include <stdexcept>

namespace cjm {

namespace {

using Vector3 = Eigen::Vector3d;
//! Up to three rows of 3 (C, C_perp): fixed storage, no heap.
using Rows3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor, 3, 3>;
using Small = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1>;

//! constraints.base.ConstraintPoint: all in the link's frame F_a.
struct Point {
  Vector3 p;
  Rows3 C, C_perp;
  Small rhs;
  double first_error = 0.0;  // the first row's error
  double error_norm = 0.0;   // |error|: constraints.base.Constraint.violation
};

struct Field {
  const char* name;
  Index offset, size;
  bool unit;
};

constexpr Field kHoleFields[] = {{"center", 0, 3, false}, {"velocity", 3, 3, false},
                                 {"link_axis", 6, 3, true}, {"gain", 9, 1, false}};
constexpr Field kPlaneFields[] = {{"link_point", 0, 3, false}, {"plane_point", 3, 3, false},
                                  {"normal", 6, 3, true}, {"velocity", 9, 3, false},
                                  {"gain", 12, 1, false}};
constexpr Field kLockFields[] = {{"link_point", 0, 3, false}, {"target", 3, 3, false},
                                 {"velocity", 6, 3, false}, {"gain", 9, 1, false}};

Eigen::Matrix3d hat(const Vector3& p) {
  Eigen::Matrix3d skew;
  skew << 0.0, -p(2), p(1), p(2), 0.0, -p(0), -p(1), p(0), 0.0;
  return skew;
}

//! constraints.base.perpendicular_basis: two orthonormal rows perpendicular to the unit
//! ``axis``, from the world axis of its smallest entry (the first such), by cross products.
Eigen::Matrix<double, 2, 3, Eigen::RowMajor> perpendicular_basis(const Vector3& axis) {
  Index smallest = 0;
  axis.cwiseAbs().minCoeff(&smallest);
  const Vector3 first = axis.cross(Vector3::Unit(smallest)).normalized();
  Eigen::Matrix<double, 2, 3, Eigen::RowMajor> basis;
  basis.row(0) = first.transpose();
  basis.row(1) = axis.cross(first).transpose();
  return basis;
}

//! Hole (constraints/hole.py): ``x`` the centre in F_a, ``p = (e . x) e`` on the link
//! axis ``e``, ``C`` perpendicular to it, ``error = -C x``, ``rhs = C f - K error``.
Point hole_point(const Parameters& parameters, const Rotation& rotation,
                 const Translation& translation) {
  const Vector3 axis = parameters.segment<3>(6);
  const Vector3 x = rotation.transpose() * (parameters.segment<3>(0) - translation);
  Point point;
  point.p = axis.dot(x) * axis;
  point.C = perpendicular_basis(axis);
  point.C_perp = axis.transpose();
  const Small error = -(point.C * x);
  point.first_error = error(0);
  point.error_norm = error.norm();
  point.rhs = -parameters(9) * error;
  const Vector3 velocity = parameters.segment<3>(3);
  if ((velocity.array() != 0.0).any()) point.rhs += point.C * (rotation.transpose() * velocity);
  return point;
}

//! Plane (constraints/plane.py): ``C = (R^T n)^T`` at the link point, ``error`` the
//! point's signed distance ``n . (R p + t - x_0)``, ``rhs = n . v - K error``.
Point plane_point(const Parameters& parameters, const Rotation& rotation,
                  const Translation& translation) {
  const Vector3 link_point = parameters.segment<3>(0);
  const Vector3 normal = parameters.segment<3>(6);
  const Vector3 local_normal = rotation.transpose() * normal;
  Point point;
  point.p = link_point;
  point.C = local_normal.transpose();
  point.C_perp = perpendicular_basis(local_normal);
  const double error =
      normal.dot(rotation * link_point + translation - parameters.segment<3>(3));
  point.rhs.resize(1);
  point.rhs(0) = normal.dot(parameters.segment<3>(9)) - parameters(12) * error;
  point.first_error = error;
  point.error_norm = std::abs(error);
  return point;
}

//! PointLock (constraints/point_lock.py): ``C = R``, ``error = R p + t - target``,
//! ``rhs = v - K error``.
Point lock_point(const Parameters& parameters, const Rotation& rotation,
                 const Translation& translation) {
  const Vector3 link_point = parameters.segment<3>(0);
  Point point;
  point.p = link_point;
  point.C = rotation;
  point.C_perp.resize(0, 3);
  const Vector3 error = rotation * link_point + translation - parameters.segment<3>(3);
  point.rhs = parameters.segment<3>(6) - parameters(9) * error;
  point.first_error = error(0);
  point.error_norm = error.norm();
  return point;
}

//! constraints.base.structure_nullspace: ``[[C_perp^T, C^T C hat(p)], [0, I]]``.
void write_nullspace_structure(const Point& point, Eigen::Map<Matrix, 0, Eigen::OuterStride<6>> S) {
  const Index k = point.C.rows();
  S.setZero();
  S.topLeftCorner(3, 3 - k) = point.C_perp.transpose();
  S.topRightCorner(3, 3).noalias() = point.C.transpose() * (point.C * hat(point.p));
  S.bottomRightCorner(3, 3).setIdentity();
}

//! constraints.base.structure_paper for a hole (C perpendicular to p = a e): the
//! constrained linear velocities paired with ``(v_i / a) (c_i x e)``, then the free
//! directions (the complements of C and of the rows ``c_i x e``, both along ``e``;
//! Python's SVD may give them the other sign, a sign flip of a free variable that leaves
//! every command and singular value as it is).
void write_paper_structure(const Point& point, double a, Eigen::Map<Matrix, 0, Eigen::OuterStride<6>> S) {
  const Vector3 e = point.p / a;
  const Vector3 c0 = point.C.row(0).transpose(), c1 = point.C.row(1).transpose();
  const Vector3 d0 = c0.cross(e), d1 = c1.cross(e);
  S.setZero();
  S.block<3, 1>(0, 0) = c0;
  S.block<3, 1>(0, 1) = c1;
  S.block<3, 1>(3, 0) = d0 / a;
  S.block<3, 1>(3, 1) = d1 / a;
  S.block<3, 1>(0, 2) = c0.cross(c1);
  S.block<3, 1>(3, 3) = d0.cross(d1);
}

//! controllers.cjm.analytical.write_terms, the structure matrix chosen by the caller.
void write_point(const Point& point, double* terms) {
  const Index k = point.C.rows();
  auto V_a0 = pre_rhs_of(terms, k).col(0);
  V_a0.head(3).noalias() = point.C.transpose() * point.rhs;
  V_a0.tail(3).setZero();
  auto residual_rows = residual_rows_of(terms, k);
  residual_rows.col(0) = -point.rhs;
  residual_rows.middleCols(1, 3) = point.C;
  residual_rows.rightCols(3).noalias() = -(point.C * hat(point.p));
}

const Field* fields_of(TermsKind kind, Index& count) {
  switch (kind) {
    case TermsKind::hole: count = 4; return kHoleFields;
    case TermsKind::plane: count = 5; return kPlaneFields;
    case TermsKind::point_lock: count = 4; return kLockFields;
  }
  throw std::invalid_argument("unknown terms kind");
}

}  // namespace

TermsKind terms_kind(const std::string& name) {
  if (name == "hole") return TermsKind::hole;
  if (name == "plane") return TermsKind::plane;
  if (name == "point_lock") return TermsKind::point_lock;
  throw std::invalid_argument("compiled form: unknown kind '" + name +
                              "' (the extension computes 'hole', 'plane', 'point_lock')");
}

const char* kind_name(TermsKind kind) {
  switch (kind) {
    case TermsKind::hole: return "hole";
    case TermsKind::plane: return "plane";
    case TermsKind::point_lock: return "point_lock";
  }
  return "?";
}

Index parameter_count(TermsKind kind) {
  switch (kind) {
    case TermsKind::hole: return 10;
    case TermsKind::plane: return 13;
    case TermsKind::point_lock: return 10;
  }
  return 0;
}

Index kind_rows(TermsKind kind) {
  switch (kind) {
    case TermsKind::hole: return 2;
    case TermsKind::plane: return 1;
    case TermsKind::point_lock: return 3;
  }
  return 0;
}

void load_parameters(TermsKind kind, const double* values, Index size, double unit_tolerance,
                     Parameters& parameters) {
  const std::string prefix = std::string(kind_name(kind)) + " compiled parameters: ";
  if (size != parameter_count(kind))
    throw std::invalid_argument(prefix + "needs " + std::to_string(parameter_count(kind)) +
                                " entries, got " + std::to_string(size));
  Index count = 0;
  const Field* fields = fields_of(kind, count);
  for (Index f = 0; f < count; ++f) {
    const Field& field = fields[f];
    const Eigen::Map<const Vector> entries(values + field.offset, field.size);
    if (!entries.allFinite())
      throw std::invalid_argument(prefix + field.name + " must be finite");
    if (field.unit && !(std::abs(entries.norm() - 1.0) <= unit_tolerance))
      throw std::invalid_argument(prefix + field.name + " must be a unit vector");
    if (field.size == 1 && entries(0) < 0.0)
      throw std::invalid_argument(prefix + field.name + " must be >= 0");
  }
  parameters.head(size) = Eigen::Map<const Vector>(values, size);
}

double declared_gain(TermsKind kind, const Parameters& parameters) {
  return parameters(parameter_count(kind) - 1);
}

bool write_terms(TermsKind kind, const Parameters& parameters, const Rotation& rotation,
                 const Translation& translation, bool paper, double paper_min_a, double* terms,
                 double& gap, double& error_norm) {
  Point point;
  switch (kind) {
    case TermsKind::hole: point = hole_point(parameters, rotation, translation); break;
    case TermsKind::plane: point = plane_point(parameters, rotation, translation); break;
    case TermsKind::point_lock: point = lock_point(parameters, rotation, translation); break;
  }
  const Index k = point.C.rows();
  gap = point.first_error;
  error_norm = point.error_norm;
  write_point(point, terms);
  // S: pre_rhs's columns after V_a0 (terms_layout.hpp)
  Eigen::Map<Matrix, 0, Eigen::OuterStride<6>> S(pre_rhs_of(terms, k).col(1).data(), 6, 6 - k,
                                                Eigen::OuterStride<6>(6));
  const double a = point.p.norm();
  const bool paper_defined = paper && a >= paper_min_a;
  if (paper_defined)
    write_paper_structure(point, a, S);
  else
    write_nullspace_structure(point, S);
  return paper_defined || !paper;
}

}  // namespace cjm
