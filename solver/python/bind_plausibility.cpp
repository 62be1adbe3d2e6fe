#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mocapedit/plausibility.h"
#include "arrays.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Span;
using mocapedit::python::DoubleArray;
using mocapedit::python::IndexArray;
using mocapedit::python::View;

// `value` as a C-contiguous double array whose last dimensions are `tail` (-1: any length, the
// series' samples), with at least one dimension before them when `series` (leading axes are
// series measured each on its own). Its shape is checked here so the message names the argument.
DoubleArray Series(const py::handle& value, const std::vector<py::ssize_t>& tail, const char* name) {
  DoubleArray a = DoubleArray::ensure(value);
  if (!a) throw std::invalid_argument(std::string(name) + ": an array of numbers expected");
  const py::ssize_t lead = a.ndim() - static_cast<py::ssize_t>(tail.size());
  bool ok = lead >= 0;
  for (std::size_t k = 0; ok && k < tail.size(); ++k) ok = tail[k] < 0 || a.shape(lead + k) == tail[k];
  if (!ok) {
    std::string want = "(...";
    for (auto d : tail) want += ", " + (d < 0 ? std::string("T") : std::to_string(d));
    throw std::invalid_argument(std::string(name) + ": expected shape " + want + "), got " + std::to_string(a.ndim()) +
                                " dimensions");
  }
  return a;
}

std::vector<py::ssize_t> Shape(const DoubleArray& a, py::ssize_t drop) {
  return std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim() - drop);
}

void SameShape(const std::vector<py::ssize_t>& a, const std::vector<py::ssize_t>& b, const char* what) {
  if (a != b) throw std::invalid_argument(std::string(what) + " must pair sample by sample (the same leading shape)");
}

// Each series of the (rows, count) layout given by `shape` (its last entry the samples).
template <typename Fn>
void ForEachSeries(const std::vector<py::ssize_t>& shape, Fn&& fn) {
  const std::size_t count = shape.empty() ? 0 : static_cast<std::size_t>(shape.back());
  std::size_t rows = 1;
  for (std::size_t k = 0; k + 1 < shape.size(); ++k) rows *= static_cast<std::size_t>(shape[k]);
  for (std::size_t r = 0; r < rows; ++r) fn(r, count);
}

// plausibility's outputs, one value per agent.
struct PlausibilityResult {
  DoubleArray max_facing_rate, source_max_facing_rate, max_extra_facing_rate;
  IndexArray worst_turn_frame, spin_frames;
  DoubleArray max_direction_deviation;
  IndexArray worst_direction_frame;
  DoubleArray max_turned_deviation, max_edit_turn, length_ratio, time_warp_min, time_warp_max;
};

}  // namespace

