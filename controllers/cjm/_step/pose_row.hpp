// A pose as a row of 12 doubles, as the compiled kinematics, pipeline and tick hold them
// (docs/design.md section 16): the rotation row-major, then the translation; and the
// compiled tick's period row, one per EE. The one description of both layouts: the
// bindings (module.cpp) give Python the offsets (controllers/cjm/pose_rows.py reads them).
#pragma once

#include <Eigen/Core>

#include "dense.hpp"

namespace cjm {

//! Doubles in a pose row, and where its translation starts (after the 9 of the rotation).
constexpr Index kPoseRow = 12;
constexpr Index kPoseTranslation = 9;

//! The compiled tick's period row per EE: the filtered target, the previous period's
//! target, the EE placement (each a pose row), then the commanded twist (6).
constexpr Index kPeriodTarget = 0;
constexpr Index kPeriodPrevious = kPeriodTarget + kPoseRow;
constexpr Index kPeriodPlacement = kPeriodPrevious + kPoseRow;
constexpr Index kPeriodTwist = kPeriodPlacement + kPoseRow;
constexpr Index kPeriodRow = kPeriodTwist + 6;

//! A pose row's rotation and translation, read in place.
using Rotation = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;
using Translation = Eigen::Map<const Eigen::Vector3d>;

inline Rotation row_rotation(const double* row) { return Rotation(row); }
inline Translation row_translation(const double* row) { return Translation(row + kPoseTranslation); }

//! ``rotation`` and ``translation`` written into the pose row at ``row``.
template <typename RotationType, typename TranslationType>
void write_pose_row(const RotationType& rotation, const TranslationType& translation, double* row) {
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> row_rotation(row);
  Eigen::Map<Eigen::Vector3d> row_translation(row + kPoseTranslation);
  row_rotation = rotation;
  row_translation = translation;
}

}  // namespace cjm
