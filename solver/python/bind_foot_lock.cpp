#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mocapedit/foot_lock.h"
#include "arrays.h"
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
}
