// The collision rows of the compiled step; see collision.hpp.
#include "collision.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace cjm {

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
//! The squared length (m^2) below which a segment is its first end (1e-10 m).
constexpr double kPointLength2 = 1e-20;
//! The norm of a cross product of unit axes below which the axes count as parallel
//! (the separating-axis test then needs no axis of theirs: a face normal covers it).
constexpr double kParallel = 1e-9;
//! The core distance (m) below which two points or segments count as intersecting.
constexpr double kTouching = 1e-12;

//! A shape's core (a box of half sides ``half``, zero for a point or across a segment)
//! swept by a ball of ``radius``, in the world.
struct Core {
  Matrix3 rotation;
  Vector3 center, half;
  double radius = 0.0;
  bool box = false;
};

Core core_of(const Shape& shape, const Pose& pose) {
  Core core{pose.rotation, pose.translation, Vector3::Zero(), 0.0, false};
  if (shape.kind == Shape::box) {
    core.half = shape.dimensions;
    core.box = true;
  } else {
    core.radius = shape.dimensions(0);
    if (shape.kind == Shape::capsule) core.half(2) = shape.dimensions(1);
  }
  return core;
}

double sign_or_zero(double value) { return value > 0.0 ? 1.0 : (value < 0.0 ? -1.0 : 0.0); }

//! The core's farthest point along ``direction`` (a tie: the middle of the face).
Vector3 support(const Core& core, const Vector3& direction) {
  const Vector3 local = core.rotation.transpose() * direction;
  Vector3 corner;
  for (int i = 0; i < 3; ++i) corner(i) = core.half(i) * sign_or_zero(local(i));
  return core.center + core.rotation * corner;
}

//! The core's point closest to ``point`` (clamped in its frame).
Vector3 closest_on(const Core& core, const Vector3& point) {
  Vector3 local = core.rotation.transpose() * (point - core.center);
  for (int i = 0; i < 3; ++i) local(i) = std::clamp(local(i), -core.half(i), core.half(i));
  return core.center + core.rotation * local;
}

//! The core's distinct vertices (1, 2, 4 or 8); returns their count.
int vertices(const Core& core, std::array<Vector3, 8>& out) {
  int count = 1;
  out[0] = core.center;
  for (int i = 0; i < 3; ++i) {
    if (!(core.half(i) > 0.0)) continue;
    const Vector3 step = core.half(i) * core.rotation.col(i);
    for (int v = 0; v < count; ++v) {
      out[count + v] = out[v] + step;
      out[v] -= step;
    }
    count *= 2;
  }
  return count;
}

using Edge = std::array<Vector3, 2>;

//! The core's edges (0 for a point, 1 for a segment, 12 for a box); returns their count.
int edges(const Core& core, std::array<Edge, 12>& out) {
  int count = 0;
  std::array<Vector3, 8> centers;
  for (int i = 0; i < 3; ++i) {
    if (!(core.half(i) > 0.0)) continue;
    Core flat = core;
    flat.half(i) = 0.0;
    const int n = vertices(flat, centers);
    const Vector3 half = core.half(i) * core.rotation.col(i);
    for (int e = 0; e < n; ++e) out[count++] = {centers[e] - half, centers[e] + half};
  }
  return count;
}

//! The closest points of segments [p1, q1] and [p2, q2] (Ericson, Real-Time Collision
//! Detection, 5.1.9); returns their distance.
double closest_segments(const Vector3& p1, const Vector3& q1, const Vector3& p2, const Vector3& q2,
                        Vector3& on_first, Vector3& on_second) {
  const Vector3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0.0, t = 0.0;
  if (a <= kPointLength2 && e <= kPointLength2) {
    s = t = 0.0;
  } else if (a <= kPointLength2) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kPointLength2) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denominator = a * e - b * b;
      s = denominator > 0.0 ? std::clamp((b * f - c * e) / denominator, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  on_first = p1 + s * d1;
  on_second = p2 + t * d2;
  return (on_first - on_second).norm();
}

//! The separating-axis test of two cores over their 15 axes: false when one separates
//! them, else true with the least overlap (the penetration depth) and its axis, from the
//! second towards the first.
bool overlapping(const Core& first, const Core& second, double& depth, Vector3& axis) {
  const Vector3 delta = first.center - second.center;
  depth = kInfinity;
  const auto overlap_along = [&](const Vector3& u) {
    double reach = 0.0;
    for (int i = 0; i < 3; ++i)
      reach += first.half(i) * std::abs(u.dot(first.rotation.col(i))) +
               second.half(i) * std::abs(u.dot(second.rotation.col(i)));
    const double along = u.dot(delta), overlap = reach - std::abs(along);
    if (overlap < depth) {
      depth = overlap;
      axis = along >= 0.0 ? u : Vector3(-u);
    }
    return overlap >= 0.0;
  };
  for (int i = 0; i < 3; ++i)
    if (!overlap_along(first.rotation.col(i)) || !overlap_along(second.rotation.col(i))) return false;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const Vector3 u = first.rotation.col(i).cross(second.rotation.col(j));
      const double norm = u.norm();
      if (norm > kParallel && !overlap_along(u / norm)) return false;
    }
  return true;
}

