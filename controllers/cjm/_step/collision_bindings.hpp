// Python bindings of the collision rows (collision.hpp), included by module.cpp: the
// description controllers/cjm/compiled_collisions.py hands over, the obstacles' centres
// and velocities read before every step (a new array, as Obstacle.move_to assigns, is
// copied; the same array is not read again), and views of what the rows measured.
#pragma once

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <array>
#include <string>
#include <tuple>
#include <vector>

#include "pipeline.hpp"

namespace cjm_collision {

namespace py = pybind11;
using cjm::Index;

//! Each obstacle's Python object and the centre and velocity arrays last copied from it,
//! and each pair's name.
struct CollisionSources {
  struct Source {
    py::object obstacle, center, velocity;
  };
  std::vector<Source> sources;
  std::vector<py::object> pair_names;
  py::str center_name{"center"}, velocity_name{"velocity"};

  static void copy(const py::object& array, cjm::Vector3& target, const char* what) {
    if (!py::isinstance<py::array_t<double>>(array))
      throw std::invalid_argument(std::string("an obstacle's ") + what + " must be a float64 array");
    const auto entries = py::reinterpret_borrow<py::array_t<double>>(array).unchecked<1>();
    if (entries.shape(0) != 3) throw std::invalid_argument(std::string("an obstacle's ") + what + " needs 3 entries");
    for (py::ssize_t i = 0; i < 3; ++i) target(i) = entries(i);
    if (!target.allFinite()) throw std::invalid_argument(std::string("an obstacle's ") + what + " must be finite");
  }

