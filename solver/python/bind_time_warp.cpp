#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <memory>

#include "mocapedit/time_warp.h"
#include "registry.h"

namespace py = pybind11;

namespace {

mocapedit::TimeWarpProblem MakeProblem(std::vector<Eigen::VectorXd> rest_times, const mocapedit::FramePairs& time_frames,
                                       const mocapedit::Flags& time_hard, const Eigen::VectorXd& time_weights,
                                       const mocapedit::FrameQuads& sync_frames, const mocapedit::Flags& sync_hard,
                                       const Eigen::VectorXd& sync_weights, double min_interval_fraction,
                                       std::vector<Eigen::VectorXd> min_intervals, double stretch_weight,
                                       double anchor_weight, int max_active_set_iterations) {
  mocapedit::TimeWarpProblem p;
  p.rest_times = std::move(rest_times);
  p.time_frames = time_frames;
  p.time_hard = time_hard;
  p.time_weights = time_weights;
  p.sync_frames = sync_frames;
  p.sync_hard = sync_hard;
  p.sync_weights = sync_weights;
  p.min_interval_fraction = min_interval_fraction;
  p.min_intervals = std::move(min_intervals);
  p.stretch_weight = stretch_weight;
  p.anchor_weight = anchor_weight;
  p.max_active_set_iterations = max_active_set_iterations;
  return p;
}

}  // namespace