//! The closest points of two disjoint cores: the least of each one's vertices against
//! the other and of the edge pairs.
double closest_disjoint(const Core& first, const Core& second, Vector3& on_first,
                        Vector3& on_second) {
  double best = kInfinity;
  const auto keep = [&](const Vector3& a, const Vector3& b) {
    const double distance2 = (a - b).squaredNorm();
    if (distance2 < best) {
      best = distance2;
      on_first = a;
      on_second = b;
    }
  };
  std::array<Vector3, 8> corners;
  for (int v = 0, n = vertices(first, corners); v < n; ++v) keep(corners[v], closest_on(second, corners[v]));
  for (int v = 0, n = vertices(second, corners); v < n; ++v) keep(closest_on(first, corners[v]), corners[v]);
  std::array<Edge, 12> first_edges, second_edges;
  const int n_first = edges(first, first_edges), n_second = edges(second, second_edges);
  Vector3 a, b;
  for (int i = 0; i < n_first; ++i)
    for (int j = 0; j < n_second; ++j) {
      closest_segments(first_edges[i][0], first_edges[i][1], second_edges[j][0], second_edges[j][1], a, b);
      keep(a, b);
    }
  return std::sqrt(best);
}

//! The cores' penetration: the least overlap along the separating axes, each core's
//! deepest point along its axis.
Contact penetration(const Core& first, const Core& second) {
  double depth = 0.0;
  Vector3 axis = Vector3::UnitZ();
  overlapping(first, second, depth, axis);
  return Contact{-depth, support(first, -axis), support(second, axis), axis};
}

//! The signed distance of two cores (their radii not yet taken).
Contact core_distance(const Core& first, const Core& second) {
  Contact contact;
  if (!first.box && !second.box) {
    const Vector3 half_first = first.half(2) * first.rotation.col(2);
    const Vector3 half_second = second.half(2) * second.rotation.col(2);
    const double distance = closest_segments(first.center - half_first, first.center + half_first,
                                             second.center - half_second, second.center + half_second,
                                             contact.on_first, contact.on_second);
    if (!(distance > kTouching)) return penetration(first, second);
    contact.distance = distance;
  } else {
    double depth = 0.0;
    Vector3 axis;
    if (overlapping(first, second, depth, axis)) return penetration(first, second);
    contact.distance = closest_disjoint(first, second, contact.on_first, contact.on_second);
    if (!(contact.distance > kTouching)) return penetration(first, second);
  }
  contact.normal = (contact.on_first - contact.on_second) / contact.distance;
  return contact;
}

//! A core against the half-space z <= 0 of ``plane``'s frame: its deepest point.
Contact against_halfspace(const Core& core, const Pose& plane) {
  const Vector3 normal = plane.rotation.col(2);
  const Vector3 deepest = support(core, -normal);
  const double height = normal.dot(deepest - plane.translation);
  return Contact{height - core.radius, deepest - core.radius * normal, deepest - height * normal, normal};
}

//! The broadphase's distance of two segments: geometry.py's segment_distances, to the
//! bit (segments shorter than 1e-6 m count as their first end).
double bounding_distance(const Vector3& first_start, const Vector3& first_end,
                         const Vector3& second_start, const Vector3& second_end) {
  constexpr double tiny = 1e-12;
  const Vector3 d1 = first_end - first_start, d2 = second_end - second_start;
  const Vector3 r = first_start - second_start;
  const double a = d1.dot(d1), e = d2.dot(d2), f = d2.dot(r), c = d1.dot(r), b = d1.dot(d2);
  const double a_safe = std::max(a, tiny), e_safe = std::max(e, tiny);
  const auto unit = [](double value) { return std::min(std::max(value, 0.0), 1.0); };
  double s = unit((b * f - c * e) / std::max(a * e - b * b, tiny));
  double t = (b * s + f) / e_safe;
  s = t < 0.0 ? unit(-c / a_safe) : (t > 1.0 ? unit((b - c) / a_safe) : s);
  if (!(e > tiny)) s = unit(-c / a_safe);
  t = unit(t);
  return (r + d1 * s - d2 * t).norm();
}

