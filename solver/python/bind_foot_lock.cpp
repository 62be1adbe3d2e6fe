#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mocapedit/foot_lock.h"
#include "arrays.h"
#include "mocapedit/foot_plant.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Span;
using mocapedit::python::DoubleArray;
using mocapedit::python::IndexArray;
using mocapedit::python::View;

// An (N, 2, width) input as a C-contiguous double array; its shape is checked here so the
// message names the argument.
DoubleArray Legs(const py::handle& value, py::ssize_t n, py::ssize_t width, const char* name) {
  DoubleArray a = DoubleArray::ensure(value);
  if (!a) throw std::invalid_argument(std::string(name) + ": an array of numbers expected");
  const bool ok = width == 1 ? (a.ndim() == 2 && a.shape(0) == n && a.shape(1) == 2)
                             : (a.ndim() == 3 && a.shape(0) == n && a.shape(1) == 2 && a.shape(2) == width);
  if (!ok)
    throw std::invalid_argument(std::string(name) + ": expected shape (" + std::to_string(n) + ", 2" +
                                (width == 1 ? std::string() : ", " + std::to_string(width)) + ")");
  return a;
}

// An (N,) or (A,) array of the given type, C-contiguous, with its length checked.
template <typename T>
py::array_t<T, py::array::c_style | py::array::forcecast> Flat(const py::handle& value, py::ssize_t n, const char* name) {
  auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(value);
  if (!a || a.ndim() != 1 || a.shape(0) != n)
    throw std::invalid_argument(std::string(name) + ": expected shape (" + std::to_string(n) + ",)");
  return a;
}

// plan_feet's outputs.
struct FootPlantResult {
  DoubleArray target;       // (N, 2, 3)
  DoubleArray target_rot;   // (N, 2, 4)
  DoubleArray weight;       // (N, 2)
  py::array_t<bool> stepping;  // (N, 2)
  IndexArray steps;         // (A,)
};

// lock_feet's outputs.
struct FootLockResult {
  DoubleArray hip_local, knee_local, ankle_local;  // (N, 2, 4) joint-local quaternions xyzw
  DoubleArray drop;                                // (N,) pelvis drop along -up
  DoubleArray reached;                             // (N, 2, 3) ankle positions after locking
};

}  // namespace

