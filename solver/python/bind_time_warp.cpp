#include <pybind11/eigen.h>
#include <pybind11/stl.h>

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

py::dict ToDict(const mocapedit::TimeWarpResult& r) {
  py::dict d;
  d["time_maps"] = r.time_maps;
  d["time_residuals"] = r.time_residuals;
  d["sync_residuals"] = r.sync_residuals;
  d["min_interval"] = r.min_interval;
  d["min_enforced"] = r.min_enforced;
  d["component"] = r.component;
  d["solver"] = r.solver;
  d["iterations"] = r.iterations;
  return d;
}

}  // namespace

MOCAPEDIT_BINDINGS(BindTimeWarp) {
  py::class_<mocapedit::TimeWarpData>(m, "TimeWarpData",
                                      "Factored time-warp components; re-solve with new constraint values.")
      .def_readonly("agents", &mocapedit::TimeWarpData::agents)
      .def_property_readonly("components", [](const mocapedit::TimeWarpData& d) { return d.components.size(); })
      .def_readonly("agent_component", &mocapedit::TimeWarpData::agent_component)
      .def(
          "solve",
          [](const mocapedit::TimeWarpData& d, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets) {
            mocapedit::TimeWarpResult r;
            {
              py::gil_scoped_release release;
              mocapedit::TimeWarpSolve(d, times, offsets, r);
            }
            return ToDict(r);
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
      py::arg("rest_times"), py::arg("time_frames"), py::arg("time_hard"), py::arg("time_weights"),
      py::arg("sync_frames"), py::arg("sync_hard"), py::arg("sync_weights"), py::arg("min_interval_fraction") = 0.1,
      py::arg("min_intervals") = std::vector<Eigen::VectorXd>{}, py::arg("stretch_weight") = 1e-6,
      py::arg("anchor_weight") = 1e-6, py::arg("max_active_set_iterations") = -1, py::arg("responses") = false,
      (std::string("Splits agents linked by sync constraints into components and factors each.\n"
                   "responses: also keep each component's response to each constraint value it reads\n"
                   "(up to 16), for cheap re-solves as values change (see time_warp.h).\n\n") +
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
        mocapedit::TimeWarpResult r;
        {
          py::gil_scoped_release release;
          mocapedit::TimeWarp(MakeProblem(std::move(rest_times), time_frames, time_hard, time_weights,
                                          sync_frames, sync_hard, sync_weights, min_interval_fraction,
                                          std::move(min_intervals), stretch_weight, anchor_weight,
                                          max_active_set_iterations),
                              times, offsets, r);
        }
        return ToDict(r);
      },
      py::arg("rest_times"), py::arg("time_frames"), py::arg("time_hard"), py::arg("time_weights"),
      py::arg("times"), py::arg("sync_frames"), py::arg("sync_hard"), py::arg("sync_weights"), py::arg("offsets"),
      py::arg("min_interval_fraction") = 0.1, py::arg("min_intervals") = std::vector<Eigen::VectorXd>{},
      py::arg("stretch_weight") = 1e-6, py::arg("anchor_weight") = 1e-6, py::arg("max_active_set_iterations") = -1,
      (std::string("Laplacian time warp of every agent's time map (precompute and solve in one call).\n\n") +
       structure_doc +
       "\ntimes: (T,) shot times; offsets: (S,) sync offsets.\n\n"
       "Returns a dict: time_maps (list of (F_a,)), time_residuals (T,), sync_residuals (S,),\n"
       "min_interval (A,), min_enforced (A,) intervals held at the minimum, component (A,),\n"
       "solver (A,) 'rest' | 'LDLT' | 'SPQR fallback', iterations (C,) active-set iterations.\n"
       "Raises TimeWarpConflict (a ValueError; args = (message, info dict)) when hard constraints\n"
       "contradict each other or the minimum interval.")
          .c_str());
}