//! The bounding capsule's half segment and radius of a shape in its own frame
//! (geometry.py's bounding_segment): a box's along its longest edge.
std::pair<Vector3, double> bounding_half(const Shape& shape) {
  const Vector3& dims = shape.dimensions;
  switch (shape.kind) {
    case Shape::capsule:
      return {Vector3(0.0, 0.0, dims(1)), dims(0)};
    case Shape::box: {
      Eigen::Index longest = 0;
      dims.maxCoeff(&longest);
      Vector3 half = Vector3::Zero();
      half(longest) = dims(longest);
      Vector3 others = dims;
      others(longest) = 0.0;
      return {half, others.norm()};
    }
    case Shape::halfspace:
      return {Vector3::Zero(), kInfinity};
    default:
      return {Vector3::Zero(), dims(0)};
  }
}

void check_shape(const Shape& shape, bool body) {
  if (shape.kind < Shape::sphere || shape.kind > Shape::halfspace)
    throw std::invalid_argument("unknown collision shape kind");
  if (body && shape.kind == Shape::halfspace)
    throw std::invalid_argument("a robot body cannot be a half-space");
  if (!shape.dimensions.allFinite() || (shape.dimensions.array() < 0.0).any())
    throw std::invalid_argument("a collision shape's dimensions must be finite and >= 0");
}

}  // namespace

Contact shape_distance(const Shape& first, const Pose& first_pose, const Shape& second,
                       const Pose& second_pose) {
  const Core a = core_of(first, first_pose);
  if (second.kind == Shape::halfspace) return against_halfspace(a, second_pose);
  const Core b = core_of(second, second_pose);
  Contact contact = core_distance(a, b);
  contact.distance -= a.radius + b.radius;
  contact.on_first -= a.radius * contact.normal;
  contact.on_second += b.radius * contact.normal;
  return contact;
}

Collisions::Collisions(std::vector<CollisionBody> bodies, std::vector<CollisionObstacle> obstacles,
                       std::vector<std::array<Index, 2>> pairs, double safety_distance,
                       double detection_distance, double gain, const Kinematics& kinematics)
    : bodies_(std::move(bodies)), obstacles_(std::move(obstacles)), pairs_(std::move(pairs)),
      safety_(safety_distance), detection_(detection_distance), gain_(gain) {
  const Index n_bodies = static_cast<Index>(bodies_.size());
  const Index n_all = n_bodies + static_cast<Index>(obstacles_.size());
  if (!(detection_ > safety_) || !(gain_ > 0.0) || !std::isfinite(detection_))
    throw std::invalid_argument("the collision distances need d_i > d_s and a gain > 0");
  for (const CollisionBody& body : bodies_) {
    check_shape(body.shape, true);
    if (body.joint < 0 || body.joint >= kinematics.njoints())
      throw std::invalid_argument("a collision body's joint is out of range");
  }
  for (const CollisionObstacle& obstacle : obstacles_) check_shape(obstacle.shape, false);
  for (const auto& [first, second] : pairs_)
    if (first < 0 || first >= n_bodies || second < 0 || second >= n_all || second == first)
      throw std::invalid_argument("a collision pair must be a body and another body or an obstacle");
  for (Index joint = 0; joint < kinematics.njoints(); ++joint)
    support_.push_back(kinematics.support_columns(joint));
  for (const CollisionBody& body : bodies_) {
    const auto [half, radius] = bounding_half(body.shape);
    const Vector3 along = body.placement.rotation * half;
    local_start_.push_back(body.placement.translation - along);
    local_end_.push_back(body.placement.translation + along);
    bound_radius_.push_back(radius);
  }
  for (const CollisionObstacle& obstacle : obstacles_) bound_radius_.push_back(bounding_half(obstacle.shape).second);
  poses_.resize(static_cast<size_t>(n_all));
  bounds_.resize(static_cast<size_t>(n_all));
  const Index n_pairs = pair_count();
  row_pairs_ = Eigen::Matrix<Index, Eigen::Dynamic, 1>::Zero(std::max<Index>(1, n_pairs));
  distances_ = Vector::Zero(std::max<Index>(1, n_pairs));
  witnesses_ = RowMatrix::Zero(std::max<Index>(1, n_pairs), 6);
  summary_ = Vector::Zero(3);
  summary_ << 0.0, kInfinity, -1.0;  // no pair measured yet
}

