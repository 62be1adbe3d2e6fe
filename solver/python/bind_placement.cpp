#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>

#include "mocapedit/placement.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using mocapedit::Span;

Span<const double> View(const DoubleArray& a) { return Span<const double>(a.data(), static_cast<std::size_t>(a.size())); }
Span<double> View(DoubleArray& a) { return Span<double>(a.mutable_data(), static_cast<std::size_t>(a.size())); }

// An (N, trailing...) array of doubles whose shape is checked here, so the message names it.
DoubleArray Shaped(const py::handle& value, std::vector<py::ssize_t> shape, const char* name) {
  DoubleArray a = DoubleArray::ensure(value);
  bool ok = a && a.ndim() == static_cast<py::ssize_t>(shape.size());
  for (std::size_t i = 0; ok && i < shape.size(); ++i) ok = shape[i] < 0 || a.shape(static_cast<py::ssize_t>(i)) == shape[i];
  if (!ok) {
    std::string want = "(";
    for (std::size_t i = 0; i < shape.size(); ++i)
      want += (i ? ", " : "") + (shape[i] < 0 ? std::string("any") : std::to_string(shape[i]));
    throw std::invalid_argument(std::string(name) + ": expected shape " + want + ")");
  }
  return a;
}

}  // namespace

MOCAPEDIT_BINDINGS(BindPlacement) {
  m.def(
      "place",
      [](const py::handle& placement_in, const py::handle& placement_rotation_in, const py::handle& motion_in,
         const py::handle& turn_in, const py::handle& up_in, const py::handle& points_in,
         const py::handle& rotations_in) {
        const DoubleArray turn = Shaped(turn_in, {-1}, "turn");
        const py::ssize_t n = turn.shape(0);
        const DoubleArray placement = Shaped(placement_in, {n, 4, 4}, "placement"),
                          placement_rotation = Shaped(placement_rotation_in, {n, 4}, "placement_rotation"),
                          motion = Shaped(motion_in, {n, 4, 4}, "motion"), up = Shaped(up_in, {3}, "up"),
                          points = Shaped(points_in, {n, -1, 3}, "points"),
                          rotations = Shaped(rotations_in, {n, -1, 4}, "rotations");
        const py::ssize_t p = points.shape(1), q = rotations.shape(1);
        DoubleArray source_points({n, p, py::ssize_t{3}}), edited_points({n, p, py::ssize_t{3}}),
            source_rotations({n, q, py::ssize_t{4}}), edited_rotations({n, q, py::ssize_t{4}});
        mocapedit::PlacementJob job;
        job.placement = View(placement), job.placement_rotation = View(placement_rotation), job.motion = View(motion);
        job.turn = View(turn), job.up = View(up), job.points = View(points), job.rotations = View(rotations);
        job.point_count = p, job.rotation_count = q;
        job.source_points = View(source_points), job.edited_points = View(edited_points);
        job.source_rotations = View(source_rotations), job.edited_rotations = View(edited_rotations);
        {
          py::gil_scoped_release release;
          job.Run();
        }
        return py::make_tuple(source_points, edited_points, source_rotations, edited_rotations);
      },
      py::kw_only(), py::arg("placement"), py::arg("placement_rotation"), py::arg("motion"), py::arg("turn"),
      py::arg("up"), py::arg("points"), py::arg("rotations"),
      "Skeleton-space points (N, P, 3) and rotations (N, Q, 4) (x, y, z, w) carried into the world by each pose's\n"
      "placement (N, 4, 4) row-vector and its rotation (N, 4), then by the edit's ground motion (N, 4, 4) and\n"
      "its turn (N,) radians about the unit up (3,) (the C++ PlacementJob). Returns (source_points,\n"
      "edited_points, source_rotations, edited_rotations). Keyword arguments only.");
}
