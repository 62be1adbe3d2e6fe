#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <tuple>

#include "mocapedit/path_terms.h"
#include "registry.h"

namespace py = pybind11;
using mocapedit::Trajectory2;
using IntGrid = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// The GIL is released while the solver runs; arguments and results convert with it held.
const py::call_guard<py::gil_scoped_release> kReleaseGil;

MOCAPEDIT_BINDINGS(BindPathTerms) {
  m.def(
      "component_chain_terms",
      [](const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
         double min_baseline) {
        mocapedit::IndexTriples t(0, 3);
        mocapedit::IndexPairs e(0, 2);
        mocapedit::ComponentChainTerms(rest, offsets, min_baseline, t, e);
        return std::make_tuple(t, e);
      },
      kReleaseGil, py::arg("rest"), py::arg("offsets"), py::arg("min_baseline"),
      "(triangles (T,3), edges (V-A,2)) shape terms of every agent: rest (V,2) concatenated,\n"
      "offsets (A+1,) int32 first vertex of each agent then V. chain_terms for each agent in order.");
  m.def(
      "key_frames",
      [](const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
         const Eigen::Ref<const Eigen::VectorXi>& keyed, const Eigen::Ref<const Eigen::VectorXi>& forced,
         double min_baseline) {
        Eigen::VectorXi keys, before;
        mocapedit::KeyFrames(rest, offsets, keyed, forced, min_baseline, keys, before);
        return std::make_tuple(keys, before);
      },
      kReleaseGil, py::kw_only(), py::arg("rest"), py::arg("offsets"), py::arg("keyed"), py::arg("forced"), py::arg("min_baseline"),
      "(keys (K,), before (V,)) int32: key frames of agents solved on keys (keyed (A,) int32 flags),\n"
      "forced (N,) int32 frames that must be keys, and per frame how many keys precede it.");
  m.def(
      "expand_key_frames",
      [](const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& keys,
         const Eigen::Ref<const Trajectory2>& positions) {
        Trajectory2 out;
        mocapedit::ExpandKeyFrames(rest, keys, positions, out);
        return out;
      },
      kReleaseGil, py::arg("rest"), py::arg("keys"), py::arg("positions"),
      "(V,2) every frame from the (K,2) solved positions of the keys (K,) int32: frames between\n"
      "two keys follow the similarity taking the keys' rest positions to their solved ones.");
  m.def(
      "group_sample_frames",
      [](const Eigen::Ref<const Eigen::VectorXd>& sample_times, const Eigen::Ref<const Eigen::VectorXi>& offsets,
         const Eigen::Ref<const Eigen::VectorXd>& times) {
        IntGrid frames;
        mocapedit::GroupSampleFrames(sample_times, offsets, times, frames);
        return frames;
      },
      kReleaseGil, py::arg("sample_times"), py::arg("offsets"), py::arg("times"),
      "(M,T) int32 frame of each member at each sampled time, -1 where it has none (within 1e-6):\n"
      "sample_times (F,) concatenated, offsets (M+1,) int32, times (T,).");
  m.def(
      "frame_partners",
      [](const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
         double min_baseline) {
        Eigen::VectorXi partner;
        mocapedit::FramePartners(rest, offsets, min_baseline, partner);
        return partner;
      },
      kReleaseGil, py::arg("rest"), py::arg("offsets"), py::arg("min_baseline"),
      "(V,) int32 frame partner of each vertex for group triangles (-1: none); rest (V,2),\n"
      "offsets (A+1,) int32.");
  m.def(
      "group_mesh_terms",
      [](const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const IntGrid>& members, int neighbours,
         const Eigen::Ref<const Eigen::VectorXi>& partner) {
        mocapedit::IndexTriples t(0, 3);
        mocapedit::IndexPairs e(0, 2);
        mocapedit::GroupMeshTerms(rest, members, neighbours, partner, t, e);
        return std::make_tuple(t, e);
      },
      kReleaseGil, py::arg("rest"), py::arg("members"), py::arg("neighbours"), py::arg("partner"),
      "(triangles (t,3), edges (e,2)) of a group mesh: members (M,T) int32 vertex of each member at\n"
      "each sampled time, each joined to its `neighbours` nearest there; partner (V,) int32.");
  m.def(
      "block_deformation_turns",
      [](const Eigen::Ref<const Trajectory2>& source, const Eigen::Ref<const Trajectory2>& edited,
         const Eigen::Ref<const mocapedit::IndexPairs>& blocks, const Eigen::Ref<const mocapedit::IndexTriples>& fixed,
         const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window, double min_travel, double max_step,
         const Eigen::Ref<const Eigen::VectorXi>& keep_spot) {
        Eigen::VectorXd out;
        mocapedit::BlockDeformationTurns(source, edited, blocks, fixed, fixed_turn, window, min_travel, max_step,
                                         keep_spot, out);
        return out;
      },
      kReleaseGil, py::kw_only(), py::arg("source"), py::arg("edited"), py::arg("blocks"), py::arg("fixed"), py::arg("fixed_turn"),
      py::arg("window"), py::arg("min_travel"), py::arg("max_step") = 0.0, py::arg("keep_spot") = Eigen::VectorXi(),
      "(V,) turn of each frame's heading from source to edited paths (V,2), block by block: blocks (B,2)\n"
      "int32 [begin, end), fixed (R,3) int32 (block, first, last) grouped by block, fixed_turn (R,),\n"
      "window (frames), min_travel (stage units), max_step (stage units per frame, 0: none), keep_spot\n"
      "(B,) int32 (nonzero: a path about one spot keeps its facing; empty: every block); see\n"
      "DeformationTurns in trajectory.h.");
  m.def(
      "null_space_support",
      [](const Eigen::Ref<const Eigen::VectorXi>& rows, const Eigen::Ref<const Eigen::VectorXi>& cols,
         const Eigen::Ref<const Eigen::VectorXcd>& values, int num_rows, int num_cols, double tolerance) {
        const std::vector<char> used = mocapedit::NullSpaceSupport(rows, cols, values, num_rows, num_cols, tolerance);
        Eigen::Matrix<bool, Eigen::Dynamic, 1> out(static_cast<Eigen::Index>(used.size()));
        for (size_t c = 0; c < used.size(); ++c) out[static_cast<Eigen::Index>(c)] = used[c] != 0;
        return out;
      },
      py::kw_only(), py::arg("rows"), py::arg("cols"), py::arg("values"), py::arg("num_rows"), py::arg("num_cols"),
      py::arg("tolerance") = 1e-9,
      "(C,) bool: columns of the sparse complex (R,C) matrix given by (rows, cols, values) entries\n"
      "(int32, int32, complex128; repeats summed) that some null vector uses.");
}