  //! The centres and velocities replaced since the last step, into ``collisions``; whether any
  //! was.
  bool read(cjm::Collisions* collisions) {
    bool changed = false;
    if (collisions == nullptr) return changed;
    for (size_t k = 0; k < sources.size(); ++k) {
      Source& source = sources[k];
      cjm::CollisionObstacle& obstacle = collisions->obstacles()[k];
      py::object center = source.obstacle.attr(center_name);
      if (!center.is(source.center)) {
        copy(center, obstacle.center, "center");
        source.center = std::move(center);
        changed = true;
      }
      py::object velocity = source.obstacle.attr(velocity_name);
      if (!velocity.is(source.velocity)) {
        copy(velocity, obstacle.velocity, "velocity");
        source.velocity = std::move(velocity);
        changed = true;
      }
    }
    return changed;
  }
};

inline cjm::Shape shape(int kind, const cjm::Vector3& dimensions) {
  if (kind < cjm::Shape::sphere || kind > cjm::Shape::halfspace)
    throw std::invalid_argument("unknown collision shape kind " + std::to_string(kind));
  return cjm::Shape{static_cast<cjm::Shape::Kind>(kind), dimensions};
}

//! Pipeline.set_collisions: the description of CollisionAvoidance.primitives().
template <typename BoundPipeline>
void set_collisions(BoundPipeline& pipeline, const std::vector<Index>& body_joints,
                    const std::vector<Eigen::Matrix4d>& body_placements,
                    const std::vector<int>& body_kinds, const std::vector<cjm::Vector3>& body_dimensions,
                    py::list obstacles, const std::vector<int>& obstacle_kinds,
                    const std::vector<cjm::Vector3>& obstacle_dimensions,
                    const std::vector<cjm::Matrix3>& obstacle_rotations,
                    const std::vector<std::array<Index, 2>>& pairs, py::list pair_names,
                    double safety_distance, double detection_distance, double gain) {
  const size_t n_bodies = body_joints.size(), n_obstacles = obstacles.size();
  if (body_placements.size() != n_bodies || body_kinds.size() != n_bodies ||
      body_dimensions.size() != n_bodies || obstacle_kinds.size() != n_obstacles ||
      obstacle_dimensions.size() != n_obstacles || obstacle_rotations.size() != n_obstacles)
    throw std::invalid_argument("one placement, kind and dimensions per body and obstacle");
  if (pair_names.size() != pairs.size()) throw std::invalid_argument("one name per pair");
  std::vector<cjm::CollisionBody> bodies;
  for (size_t i = 0; i < n_bodies; ++i)
    bodies.push_back(cjm::CollisionBody{
        body_joints[i],
        cjm::Pose{body_placements[i].topLeftCorner<3, 3>(), body_placements[i].topRightCorner<3, 1>()},
        shape(body_kinds[i], body_dimensions[i])});
  std::vector<cjm::CollisionObstacle> described;
  CollisionSources sources;
  for (size_t k = 0; k < n_obstacles; ++k) {
    cjm::CollisionObstacle obstacle{shape(obstacle_kinds[k], obstacle_dimensions[k]), obstacle_rotations[k]};
    py::object source = py::reinterpret_borrow<py::object>(obstacles[k]);
    py::object center = source.attr("center"), velocity = source.attr("velocity");
    CollisionSources::copy(center, obstacle.center, "center");
    CollisionSources::copy(velocity, obstacle.velocity, "velocity");
    sources.sources.push_back({source, center, velocity});
    described.push_back(obstacle);
  }
  pipeline.set_collisions(std::make_unique<cjm::Collisions>(
      std::move(bodies), std::move(described), pairs, safety_distance, detection_distance, gain,
      pipeline.kinematics()));
  for (py::handle name : pair_names) sources.pair_names.push_back(py::reinterpret_borrow<py::object>(name));
  pipeline.collision_sources = std::move(sources);
}

//! A copy of the first ``rows`` rows of ``matrix`` as a new array.
inline py::array_t<double> copy_rows(const cjm::RowMatrix& matrix, Index rows, Index columns) {
  py::array_t<double> array({rows, columns});
  std::copy(matrix.data(), matrix.data() + rows * columns, array.mutable_data());
  return array;
}

//! A copy of the first ``count`` entries of ``vector`` as a new array.
inline py::array_t<double> copy_head(const cjm::Vector& vector, Index count) {
  py::array_t<double> array(count);
  std::copy(vector.data(), vector.data() + count, array.mutable_data());
  return array;
}

//! Pipeline.collision_report: the last step's rows as CollisionRows' fields (rows,
//! lower, pair names, distances, witnesses (m x 2 x 3), minimum distance, its pair), copies.
template <typename BoundPipeline>
py::tuple collision_report(BoundPipeline& pipeline) {
  cjm::Collisions* collisions = pipeline.collisions();
  if (collisions == nullptr) throw std::invalid_argument("no collision rows are set");
  const cjm::Vector& summary = collisions->summary();
  const auto count = static_cast<Index>(summary(0));
  const auto closest = static_cast<Index>(summary(2));
  cjm::Step& step = pipeline.step();
  const Index nv = step.pair_rows().cols();
  py::tuple names(count);
  for (Index i = 0; i < count; ++i)
    names[i] = pipeline.collision_sources.pair_names[static_cast<size_t>(collisions->row_pairs()(i))];
  py::array_t<double> witnesses({count, Index{2}, Index{3}});
  std::copy(collisions->witnesses().data(), collisions->witnesses().data() + 6 * count,
            witnesses.mutable_data());
  return py::make_tuple(
      copy_rows(step.pair_rows(), count, nv), copy_head(step.pair_lower(), count),
      names, copy_head(collisions->distances(), count), witnesses, summary(1),
      closest >= 0 ? pipeline.collision_sources.pair_names[static_cast<size_t>(closest)] : py::str(""));
}

template <typename Scalar>
py::array_t<Scalar> view(Scalar* data, std::vector<py::ssize_t> shape, py::handle owner) {
  std::vector<py::ssize_t> strides(shape.size(), sizeof(Scalar));
  for (size_t i = shape.size(); i-- > 1;) strides[i - 1] = strides[i] * shape[i];
  return py::array_t<Scalar>(shape, strides, data, owner);
}

//! Pipeline.collision_views: (row pairs, distances, witnesses (n x 6), summary), views
//! valid until the next set_collisions.
template <typename BoundPipeline>
py::tuple collision_views(py::object self) {
  cjm::Collisions* collisions = self.cast<BoundPipeline&>().collisions();
  if (collisions == nullptr) throw std::invalid_argument("no collision rows are set");
  auto& pairs = collisions->row_pairs();
  auto& distances = collisions->distances();
  auto& witnesses = collisions->witnesses();
  auto& summary = collisions->summary();
  return py::make_tuple(view(pairs.data(), {pairs.size()}, self),
                        view(distances.data(), {distances.size()}, self),
                        view(witnesses.data(), {witnesses.rows(), witnesses.cols()}, self),
                        view(summary.data(), {summary.size()}, self));
}

//! The module's ``shape_distance``: two posed primitives' signed distance, witness
//! points and normal (for the tests against coal).
inline void bind(py::module_& module) {
  module.def(
      "shape_distance",
      [](int first_kind, const cjm::Vector3& first_dimensions, const Eigen::Matrix4d& first_pose,
         int second_kind, const cjm::Vector3& second_dimensions, const Eigen::Matrix4d& second_pose) {
        if (first_kind == cjm::Shape::halfspace)
          throw std::invalid_argument("a half-space only as the second shape");
        const cjm::Contact contact = cjm::shape_distance(
            shape(first_kind, first_dimensions), cjm::Pose{first_pose.topLeftCorner<3, 3>(), first_pose.topRightCorner<3, 1>()},
            shape(second_kind, second_dimensions), cjm::Pose{second_pose.topLeftCorner<3, 3>(), second_pose.topRightCorner<3, 1>()});
        return std::make_tuple(contact.distance, contact.on_first, contact.on_second, contact.normal);
      },
      py::arg("first_kind"), py::arg("first_dimensions"), py::arg("first_pose"),
      py::arg("second_kind"), py::arg("second_dimensions"), py::arg("second_pose"),
      "(distance, witness on the first, on the second, normal from the second to the first).");
  py::dict kinds;
  kinds["sphere"] = static_cast<int>(cjm::Shape::sphere);
  kinds["capsule"] = static_cast<int>(cjm::Shape::capsule);
  kinds["box"] = static_cast<int>(cjm::Shape::box);
  kinds["halfspace"] = static_cast<int>(cjm::Shape::halfspace);
  module.attr("SHAPE_KINDS") = kinds;
}

}  // namespace cjm_collision