MOCAPEDIT_BINDINGS(BindTimeWarp) {
  using mocapedit::TimeWarpResult;
  py::class_<TimeWarpResult>(m, "TimeWarpResult", "Warped time maps and the figures to report (time_warp).")
      .def_readonly("time_maps", &TimeWarpResult::time_maps, py::return_value_policy::copy, "list of (F_a,) warped shot times, one per agent")
      .def_readonly("time_residuals", &TimeWarpResult::time_residuals, py::return_value_policy::copy, "(T,) |T[frame] - time| per time constraint")
      .def_readonly("sync_residuals", &TimeWarpResult::sync_residuals, py::return_value_policy::copy,
                    "(S,) |T_a[frame] - T_b[targetFrame] - offset| per sync constraint")
      .def_readonly("min_interval", &TimeWarpResult::min_interval, py::return_value_policy::copy, "(A,) smallest warped interval (inf: one frame)")
      .def_readonly("min_enforced", &TimeWarpResult::min_enforced, py::return_value_policy::copy,
                    "(A,) intervals the active set held at their minimum")
      .def_readonly("component", &TimeWarpResult::component, py::return_value_policy::copy, "(A,) component of each agent, -1 if unconstrained")
      .def_readonly("solver", &TimeWarpResult::solver, py::return_value_policy::copy, "(A,) 'rest', 'LDLT' or 'SPQR fallback'")
      .def_readonly("iterations", &TimeWarpResult::iterations, py::return_value_policy::copy, "(C,) active-set iterations per component");

  py::class_<mocapedit::TimeWarpData>(m, "TimeWarpData",
                                      "Factored time-warp components; re-solve with new constraint values.")
      .def_readonly("agents", &mocapedit::TimeWarpData::agents)
      .def_property_readonly("components", [](const mocapedit::TimeWarpData& d) { return d.components.size(); })
      .def_readonly("agent_component", &mocapedit::TimeWarpData::agent_component)
      .def(
          "solve",
          [](const mocapedit::TimeWarpData& d, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets) {
            TimeWarpResult r;
            {
              py::gil_scoped_release release;
              mocapedit::TimeWarpSolve(d, times, offsets, r);
            }
            return r;
          },
          py::arg("times"), py::arg("offsets"),
          "Warps the time maps to (T,) constraint times and (S,) sync offsets; see time_warp.");

  const char* structure_doc =
      "rest_times: list of (F_a,) increasing shot times, one per agent (the time maps at rest).\n"
      "time_frames: (T, 2) int (agent, frame); time_hard: (T,) bool; time_weights: (T,) soft weights.\n"
      "sync_frames: (S, 4) int (agent, frame, target, targetFrame); sync_hard, sync_weights: (S,).\n"
      "min_interval_fraction: smallest warped interval as a fraction of the rest interval, in (0, 1];\n"
      "min_intervals: optional list of (F_a - 1,) smallest intervals per agent (overrides the fraction).\n"
      "stretch_weight, anchor_weight: the regularisers (see solver/include/mocapedit/time_warp.h).";
  m.def(
      "time_warp_precompute",
      [](std::vector<Eigen::VectorXd> rest_times, const mocapedit::FramePairs& time_frames,
         const mocapedit::Flags& time_hard, const Eigen::VectorXd& time_weights,
         const mocapedit::FrameQuads& sync_frames, const mocapedit::Flags& sync_hard,
         const Eigen::VectorXd& sync_weights, double min_interval_fraction,
         std::vector<Eigen::VectorXd> min_intervals, double stretch_weight, double anchor_weight,
         int max_active_set_iterations, bool responses) {
        auto data = std::make_unique<mocapedit::TimeWarpData>();
        {
          py::gil_scoped_release release;
          mocapedit::TimeWarpProblem p =
              MakeProblem(std::move(rest_times), time_frames, time_hard, time_weights, sync_frames, sync_hard,
                          sync_weights, min_interval_fraction, std::move(min_intervals), stretch_weight,
                          anchor_weight, max_active_set_iterations);
          p.precompute_responses = responses;
          mocapedit::TimeWarpPrecompute(p, *data);
        }
        return data;
      },
      py::kw_only(), py::arg("rest_times"), py::arg("time_frames"), py::arg("time_hard"), py::arg("time_weights"),
      py::arg("sync_frames"), py::arg("sync_hard"), py::arg("sync_weights"), py::arg("min_interval_fraction") = 0.1,
      py::arg("min_intervals") = std::vector<Eigen::VectorXd>{}, py::arg("stretch_weight") = 1e-6,
      py::arg("anchor_weight") = 1e-6, py::arg("max_active_set_iterations") = -1, py::arg("responses") = false,
      (std::string("Splits agents linked by sync constraints into components and factors each.\n"
                   "responses: also keep each component's response to each constraint value it reads\n"
                   "(up to 16), for cheap re-solves as values change (see time_warp.h). Keyword\n"
                   "arguments only.\n\n") +
       structure_doc)
          .c_str());
  m.def(
      "time_warp",
      [](std::vector<Eigen::VectorXd> rest_times, const mocapedit::FramePairs& time_frames,
         const mocapedit::Flags& time_hard, const Eigen::VectorXd& time_weights, const Eigen::VectorXd& times,
         const mocapedit::FrameQuads& sync_frames, const mocapedit::Flags& sync_hard,
         const Eigen::VectorXd& sync_weights, const Eigen::VectorXd& offsets, double min_interval_fraction,
         std::vector<Eigen::VectorXd> min_intervals, double stretch_weight, double anchor_weight,
         int max_active_set_iterations) {
        TimeWarpResult r;
        {
          py::gil_scoped_release release;
          mocapedit::TimeWarp(MakeProblem(std::move(rest_times), time_frames, time_hard, time_weights,
                                          sync_frames, sync_hard, sync_weights, min_interval_fraction,
                                          std::move(min_intervals), stretch_weight, anchor_weight,
                                          max_active_set_iterations),
                              times, offsets, r);
        }
        return r;
      },
      py::kw_only(), py::arg("rest_times"), py::arg("time_frames"), py::arg("time_hard"), py::arg("time_weights"),
      py::arg("times"), py::arg("sync_frames"), py::arg("sync_hard"), py::arg("sync_weights"), py::arg("offsets"),
      py::arg("min_interval_fraction") = 0.1, py::arg("min_intervals") = std::vector<Eigen::VectorXd>{},
      py::arg("stretch_weight") = 1e-6, py::arg("anchor_weight") = 1e-6, py::arg("max_active_set_iterations") = -1,
      (std::string("Laplacian time warp of every agent's time map (precompute and solve in one call).\n"
                   "Keyword arguments only.\n\n") +
       structure_doc +
       "\ntimes: (T,) shot times; offsets: (S,) sync offsets.\n\n"
       "Returns a TimeWarpResult. Raises TimeWarpConflict (an InvalidInput) when hard constraints\n"
       "contradict each other or the minimum interval.")
          .c_str());
}
