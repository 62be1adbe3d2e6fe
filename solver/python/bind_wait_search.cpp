#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mocapedit/wait_search.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Trajectory2;

// The pairs tried over the rounds of one wait, held for Python (a class of its own: stl.h would
// convert a bare map to a dict and back on each call).
struct WaitMemory {
  mocapedit::WaitTried tried;
};

}  // namespace

MOCAPEDIT_BINDINGS(BindWaitSearch) {
  py::class_<mocapedit::WaitDelay>(m, "WaitDelay", "A delay found by wait_round.")
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
           py::arg("passing_cos"), py::arg("block"));
  py::class_<WaitMemory>(m, "WaitMemory", "The pairs that rounds of waiting have tried, and the delays both had then.")
      .def(py::init<>())
      .def("__len__", [](const WaitMemory& memory) { return memory.tried.size(); });
  m.def(
      "wait_round",
      [](const mocapedit::WaitSearch& search, const Eigen::Ref<const Eigen::VectorXi>& walkers,
         const Eigen::Ref<const Eigen::VectorXi>& others, const Eigen::Ref<const Eigen::VectorXi>& firsts,
         const Eigen::Ref<const Eigen::VectorXi>& lasts, const Eigen::Ref<const Eigen::VectorXd>& guesses,
         const py::list& paths, const py::list& times, const py::list& source_times, double budget, double step,
         const Eigen::Ref<const Eigen::VectorXd>& delay, WaitMemory& memory,
         const py::object& earliest_arg) {
        const bool has_earliest = !earliest_arg.is_none();
        const Eigen::VectorXd earliest = has_earliest ? earliest_arg.cast<Eigen::VectorXd>() : Eigen::VectorXd();
        const Eigen::Index n = walkers.size();
        if (others.size() != n || firsts.size() != n || lasts.size() != n || guesses.size() != n)
          throw std::invalid_argument("walkers, others, firsts, lasts and guesses need one entry per encounter");
        const auto agents = static_cast<size_t>(search.agents());
        if (py::len(paths) != agents || py::len(times) != agents || py::len(source_times) != agents ||
            static_cast<size_t>(delay.size()) != agents || (has_earliest && static_cast<size_t>(earliest.size()) != agents))
          throw std::invalid_argument("paths, times, source_times, delay and earliest need one entry per agent");
        using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
        std::vector<Array> held;
        held.reserve(3 * agents);
        std::vector<mocapedit::WaitWalker> frames;
        frames.reserve(agents);
        for (size_t a = 0; a < agents; ++a) {
          Array path = Array::ensure(paths[a]), t = Array::ensure(times[a]), src = Array::ensure(source_times[a]);
          if (!path || path.ndim() != 2 || path.shape(1) != 2 || !t || t.ndim() != 1 || !src || src.ndim() != 1)
            throw std::invalid_argument("agent " + std::to_string(a) + ": path (F, 2), times and source_times (F,) expected");
          frames.push_back({Eigen::Map<const mocapedit::Trajectory2>(path.data(), path.shape(0), 2),
                            Eigen::Map<const Eigen::VectorXd>(t.data(), t.shape(0)),
                            Eigen::Map<const Eigen::VectorXd>(src.data(), src.shape(0)),
                            has_earliest ? earliest[static_cast<Eigen::Index>(a)] : -std::numeric_limits<double>::infinity()});
          held.push_back(std::move(path)), held.push_back(std::move(t)), held.push_back(std::move(src));
        }
        std::vector<mocapedit::WaitEncounter> encounters(static_cast<size_t>(n));
        for (Eigen::Index i = 0; i < n; ++i)
          encounters[static_cast<size_t>(i)] = {walkers[i], others[i], firsts[i], lasts[i], guesses[i]};
        std::vector<double> taken(delay.data(), delay.data() + delay.size());
        std::vector<std::pair<int, mocapedit::WaitDelay>> found;
        {
          py::gil_scoped_release release;
          found = mocapedit::WaitRound(search, encounters, frames, budget, step, taken, memory.tried);
        }
        return found;
      },
      py::kw_only(), py::arg("search"), py::arg("walkers"), py::arg("others"), py::arg("firsts"), py::arg("lasts"),
      py::arg("guesses"), py::arg("paths"), py::arg("times"), py::arg("source_times"), py::arg("budget"),
      py::arg("step"), py::arg("delay"), py::arg("tried"), py::arg("earliest") = py::none(),
      "One round of waiting (the C++ WaitRound): the encounters (walkers, others, their first and last\n"
      "samples, first guesses) in turn, each walker taking the least delay of the first of its encounters\n"
      "that has one, at most one per round, within `budget` time codes in all (`delay` (A,): taken so far;\n"
      "passed over below `step` left) and not tried before with both delays as they are (`tried`, a\n"
      "WaitMemory, records every pair tried). paths (F, 2), times and source_times (F,): every agent's;\n"
      "earliest (A,) or None: the shot time before which each agent's time map stays as it is.\n"
      "Returns [(walker, WaitDelay)] in the order taken.");
  m.def(
      "smooth_delay",
      [](const Eigen::Ref<const Eigen::VectorXd>& times, double start, double end, double delay) {
        return mocapedit::SmoothDelay(times, start, end, delay);
      },
      py::arg("times"), py::arg("start"), py::arg("end"), py::arg("delay"),
      "(F,) the time map `times` with `delay` time codes taken up between shot times start and end\n"
      "by a smoothstep (no interval shrinks; every one after `end` is unchanged).");
}