MOCAPEDIT_BINDINGS(BindPlausibility) {
  m.def(
      "joint_facing",
      [](const py::handle& matrices_in, int up_axis) {
        const DoubleArray matrices = Series(matrices_in, {-1, 4, 4}, "matrices");
        const auto shape = Shape(matrices, 2);
        DoubleArray facing(shape);
        ForEachSeries(shape, [&](std::size_t r, std::size_t n) {
          mocapedit::JointFacing(Span<const double>(matrices.data() + 16 * n * r, 16 * n), up_axis,
                                 Span<double>(facing.mutable_data() + n * r, n));
        });
        return facing;
      },
      py::kw_only(), py::arg("matrices"), py::arg("up_axis"),
      "Heading of a joint's facing (radians, counter-clockwise about up, not unwrapped) at each\n"
      "sample of its world matrices (..., T, 4, 4): the ground projection of its most horizontal\n"
      "local axis. up_axis 1 (Y) or 2 (Z). Returns (..., T).");
  m.def(
      "turning_rates",
      [](const py::handle& facing_in, const py::handle& seconds_in) {
        const DoubleArray facing = Series(facing_in, {-1}, "facing"), seconds = Series(seconds_in, {-1}, "seconds");
        const auto shape = Shape(facing, 0);
        SameShape(shape, Shape(seconds, 0), "facing and seconds");
        auto out_shape = shape;
        if (!out_shape.empty()) out_shape.back() = std::max<py::ssize_t>(out_shape.back() - 1, 0);
        DoubleArray rates(out_shape);
        ForEachSeries(shape, [&](std::size_t r, std::size_t n) {
          const std::size_t m = n ? n - 1 : 0;
          mocapedit::TurningRates(Span<const double>(facing.data() + n * r, n), Span<const double>(seconds.data() + n * r, n),
                                  Span<double>(rates.mutable_data() + m * r, m));
        });
        return rates;
      },
      py::kw_only(), py::arg("facing"), py::arg("seconds"),
      "Unsigned turning rate (degrees per second) of a facing (..., T) radians between samples at\n"
      "increasing seconds (..., T): (..., T-1).");
  m.def(
      "direction_deviation",
      [](const py::handle& source_in, const py::handle& edited_in, const py::handle& seconds_in, double min_speed,
         double chord, const py::handle& turn_in) {
        const DoubleArray source = Series(source_in, {-1, 2}, "source"), edited = Series(edited_in, {-1, 2}, "edited");
        const DoubleArray seconds = Series(seconds_in, {-1}, "seconds");
        const auto shape = Shape(seconds, 0);
        SameShape(Shape(source, 1), shape, "source and seconds");
        SameShape(Shape(edited, 1), shape, "edited and seconds");
        DoubleArray turn;
        if (!turn_in.is_none()) {
          turn = Series(turn_in, {-1}, "turn");
          SameShape(Shape(turn, 0), shape, "turn and seconds");
        }
        DoubleArray deviation(shape);
        ForEachSeries(shape, [&](std::size_t r, std::size_t n) {
          mocapedit::DirectionDeviation(
              Span<const double>(source.data() + 2 * n * r, 2 * n), Span<const double>(edited.data() + 2 * n * r, 2 * n),
              Span<const double>(seconds.data() + n * r, n), min_speed, chord,
              turn_in.is_none() ? Span<const double>() : Span<const double>(turn.data() + n * r, n),
              Span<double>(deviation.mutable_data() + n * r, n));
        });
        return deviation;
      },
      py::kw_only(), py::arg("source"), py::arg("edited"), py::arg("seconds"), py::arg("min_speed"), py::arg("chord"),
      py::arg("turn") = py::none(),
      "Angle (degrees) between the edited and the source walking direction over chords of `chord`\n"
      "seconds: ground paths source, edited (..., T, 2) at seconds (..., T); NaN where the source is\n"
      "slower than min_speed or has no full chord; turn (..., T) radians turns the source chord\n"
      "first. Returns (..., T).");
  m.def(
      "edit_turn",
      [](const py::handle& source_in, const py::handle& edited_in, const py::handle& seconds_in, double min_speed,
         double span) {
        const DoubleArray source = Series(source_in, {-1, 2}, "source"), edited = Series(edited_in, {-1, 2}, "edited");
        const DoubleArray seconds = Series(seconds_in, {-1}, "seconds");
        const auto shape = Shape(seconds, 0);
        SameShape(Shape(source, 1), shape, "source and seconds");
        SameShape(Shape(edited, 1), shape, "edited and seconds");
        DoubleArray turn(shape);
        ForEachSeries(shape, [&](std::size_t r, std::size_t n) {
          mocapedit::EditTurn(Span<const double>(source.data() + 2 * n * r, 2 * n),
                              Span<const double>(edited.data() + 2 * n * r, 2 * n),
                              Span<const double>(seconds.data() + n * r, n), min_speed, span,
                              Span<double>(turn.mutable_data() + n * r, n));
        });
        return turn;
      },
      py::kw_only(), py::arg("source"), py::arg("edited"), py::arg("seconds"), py::arg("min_speed"), py::arg("span"),
      "The turn (radians, counter-clockwise, unwrapped) an edit gives a walk at each sample: source\n"
      "chord to edited chord over `span` seconds centred on it, interpolated where the source is\n"
      "slower than min_speed. Paths (..., T, 2), seconds (..., T). Returns (..., T).");

  py::class_<PlausibilityResult>(m, "PlausibilityResult", "Result of plausibility: one value per agent.")
      .def_readonly("max_facing_rate", &PlausibilityResult::max_facing_rate, "(A,) degrees per second, edited")
      .def_readonly("source_max_facing_rate", &PlausibilityResult::source_max_facing_rate, "(A,) degrees per second, source")
      .def_readonly("max_extra_facing_rate", &PlausibilityResult::max_extra_facing_rate, "(A,) edited rate less the source's")
      .def_readonly("worst_turn_frame", &PlausibilityResult::worst_turn_frame, "(A,) edited sample of the largest extra rate")
      .def_readonly("spin_frames", &PlausibilityResult::spin_frames, "(A,) intervals that spin")
      .def_readonly("max_direction_deviation", &PlausibilityResult::max_direction_deviation, "(A,) degrees")
      .def_readonly("worst_direction_frame", &PlausibilityResult::worst_direction_frame, "(A,) edited sample, -1: none")
      .def_readonly("max_turned_deviation", &PlausibilityResult::max_turned_deviation, "(A,) degrees")
      .def_readonly("max_edit_turn", &PlausibilityResult::max_edit_turn, "(A,) degrees")
      .def_readonly("length_ratio", &PlausibilityResult::length_ratio, "(A,) edited over source path length")
      .def_readonly("time_warp_min", &PlausibilityResult::time_warp_min, "(A,) smallest time warp")
      .def_readonly("time_warp_max", &PlausibilityResult::time_warp_max, "(A,) largest time warp");
  m.def(
      "plausibility",
      [](const py::handle& source_offsets_in, const py::handle& edited_offsets_in, const py::handle& source_seconds_in,
         const py::handle& source_hip_in, const py::handle& edited_seconds_in, const py::handle& edited_hip_in,
         const py::handle& edited_frames_in, int up_axis, double walking_speed, double chord, double edit_turn_span,
         double spin_rate) {
        const IndexArray source_offsets = IndexArray::ensure(source_offsets_in);
        const IndexArray edited_offsets = IndexArray::ensure(edited_offsets_in);
        if (!source_offsets || source_offsets.ndim() != 1 || source_offsets.size() < 1)
          throw std::invalid_argument("source_offsets: a (A+1,) integer array expected");
        if (!edited_offsets || edited_offsets.ndim() != 1 || edited_offsets.size() != source_offsets.size())
          throw std::invalid_argument("edited_offsets: a (A+1,) integer array expected, as long as source_offsets");
        const DoubleArray source_seconds = Series(source_seconds_in, {-1}, "source_seconds");
        const DoubleArray source_hip = Series(source_hip_in, {-1, 4, 4}, "source_hip");
        const DoubleArray edited_seconds = Series(edited_seconds_in, {-1}, "edited_seconds");
        const DoubleArray edited_hip = Series(edited_hip_in, {-1, 4, 4}, "edited_hip");
        DoubleArray edited_frames;
        if (!edited_frames_in.is_none()) edited_frames = Series(edited_frames_in, {-1}, "edited_frames");
        const py::ssize_t agents = source_offsets.size() - 1;
        PlausibilityResult out{DoubleArray(agents), DoubleArray(agents), DoubleArray(agents), IndexArray(agents),
                               IndexArray(agents), DoubleArray(agents), IndexArray(agents), DoubleArray(agents),
                               DoubleArray(agents), DoubleArray(agents), DoubleArray(agents), DoubleArray(agents)};
        mocapedit::PlausibilityJob job;
        job.source_offsets = Span<const std::int64_t>(source_offsets.data(), static_cast<std::size_t>(source_offsets.size()));
        job.edited_offsets = Span<const std::int64_t>(edited_offsets.data(), static_cast<std::size_t>(edited_offsets.size()));
        job.source_seconds = View(source_seconds), job.source_hip = View(source_hip);
        job.edited_seconds = View(edited_seconds), job.edited_hip = View(edited_hip);
        if (!edited_frames_in.is_none()) job.edited_frames = View(edited_frames);
        job.up_axis = up_axis, job.walking_speed = walking_speed, job.chord = chord;
        job.edit_turn_span = edit_turn_span, job.spin_rate = spin_rate;
        auto index = [](IndexArray& a) { return Span<std::int64_t>(a.mutable_data(), static_cast<std::size_t>(a.size())); };
        job.max_facing_rate = View(out.max_facing_rate), job.source_max_facing_rate = View(out.source_max_facing_rate);
        job.max_extra_facing_rate = View(out.max_extra_facing_rate), job.worst_turn_frame = index(out.worst_turn_frame);
        job.spin_frames = index(out.spin_frames), job.max_direction_deviation = View(out.max_direction_deviation);
        job.worst_direction_frame = index(out.worst_direction_frame);
        job.max_turned_deviation = View(out.max_turned_deviation), job.max_edit_turn = View(out.max_edit_turn);
        job.length_ratio = View(out.length_ratio), job.time_warp_min = View(out.time_warp_min);
        job.time_warp_max = View(out.time_warp_max);
        {
          py::gil_scoped_release release;
          job.Run();
        }
        return out;
      },
      py::kw_only(), py::arg("source_offsets"), py::arg("edited_offsets"), py::arg("source_seconds"),
      py::arg("source_hip"), py::arg("edited_seconds"), py::arg("edited_hip"), py::arg("edited_frames") = py::none(),
      py::arg("up_axis"), py::arg("walking_speed"), py::arg("chord"), py::arg("edit_turn_span"), py::arg("spin_rate"),
      "Plausibility figures of many agents (the C++ PlausibilityJob).\n\n"
      "source_offsets, edited_offsets (A+1,) int64 sample offsets per agent; source_seconds (S,),\n"
      "source_hip (S,4,4) facing joint world matrices; edited_seconds (E,), edited_hip (E,4,4);\n"
      "edited_frames (E,) source frame each edited sample plays, or None; up_axis 1 (Y) or 2 (Z);\n"
      "walking_speed stage units per second; chord and edit_turn_span seconds; spin_rate degrees\n"
      "per second. Returns a PlausibilityResult. Keyword arguments only.");
}
