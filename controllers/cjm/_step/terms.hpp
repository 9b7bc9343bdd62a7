// Each constraint's per-step terms, computed from what it declares
// (controllers/cjm/compiled_forms.py, docs/design.md section 16): one function per kind, the same
// math and the same choices as the Python reference (constraints/*.py evaluate,
// constraints.base.structure_nullspace / structure_paper / perpendicular_basis,
// controllers.cjm.analytical.write_terms).
//
// A constraint's flat terms buffer: terms_layout.hpp.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>

#include "dense.hpp"
#include "pose_row.hpp"

namespace cjm {

//! The kinds of terms the extension computes, by their declared names.
enum class TermsKind : int { hole = 0, plane, point_lock };

//! The declared parameters of one constraint (controllers/cjm/compiled_forms.py), by kind:
//!   hole:       center (3, world), velocity (3, world), link_axis (3, link), gain
//!   plane:      link_point (3, link), plane_point (3, world), normal (3, world),
//!               velocity (3, world), gain  (a barrier: the same, its plan an inequality)
//!   point_lock: link_point (3, link), target (3, world), velocity (3, world), gain
constexpr Index kMaxParameters = 13;
using Parameters = Eigen::Matrix<double, kMaxParameters, 1>;

//! ``kind``'s value for a declared name; std::invalid_argument naming the known kinds else.
TermsKind terms_kind(const std::string& name);
//! The kind's name and the number of parameters it declares.
const char* kind_name(TermsKind kind);
Index parameter_count(TermsKind kind);
//! Rows k of a kind's terms (2, 1, 3).
Index kind_rows(TermsKind kind);
//! The drift-feedback gain K among the declared parameters (every kind's last entry).
double declared_gain(TermsKind kind, const Parameters& parameters);

//! Checks ``values`` (``size`` entries) against ``kind``'s declaration and copies them to
//! ``parameters``: std::invalid_argument naming the field for a wrong size, a non-finite
//! entry, an axis or normal whose norm is more than ``unit_tolerance`` from 1
//! (controllers.cjm.compiled_forms.UNIT_TOLERANCE), or a negative gain.
void load_parameters(TermsKind kind, const double* values, Index size, double unit_tolerance,
                     Parameters& parameters);

//! Writes one constraint's terms at its link's placement (a pose row of
//! Kinematics::placements) into ``terms`` (terms_size(k) entries, terms_layout.hpp). ``paper``: the hole's structure matrix in the paper's parametrisation (eqs
//! 11-13) where it is defined (``|p| >= paper_min_a``); returns false when it is not
//! (the null-space one written instead, as controllers.cjm.compiled falls back).
//! ``gap``: the first row's error ``e``, an inequality's damper gap (docs/design.md 12);
//! ``error_norm``: ``|e|``, an equality's violation (constraints.base.Constraint.violation).
bool write_terms(TermsKind kind, const Parameters& parameters, const Rotation& rotation,
                 const Translation& translation, bool paper, double paper_min_a, double* terms,
                 double& gap, double& error_norm);

}  // namespace cjm
