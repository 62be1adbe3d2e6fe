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
  m.def(
      "deformation_turns",
      [](const Eigen::Ref<const Trajectory2>& source, const Eigen::Ref<const Trajectory2>& edited,
         const std::vector<mocapedit::FrameRange>& fixed, const Eigen::VectorXd& fixed_turn, int window,
         double min_travel, double max_step) {
        py::gil_scoped_release release;
        return mocapedit::DeformationTurns(source, edited, fixed, fixed_turn, window, min_travel, max_step);
      },
      py::kw_only(), py::arg("source"), py::arg("edited"), py::arg("fixed") = std::vector<mocapedit::FrameRange>{},
      py::arg("fixed_turn") = Eigen::VectorXd(), py::arg("window") = 2, py::arg("min_travel") = 0.0,
      py::arg("max_step") = 0.0,
      "(N,) turn (radians, CCW) of each frame's heading when the path goes from source to edited (N,2):\n"
      "the least-squares rotation of the source steps onto the edited ones within two nested windows of\n"
      "`window` frames each side; frames whose source moves less than `min_travel` across the window take\n"
      "it from the moving frames around them; `fixed` inclusive ranges turn by their `fixed_turn`;\n"
      "source steps longer than `max_step` (0: none) are cuts and count for nothing.");
  m.def(
      "spot_weight",
      [](const Eigen::Ref<const Trajectory2>& source, int window, double min_travel, double max_step) {
        return mocapedit::SpotWeight(source, window, min_travel, max_step);
      },
      py::kw_only(), py::arg("source"), py::arg("window") = 2, py::arg("min_travel") = 0.0, py::arg("max_step") = 0.0,
      "How far the path (N,2) stays about one spot, in [0, 1], as deformation_turns holds it when no frame\n"
      "travels far enough to be sure of its own turn: 1 minus the whole path's straightness (chord over\n"
      "distance walked: 0 at most 0.4, 1 from 0.7); 0 when some frame is sure or min_travel is 0.");
}
