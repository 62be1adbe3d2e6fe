#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <optional>

#include "mocapedit/wait_search.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Trajectory2;

}  // namespace

MOCAPEDIT_BINDINGS(BindWaitSearch) {
  py::class_<mocapedit::WaitDelay>(m, "WaitDelay", "A delay found by WaitSearch.least_delay.")
      .def_readonly("delay", &mocapedit::WaitDelay::delay, "time codes")
      .def_readonly("start", &mocapedit::WaitDelay::start, "shot time where the slowing starts")
      .def_readonly("end", &mocapedit::WaitDelay::end, "shot time where it ends")
      .def_readonly("times", &mocapedit::WaitDelay::times, py::return_value_policy::copy,
                    "(F,) the walker's new time map");
  py::class_<mocapedit::WaitSearch>(
      m, "WaitSearch",
      "One round of waiting: every agent at the round's samples and their bounding boxes.\n\n"
      "positions: (K*A, 2) ground positions, time-major (row k*A + a is agent a at sample k);\n"
      "times: (K,) sample times; radius: (A,) capsule radii (stage units); margin: clearance kept\n"
      "beyond both radii; step: delays are tried in steps of it (time codes); block: samples per\n"
      "bounding box of the broad phase.")
      .def(py::init([](const Eigen::Ref<const Trajectory2>& positions, const Eigen::Ref<const Eigen::VectorXd>& times,
                       const Eigen::Ref<const Eigen::VectorXd>& radius, double time_codes_per_second,
                       double sample_step, double step, double margin, double slowest_pace, double passing_cos,
                       int block) {
             mocapedit::WaitSettings s;
             s.time_codes_per_second = time_codes_per_second;
             s.sample_step = sample_step;
             s.step = step;
             s.margin = margin;
             s.slowest_pace = slowest_pace;
             s.passing_cos = passing_cos;
             s.block = block;
             py::gil_scoped_release release;
             return mocapedit::WaitSearch(positions, times, radius, s);
           }),
           py::kw_only(), py::arg("positions"), py::arg("times"), py::arg("radius"), py::arg("time_codes_per_second"),
           py::arg("sample_step"), py::arg("step"), py::arg("margin"), py::arg("slowest_pace"),
           py::arg("passing_cos"), py::arg("block"))
      .def(
          "least_delay",
          [](const mocapedit::WaitSearch& search, int walker, int other, int first, int last, double room,
             double guess, const Eigen::Ref<const Trajectory2>& path, const Eigen::Ref<const Eigen::VectorXd>& times,
             const Eigen::Ref<const Eigen::VectorXd>& source_times) -> std::optional<mocapedit::WaitDelay> {
            mocapedit::WaitQuery q;
            q.walker = walker, q.other = other, q.first = first, q.last = last, q.room = room, q.guess = guess;
            mocapedit::WaitWalker w{path, times, source_times};
            mocapedit::WaitDelay found = search.LeastDelay(q, w);
            if (!found.found) return std::nullopt;
            return found;
          },
          py::kw_only(), py::arg("walker"), py::arg("other"), py::arg("first"), py::arg("last"), py::arg("room"),
          py::arg("guess"), py::arg("path"), py::arg("times"), py::arg("source_times"),
          "The least delay of `walker` (time codes, in steps from a step below `guess` up to `room`) that\n"
          "parts it from `other` over their encounter (samples first..last) and meets nobody new but\n"
          "walkers going its way; path (F, 2), times and source_times (F,) are the walker's path, current\n"
          "and source time maps. None when no delay does.");
  m.def(
      "smooth_delay",
      [](const Eigen::Ref<const Eigen::VectorXd>& times, double start, double end, double delay) {
        return mocapedit::SmoothDelay(times, start, end, delay);
      },
      py::arg("times"), py::arg("start"), py::arg("end"), py::arg("delay"),
      "(F,) the time map `times` with `delay` time codes taken up between shot times start and end\n"
      "by a smoothstep (no interval shrinks; every one after `end` is unchanged).");
}