void Collisions::place(const Kinematics& kinematics) {
  const size_t n_bodies = bodies_.size();
  for (size_t i = 0; i < n_bodies; ++i) {
    const Matrix3& rotation = kinematics.joint_rotation(bodies_[i].joint);
    const Vector3& translation = kinematics.joint_translation(bodies_[i].joint);
    poses_[i].rotation.noalias() = rotation * bodies_[i].placement.rotation;
    poses_[i].translation.noalias() = rotation * bodies_[i].placement.translation;
    poses_[i].translation += translation;
    bounds_[i].start.noalias() = rotation * local_start_[i];
    bounds_[i].start += translation;
    bounds_[i].end.noalias() = rotation * local_end_[i];
    bounds_[i].end += translation;
    bounds_[i].center = 0.5 * (bounds_[i].start + bounds_[i].end);
    bounds_[i].half_length = 0.5 * (bounds_[i].end - bounds_[i].start).norm();
  }
  for (size_t k = 0; k < obstacles_.size(); ++k) {
    const CollisionObstacle& obstacle = obstacles_[k];
    Pose& pose = poses_[n_bodies + k];
    pose.rotation = obstacle.rotation;
    pose.translation = obstacle.center;
    const Vector3 along = obstacle.rotation * bounding_half(obstacle.shape).first;
    bounds_[n_bodies + k] = Bound{obstacle.center - along, obstacle.center + along, obstacle.center, along.norm()};
  }
}

double Collisions::gap(Index first, Index second) const {
  const Bound& body = bounds_[first];
  const Index n_bodies = static_cast<Index>(bodies_.size());
  if (second >= n_bodies && obstacles_[second - n_bodies].shape.kind == Shape::halfspace) {
    const Pose& plane = poses_[second];
    const Vector3 normal = plane.rotation.col(2);
    return std::min(normal.dot(body.start - plane.translation), normal.dot(body.end - plane.translation)) -
           bound_radius_[first];
  }
  const Bound& other = bounds_[second];
  // the segments are at least their centres' distance less their half lengths apart:
  // a pair that far beyond d_i needs no segment distance
  const double beyond = (body.center - other.center).norm() - body.half_length - other.half_length -
                        bound_radius_[first] - bound_radius_[second];
  if (beyond >= detection_) return beyond;
  return bounding_distance(body.start, body.end, other.start, other.end) - bound_radius_[first] -
         bound_radius_[second];
}

void Collisions::add_point_row(const Kinematics& kinematics, Index joint, const Vector3& point,
                               const Vector3& normal, double sign,
                               Eigen::Ref<Eigen::RowVectorXd> row) const {
  // v(p) = v_O + w x p (WORLD frame), so n^T v(p) = n^T J_v + (p x n)^T J_w
  const Vector3 arm = point.cross(normal);
  const auto& jacobian = kinematics.world_jacobians();
  for (const Index column : support_[static_cast<size_t>(joint)])
    row(column) += sign * (normal.dot(jacobian.col(column).head<3>()) +
                           arm.dot(jacobian.col(column).tail<3>()));
}

void Collisions::write_rows(const Kinematics& kinematics, Step& step) {
  place(kinematics);
  const Index n_bodies = static_cast<Index>(bodies_.size());
  RowMatrix& rows = step.pair_rows();
  Vector& lower = step.pair_lower();
  Index count = 0, closest = -1;
  double minimum = kInfinity;
  for (Index p = 0; p < pair_count(); ++p) {
    const auto [first, second] = pairs_[static_cast<size_t>(p)];
    if (!(gap(first, second) < detection_)) continue;
    const Shape& other = second < n_bodies ? bodies_[second].shape : obstacles_[second - n_bodies].shape;
    const Contact contact = shape_distance(bodies_[first].shape, poses_[first], other, poses_[second]);
    if (contact.distance < minimum) {
      minimum = contact.distance;
      closest = p;
    }
    if (!(contact.distance < detection_)) continue;
    auto row = rows.row(count);
    row.setZero();
    add_point_row(kinematics, bodies_[first].joint, contact.on_first, contact.normal, 1.0, row);
    double bound = -gain_ * (contact.distance - safety_);
    if (second < n_bodies)
      add_point_row(kinematics, bodies_[second].joint, contact.on_second, contact.normal, -1.0, row);
    else
      bound += contact.normal.dot(obstacles_[second - n_bodies].velocity);
    lower(count) = bound + step.damper_raise(row, contact.distance - safety_, gain_);
    row_pairs_(count) = p;
    distances_(count) = contact.distance;
    witnesses_.row(count).head<3>() = contact.on_first.transpose();
    witnesses_.row(count).tail<3>() = contact.on_second.transpose();
    ++count;
  }
  step.set_pair_count(count);
  summary_ << static_cast<double>(count), minimum, static_cast<double>(closest);
}

}  // namespace cjm
