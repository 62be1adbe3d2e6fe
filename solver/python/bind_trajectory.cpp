#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "mocapedit/trajectory.h"
#include "registry.h"

namespace py = pybind11;

MOCAPEDIT_BINDINGS(BindTrajectory) {
  using mocapedit::Trajectory2;
  m.def("path_length", &mocapedit::PathLength, py::arg("points"),
        "Polyline length of a (N, 2) ground trajectory.");
  m.def("cumulative_arc_length", &mocapedit::CumulativeArcLength, py::arg("points"),
        "(N,) arc length along a (N, 2) trajectory, starting at 0.");
  m.def(
      "tangent_headings",
      [](const Eigen::Ref<const Trajectory2>& points, const std::vector<mocapedit::FrameRange>& fixed,
         const Eigen::VectorXd& fallback, double min_step) {
        py::gil_scoped_release release;
        return mocapedit::TangentHeadings(points, fixed, fallback, min_step);
      },
      py::arg("points"), py::arg("fixed") = std::vector<mocapedit::FrameRange>{},
      py::arg("fallback") = Eigen::VectorXd(), py::arg("min_step") = 1e-9,
      "(N,) unwrapped headings (radians, CCW about up) from the path tangent.\n\n"
      "Frames inside a `fixed` inclusive range take that range's `fallback` heading;\n"
      "frames standing still (tangent shorter than `min_step`) keep the nearest moving heading.");
}
