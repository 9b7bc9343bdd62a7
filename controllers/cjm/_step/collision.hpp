// The collision rows of the compiled CJM step (docs/design.md sections 18.3 and 18.4): the
// signed distance, witness points and normal of primitive pairs (sphere, capsule, box,
// half-space), the bounding-capsule broadphase, and one velocity-damper row per pair
// closer than the detection distance, written into the step's pair buffer.
//
// A sphere, a capsule and a box are each a *core* (a point, a segment, a box: all boxes,
// some of zero extent) swept by a ball of radius r, so the signed distance of two of
// them is their cores' less the two radii (exact for penetration too: the Minkowski sum
// with a ball moves every boundary point of the cores' difference by r). Two cores:
//  * neither a box: Ericson's closest points of two segments (a point is a segment of
//    length zero);
//  * else the separating-axis test over the 15 axes (each box's 3, their 9 crosses):
//    separated, the distance is the least over the vertices of one against the other
//    and the edge pairs (the closest points of two disjoint polytopes lie on one of
//    those); intersecting, the least overlap over those axes is the penetration depth
//    (the axes hold every face normal of the cores' Minkowski difference).
// In penetration the distance is minus the depth (coal's sign), the normal the axis of
// least overlap and the witness points each body's deepest point along it.
#pragma once

#include <array>
#include <vector>

#include "kinematics.hpp"
#include "step.hpp"

namespace cjm {

using Vector3 = Eigen::Vector3d;
using Matrix3 = Eigen::Matrix3d;

//! A primitive in its own frame; the order is controllers/cjm/compiled_collisions.py's.
struct Shape {
  enum Kind : int { sphere = 0, capsule, box, halfspace };
  Kind kind = sphere;
  //! sphere: (radius, 0, 0); capsule: (radius, half length along z, 0); box: its half
  //! sides; half-space: unused (its solid side is its frame's z <= 0)
  Vector3 dimensions = Vector3::Zero();
};

struct Pose {
  Matrix3 rotation = Matrix3::Identity();
  Vector3 translation = Vector3::Zero();
};

//! A pair's signed distance (m), its witness points and the unit normal from the second
//! body towards the first.
struct Contact {
  double distance = 0.0;
  Vector3 on_first = Vector3::Zero(), on_second = Vector3::Zero(), normal = Vector3::UnitZ();
};

//! ``first`` against ``second`` (a half-space only as ``second``).
Contact shape_distance(const Shape& first, const Pose& first_pose, const Shape& second,
                       const Pose& second_pose);

//! A robot body: on joint ``joint`` at ``placement`` in that joint's frame.
struct CollisionBody {
  Index joint = 0;
  Pose placement;
  Shape shape;
};

//! An obstacle: its shape's rotation (fixed), centre and velocity (moved between steps).
struct CollisionObstacle {
  Shape shape;
  Matrix3 rotation = Matrix3::Identity();
  Vector3 center = Vector3::Zero(), velocity = Vector3::Zero();
};

class Collisions {
 public:
  //! ``pairs``: (first, second) indices into the bodies then the obstacles, the first a
  //! body; ``gain`` the damper's ``xi / (d_i - d_s)``.
  Collisions(std::vector<CollisionBody> bodies, std::vector<CollisionObstacle> obstacles,
             std::vector<std::array<Index, 2>> pairs, double safety_distance,
             double detection_distance, double gain, const Kinematics& kinematics);

  //! The rows at the joint placements and Jacobians of ``kinematics`` (computed) into
  //! ``step``'s pair buffer (its capacity at least pair_count()), and their count.
  void write_rows(const Kinematics& kinematics, Step& step);

  Index pair_count() const { return static_cast<Index>(pairs_.size()); }
  std::vector<CollisionObstacle>& obstacles() { return obstacles_; }
  //! Per row of the last write_rows(): its pair index, distance, witness points (first
  //! then second, world).
  Eigen::Matrix<Index, Eigen::Dynamic, 1>& row_pairs() { return row_pairs_; }
  Vector& distances() { return distances_; }
  RowMatrix& witnesses() { return witnesses_; }
  //! (row count, smallest distance measured (inf: none), its pair (-1: none)).
  Vector& summary() { return summary_; }

 private:
  struct Bound {  // a bounding capsule in the world: its segment, centre and half length
    Vector3 start, end, center;
    double half_length = 0.0;
  };
  void place(const Kinematics& kinematics);
  double gap(Index first, Index second) const;
  //! ``sign n^T J_p`` of the world ``point`` carried by ``joint`` added to ``row``.
  void add_point_row(const Kinematics& kinematics, Index joint, const Vector3& point,
                     const Vector3& normal, double sign, Eigen::Ref<Eigen::RowVectorXd> row) const;

  std::vector<CollisionBody> bodies_;
  std::vector<CollisionObstacle> obstacles_;
  std::vector<std::array<Index, 2>> pairs_;
  double safety_, detection_, gain_;
  std::vector<std::vector<Index>> support_;  // per joint: its velocity columns
  std::vector<Vector3> local_start_, local_end_;  // bounding segments, bodies: joint frame
  std::vector<double> bound_radius_;              // bodies then obstacles (inf: half-space)
  // per step
  std::vector<Pose> poses_;    // bodies then obstacles, world
  std::vector<Bound> bounds_;  // bodies then obstacles
  Eigen::Matrix<Index, Eigen::Dynamic, 1> row_pairs_;
  Vector distances_, summary_;
  RowMatrix witnesses_;
};

}  // namespace cjm
