#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "mocapedit/skeleton_space.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;
using mocapedit::Span;

template <typename T, typename A>
Span<const T> View(const A& a) { return Span<const T>(a.data(), static_cast<std::size_t>(a.size())); }

// A (T, C, width) float32 pose array.
FloatArray PoseArray(const py::handle& value, py::ssize_t width, const char* name) {
  FloatArray a = FloatArray::ensure(value);
  if (!a || a.ndim() != 3 || a.shape(2) != width)
    throw std::invalid_argument(std::string(name) + ": expected shape (T, C, " + std::to_string(width) + ")");
  return a;
}

}  // namespace

MOCAPEDIT_BINDINGS(BindSkeletonSpace) {
  m.def(
      "skeleton_space",
      [](const py::handle& parents_in, const py::handle& columns_in, const py::handle& rest_in,
         const py::handle& translations_in, const py::handle& rotations_in, const py::handle& scales_in,
         const py::handle& joints_in, bool with_rotations) {
        const IndexArray parents = IndexArray::ensure(parents_in), columns = IndexArray::ensure(columns_in),
                         joints = IndexArray::ensure(joints_in);
        if (!parents || parents.ndim() != 1) throw std::invalid_argument("parents: a (J,) integer array expected");
        if (!columns || columns.ndim() != 1) throw std::invalid_argument("columns: a (J,) integer array expected");
        if (!joints || joints.ndim() != 1) throw std::invalid_argument("joints: a (K,) integer array expected");
        const DoubleArray rest = DoubleArray::ensure(rest_in);
        if (!rest || rest.ndim() != 3 || rest.shape(1) != 4 || rest.shape(2) != 4)
          throw std::invalid_argument("rest: expected shape (J, 4, 4)");
        const FloatArray t = PoseArray(translations_in, 3, "translations"), r = PoseArray(rotations_in, 4, "rotations"),
                         s = PoseArray(scales_in, 3, "scales");
        const py::ssize_t poses = t.shape(0), cols = t.shape(1);
        if (r.shape(0) != poses || r.shape(1) != cols || s.shape(0) != poses || s.shape(1) != cols)
          throw std::invalid_argument("translations, rotations and scales need the same (T, C)");
        DoubleArray matrices({poses, joints.size(), py::ssize_t{4}, py::ssize_t{4}});
        mocapedit::SkeletonSpaceJob job;
        job.parents = View<std::int64_t>(parents), job.columns = View<std::int64_t>(columns);
        job.rest = View<double>(rest), job.joints = View<std::int64_t>(joints);
        job.pose = mocapedit::ConstPoseStreamView(View<float>(t), View<float>(r), View<float>(s));
        job.pose_columns = cols;
        job.matrices = Span<double>(matrices.mutable_data(), static_cast<std::size_t>(matrices.size()));
        DoubleArray rotations({with_rotations ? poses : py::ssize_t{0}, joints.size(), py::ssize_t{4}});
        job.rotations = Span<double>(rotations.mutable_data(), static_cast<std::size_t>(rotations.size()));
        {
          py::gil_scoped_release release;
          job.Run();
        }
        if (with_rotations) return py::object(py::make_tuple(matrices, rotations));
        return py::object(matrices);
      },
      py::kw_only(), py::arg("parents"), py::arg("columns"), py::arg("rest"), py::arg("translations"),
      py::arg("rotations"), py::arg("scales"), py::arg("joints"), py::arg("with_rotations") = false,
      "Forward kinematics (the C++ SkeletonSpaceJob): (T, K, 4, 4) skeleton-space row-vector matrices of the\n"
      "wanted joints (K,) of (T, C, 3/4/3) float32 local transforms. parents (J,) -1 for roots, parents first;\n"
      "columns (J,) the pose column of each joint, -1 for its rest transform; rest (J, 4, 4). with_rotations: also\n"
      "(T, K, 4) each matrix's rotation (x, y, z, w; w >= 0) once its scales are divided out, as\n"
      "mocapedit.solve.layering.trs_from_matrices finds it; returns (matrices, rotations). Keyword arguments only.");
}