MOCAPEDIT_BINDINGS(BindFootLock) {
  py::class_<FootLockResult>(m, "FootLockResult", "Result of lock_feet.")
      .def_readonly("hip_local", &FootLockResult::hip_local, py::return_value_policy::copy, "(N, 2, 4) hip joint-local quaternions (x, y, z, w)")
      .def_readonly("knee_local", &FootLockResult::knee_local, py::return_value_policy::copy, "(N, 2, 4) knee joint-local quaternions")
      .def_readonly("ankle_local", &FootLockResult::ankle_local, py::return_value_policy::copy, "(N, 2, 4) ankle joint-local quaternions")
      .def_readonly("drop", &FootLockResult::drop, py::return_value_policy::copy, "(N,) how far the pelvis is lowered along -up, world units")
      .def_readonly("reached", &FootLockResult::reached, py::return_value_policy::copy, "(N, 2, 3) world ankle positions after locking");
  m.def(
      "lock_feet",
      [](const py::handle& offsets_in, const py::handle& smooth_in, const py::handle& up_in, const py::handle& hip_in,
         const py::handle& knee_in, const py::handle& ankle_in, const py::handle& parent_rot_in,
         const py::handle& hip_rot_in, const py::handle& knee_rot_in, const py::handle& ankle_rot_in,
         const py::handle& target_in, const py::handle& target_rot_in, const py::handle& weight_in,
         const py::handle& hinge_in, const py::handle& keep_in, int threads) {
        const IndexArray offsets = IndexArray::ensure(offsets_in), smooth = IndexArray::ensure(smooth_in);
        const DoubleArray up = DoubleArray::ensure(up_in);
        if (!offsets || offsets.ndim() != 1 || offsets.size() < 1)
          throw std::invalid_argument("offsets: a (A+1,) integer array expected");
        if (!smooth || smooth.ndim() != 1) throw std::invalid_argument("smooth: a (A,) integer array expected");
        if (!up) throw std::invalid_argument("up: 3 numbers expected");
        const py::ssize_t n = static_cast<py::ssize_t>(offsets.data()[offsets.size() - 1]);
        if (n < 0) throw std::invalid_argument("offsets: the last offset must not be negative");
        const DoubleArray hip = Legs(hip_in, n, 3, "hip"), knee = Legs(knee_in, n, 3, "knee"),
                          ankle = Legs(ankle_in, n, 3, "ankle"), parent_rot = Legs(parent_rot_in, n, 4, "parent_rot"),
                          hip_rot = Legs(hip_rot_in, n, 4, "hip_rot"), knee_rot = Legs(knee_rot_in, n, 4, "knee_rot"),
                          ankle_rot = Legs(ankle_rot_in, n, 4, "ankle_rot"), target = Legs(target_in, n, 3, "target"),
                          target_rot = Legs(target_rot_in, n, 4, "target_rot"), weight = Legs(weight_in, n, 1, "weight"),
                          hinge = Legs(hinge_in, n, 3, "hinge");
        DoubleArray hip_local({n, py::ssize_t{2}, py::ssize_t{4}}), knee_local({n, py::ssize_t{2}, py::ssize_t{4}}),
            ankle_local({n, py::ssize_t{2}, py::ssize_t{4}}), drop(std::vector<py::ssize_t>{n}),
            reached({n, py::ssize_t{2}, py::ssize_t{3}});
        mocapedit::FootLockJob job;
        job.offsets = Span<const std::int64_t>(offsets.data(), static_cast<std::size_t>(offsets.size()));
        job.smooth = Span<const std::int64_t>(smooth.data(), static_cast<std::size_t>(smooth.size()));
        job.up = View(up);
        job.hip = View(hip), job.knee = View(knee), job.ankle = View(ankle);
        job.parent_rot = View(parent_rot), job.hip_rot = View(hip_rot), job.knee_rot = View(knee_rot);
        job.ankle_rot = View(ankle_rot), job.target = View(target), job.target_rot = View(target_rot);
        job.weight = View(weight);
        job.hinge = View(hinge);
        using KeepArray = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>;
        const KeepArray keep = KeepArray::ensure(keep_in);
        if (!keep || keep.ndim() != 1 || (keep.size() != 0 && keep.size() != n))
          throw std::invalid_argument("keep: expected shape (" + std::to_string(n) + ",) or (0,)");
        job.keep = Span<const std::uint8_t>(keep.data(), static_cast<std::size_t>(keep.size()));
        job.threads = threads;
        job.hip_local = View(hip_local), job.knee_local = View(knee_local), job.ankle_local = View(ankle_local);
        job.drop = View(drop), job.reached = View(reached);
        {
          py::gil_scoped_release release;
          job.Run();
        }
        return FootLockResult{hip_local, knee_local, ankle_local, drop, reached};
      },
      py::kw_only(), py::arg("offsets"), py::arg("smooth"), py::arg("up"), py::arg("hip"), py::arg("knee"), py::arg("ankle"),
      py::arg("parent_rot"), py::arg("hip_rot"), py::arg("knee_rot"), py::arg("ankle_rot"), py::arg("target"),
      py::arg("target_rot"), py::arg("weight"), py::arg("hinge"), py::arg("keep"), py::arg("threads") = 0,
      "Holds planted feet in place by two-bone leg IK (the C++ FootLockJob), for many agents.\n\n"
      "offsets (A+1,) int64 pose offsets per agent; smooth (A,) frames of pelvis easing; up (3,)\n"
      "unit world up; hip, knee, ankle (N,2,3) world positions; parent_rot, hip_rot, knee_rot,\n"
      "ankle_rot (N,2,4) world quaternions xyzw; target (N,2,3), target_rot (N,2,4) planted ankle;\n"
      "weight (N,2) in [0,1]; hinge (N,2,3) knee hinge axes, world; keep (N,) uint8 poses the pelvis drop must not touch, or (0,).\n"
      "Returns a FootLockResult. Keyword arguments only.");

  py::class_<FootPlantResult>(m, "FootPlantResult", "Result of plan_feet.")
      .def_readonly("target", &FootPlantResult::target, py::return_value_policy::copy, "(N, 2, 3) planted ankle positions (the edited ankle where weight is 0)")
      .def_readonly("target_rot", &FootPlantResult::target_rot, py::return_value_policy::copy, "(N, 2, 4) planted ankle rotations (x, y, z, w)")
      .def_readonly("weight", &FootPlantResult::weight, py::return_value_policy::copy, "(N, 2) how much of the plant each leg reaches, in [0, 1]")
      .def_readonly("stepping", &FootPlantResult::stepping, py::return_value_policy::copy, "(N, 2) the foot is stepping (in the air)")
      .def_readonly("steps", &FootPlantResult::steps, py::return_value_policy::copy, "(A,) steps each agent takes");
  m.def(
      "plan_feet",
      [](const py::handle& offsets_in, const py::handle& frames_in, const py::handle& seconds_in,
         const py::handle& stationary_in, const py::handle& turn_in, const py::handle& hip_in, const py::handle& knee_in,
         const py::handle& ankle_in, const py::handle& ankle_rot_in, const py::handle& source_hip_in,
         const py::handle& source_ankle_in, const py::handle& source_hip_rot_in, const py::handle& source_knee_rot_in,
         const py::handle& source_ankle_rot_in, const py::handle& contact_offsets_in, const py::handle& contacts_in,
         const py::handle& blend_in, const py::handle& stretch_in, const py::handle& turn_leash_in,
         const py::handle& reach_leash_in, const py::handle& step_leash_in, const py::handle& up_in, double meters_per_unit,
         double leash_m, double max_leash_m, double max_drop_m, double leash_degrees, double soft_reach,
         double step_slide_m, double step_slide_degrees, double step_seconds, double step_longest_seconds,
         double step_height_m, double step_foot_speed_ratio, double step_min_foot_speed_m,
         double step_min_turn_speed, double step_min_knee_speed, int threads) {
        const IndexArray offsets = IndexArray::ensure(offsets_in);
        if (!offsets || offsets.ndim() != 1 || offsets.size() < 1)
          throw std::invalid_argument("offsets: a (A+1,) integer array expected");
        const py::ssize_t agents = offsets.size() - 1;
        const py::ssize_t n = static_cast<py::ssize_t>(offsets.data()[agents]);
        if (n < 0) throw std::invalid_argument("offsets: the last offset must not be negative");
        const DoubleArray frames = Flat<double>(frames_in, n, "frames"), seconds = Flat<double>(seconds_in, n, "seconds"),
                          turn = Flat<double>(turn_in, n, "turn"), blend = Flat<double>(blend_in, agents, "blend"),
                          turn_leash = Flat<double>(turn_leash_in, agents, "turn_leash"),
                          reach_leash = Flat<double>(reach_leash_in, agents, "reach_leash"),
                          step_leash = Flat<double>(step_leash_in, agents, "step_leash"),
                          up = Flat<double>(up_in, 3, "up");
        using FlagArray = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>;
        const FlagArray stationary = Flat<std::uint8_t>(stationary_in, n, "stationary");
        const DoubleArray hip = Legs(hip_in, n, 3, "hip"), knee = Legs(knee_in, n, 3, "knee"),
                          ankle = Legs(ankle_in, n, 3, "ankle"), ankle_rot = Legs(ankle_rot_in, n, 4, "ankle_rot"),
                          source_hip = Legs(source_hip_in, n, 3, "source_hip"),
                          source_ankle = Legs(source_ankle_in, n, 3, "source_ankle"),
                          source_hip_rot = Legs(source_hip_rot_in, n, 4, "source_hip_rot"),
                          source_knee_rot = Legs(source_knee_rot_in, n, 4, "source_knee_rot"),
                          source_ankle_rot = Legs(source_ankle_rot_in, n, 4, "source_ankle_rot"),
                          stretch = Legs(stretch_in, agents, 1, "stretch");
        const IndexArray contact_offsets = Flat<std::int64_t>(contact_offsets_in, 2 * agents + 1, "contact_offsets");
        const py::ssize_t contact_count = contact_offsets.data()[2 * agents];
        DoubleArray contacts = DoubleArray::ensure(contacts_in);
        if (!contacts || contacts.ndim() != 2 || contacts.shape(0) != contact_count || contacts.shape(1) != 2)
          throw std::invalid_argument("contacts: expected shape (" + std::to_string(contact_count) + ", 2)");
        DoubleArray target({n, py::ssize_t{2}, py::ssize_t{3}}), target_rot({n, py::ssize_t{2}, py::ssize_t{4}}),
            weight({n, py::ssize_t{2}});
        py::array_t<bool> stepping({n, py::ssize_t{2}});
        IndexArray steps(std::vector<py::ssize_t>{agents});
        static_assert(sizeof(bool) == 1, "stepping flags are written as bytes");
        mocapedit::FootPlantJob job;
        job.offsets = Span<const std::int64_t>(offsets.data(), static_cast<std::size_t>(offsets.size()));
        job.frames = View(frames), job.seconds = View(seconds), job.turn = View(turn);
        job.stationary = Span<const std::uint8_t>(stationary.data(), static_cast<std::size_t>(stationary.size()));
        job.hip = View(hip), job.knee = View(knee), job.ankle = View(ankle), job.ankle_rot = View(ankle_rot);
        job.source_hip = View(source_hip), job.source_ankle = View(source_ankle);
        job.source_hip_rot = View(source_hip_rot), job.source_knee_rot = View(source_knee_rot);
        job.source_ankle_rot = View(source_ankle_rot);
        job.contact_offsets =
            Span<const std::int64_t>(contact_offsets.data(), static_cast<std::size_t>(contact_offsets.size()));
        job.contacts = View(contacts), job.blend = View(blend), job.stretch = View(stretch), job.up = View(up);
        job.turn_leash = View(turn_leash), job.reach_leash = View(reach_leash), job.step_leash = View(step_leash);
        job.meters_per_unit = meters_per_unit, job.leash_m = leash_m, job.max_leash_m = max_leash_m;
        job.max_drop_m = max_drop_m, job.leash_degrees = leash_degrees, job.soft_reach = soft_reach;
        job.step_slide_m = step_slide_m, job.step_slide_degrees = step_slide_degrees, job.step_seconds = step_seconds;
        job.step_longest_seconds = step_longest_seconds, job.step_height_m = step_height_m;
        job.step_foot_speed_ratio = step_foot_speed_ratio, job.step_min_foot_speed_m = step_min_foot_speed_m;
        job.step_min_turn_speed = step_min_turn_speed, job.step_min_knee_speed = step_min_knee_speed;
        job.threads = threads;
        job.target = View(target), job.target_rot = View(target_rot), job.weight = View(weight);
        job.stepping = Span<std::uint8_t>(reinterpret_cast<std::uint8_t*>(stepping.mutable_data()),
                                          static_cast<std::size_t>(stepping.size()));
        job.steps = Span<std::int64_t>(steps.mutable_data(), static_cast<std::size_t>(steps.size()));
        {
          py::gil_scoped_release release;
          job.Run();
        }
        return FootPlantResult{target, target_rot, weight, stepping, steps};
      },
      py::kw_only(), py::arg("offsets"), py::arg("frames"), py::arg("seconds"), py::arg("stationary"), py::arg("turn"),
      py::arg("hip"), py::arg("knee"), py::arg("ankle"), py::arg("ankle_rot"), py::arg("source_hip"),
      py::arg("source_ankle"), py::arg("source_hip_rot"), py::arg("source_knee_rot"), py::arg("source_ankle_rot"),
      py::arg("contact_offsets"), py::arg("contacts"), py::arg("blend"), py::arg("stretch"), py::arg("turn_leash"), py::arg("reach_leash"), py::arg("step_leash"), py::arg("up"),
      py::arg("meters_per_unit"), py::arg("leash_m"), py::arg("max_leash_m"), py::arg("max_drop_m"),
      py::arg("leash_degrees"), py::arg("soft_reach"), py::arg("step_slide_m"), py::arg("step_slide_degrees"),
      py::arg("step_seconds"), py::arg("step_longest_seconds"), py::arg("step_height_m"),
      py::arg("step_foot_speed_ratio"), py::arg("step_min_foot_speed_m"), py::arg("step_min_turn_speed"),
      py::arg("step_min_knee_speed"), py::arg("threads") = 0,
      "Where planted feet go while an edit drags the body (the C++ FootPlantJob), for many agents.\n\n"
      "offsets (A+1,) int64 pose offsets per agent; frames, seconds, turn (N,) source frame, time in seconds\n"
      "and the edit's turn about up; stationary (N,) uint8; hip, knee, ankle (N,2,3) and ankle_rot (N,2,4)\n"
      "world, as edited; source_hip, source_ankle (N,2,3) and source_hip_rot, source_knee_rot,\n"
      "source_ankle_rot (N,2,4) world, posed before the edit's ground motion; contact_offsets (2A+1,) int64\n"
      "and contacts (R,2) inclusive source frame ranges per agent and leg; blend (A,) frames; stretch (A,2);\n"
      "turn_leash (A,) times leash_degrees each agent's plants may lag the turn; reach_leash (A,) times\n"
      "max_leash_m they may lie from the edited foot; step_leash (A,) times max_leash_m a foot may lie from\n"
      "its plant before it steps (above reach_leash: reach_leash);\n"
      "up (3,) +Y or +Z; lengths named _m in metres; speeds in metres or radians per second. Returns a\n"
      "FootPlantResult. Keyword arguments only.");
}
