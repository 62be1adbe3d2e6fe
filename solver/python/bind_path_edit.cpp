#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <optional>

#include "mocapedit/path_edit.h"
#include "registry.h"

namespace py = pybind11;
using mocapedit::Trajectory2;

namespace {

// The classes first: the functions' signatures name them.
void BindPathEditClasses(py::module_& m) {
  py::class_<mocapedit::PathEditData>(
      m, "PathEditData", "Factored path-editing problem from path_edit_precompute; pass it to path_edit_solve.")
      .def_readonly("handle_count", &mocapedit::PathEditData::handle_count, "#H handles of the problem")
      .def_readonly("link_count", &mocapedit::PathEditData::link_count, "#L links of the problem");

  py::class_<mocapedit::StepInfo>(m, "StepInfo", "How one step of a path edit was solved, for the report.")
      .def_readonly("solver", &mocapedit::StepInfo::solver,
                    "'LDLT', 'LDLT (AMD)', 'CHOLMOD supernodal', 'SPQR', ... , 'rigid' or 'none'")
      .def_readonly("unknowns", &mocapedit::StepInfo::unknowns, "free vertices after elimination")
      .def_readonly("refinements", &mocapedit::StepInfo::refinements, "refinement passes of the last solve")
      .def_readonly("correction", &mocapedit::StepInfo::correction,
                    "size of the last refinement correction (stage units)");

  py::class_<mocapedit::PathEditResult>(m, "PathEditResult", "Result of path_edit_solve.")
      .def_readonly("positions", &mocapedit::PathEditResult::positions, "(V, 2) edited positions (step 2)")
      .def_readonly("shape", &mocapedit::PathEditResult::shape, "(V, 2) step-1 (shape) positions")
      .def_readonly("rigid_angles", &mocapedit::PathEditResult::rigid_angles,
                    "(R,) rotation in radians (CCW) applied to each rigid range")
      .def_readonly("rigid_motion", &mocapedit::PathEditResult::rigid_motion,
                    "True when one rigid motion met every constraint")
      .def_readonly("rigid_angle", &mocapedit::PathEditResult::rigid_angle, "that motion's rotation (radians)")
      .def_readonly("step1", &mocapedit::PathEditResult::step1, "how step 1 (shape) was solved")
      .def_readonly("step2", &mocapedit::PathEditResult::step2, "how step 2 (scale) was solved");
}

}  // namespace

MOCAPEDIT_BINDINGS(BindPathEdit) {
  BindPathEditClasses(m);
  m.def(
      "path_edit_precompute",
      [](const Trajectory2& rest, const mocapedit::IndexTriples& triangles, const Eigen::VectorXd& triangle_weights,
         const mocapedit::IndexPairs& edges, const Eigen::VectorXd& edge_weights,
         const std::vector<std::pair<std::vector<int>, std::string>>& rigid, const Eigen::VectorXi& handles,
         const Eigen::VectorXd& handle_weights, const mocapedit::IndexPairs& links, const Eigen::VectorXd& link_weights,
         double rigid_min_extent, bool precompute_responses, bool force_qr,
         const std::optional<Eigen::VectorXd>& vertex_times) {
        mocapedit::PathEditProblem p;
        p.rest = rest;
        p.triangles = triangles;
        p.triangle_weights = triangle_weights;
        p.edges = edges;
        p.edge_weights = edge_weights;
        for (const auto& r : rigid) {
          if (r.second != "rotate" && r.second != "translate")
            throw mocapedit::InvalidInput("PathEdit", "rigid mode must be 'rotate' or 'translate', got '" + r.second + "'");
          p.rigid.push_back({r.first, r.second == "rotate" ? mocapedit::RigidMode::kRotate
                                                           : mocapedit::RigidMode::kTranslate});
        }
        p.handles = handles;
        p.handle_weights = handle_weights;
        p.links = links;
        p.link_weights = link_weights;
        p.rigid_min_extent = rigid_min_extent;
        p.precompute_responses = precompute_responses;
        p.force_qr = force_qr;
        if (vertex_times) p.vertex_times = *vertex_times;
        mocapedit::PathEditData data;
        {
          py::gil_scoped_release release;
          mocapedit::PathEditPrecompute(p, data);
        }
        return data;
      },
      py::kw_only(), py::arg("rest"), py::arg("triangles") = mocapedit::IndexTriples(0, 3),
      py::arg("triangle_weights") = Eigen::VectorXd(), py::arg("edges") = mocapedit::IndexPairs(0, 2),
      py::arg("edge_weights") = Eigen::VectorXd(),
      py::arg("rigid") = std::vector<std::pair<std::vector<int>, std::string>>{},
      py::arg("handles") = Eigen::VectorXi(), py::arg("handle_weights") = Eigen::VectorXd(),
      py::arg("links") = mocapedit::IndexPairs(0, 2), py::arg("link_weights") = Eigen::VectorXd(),
      py::arg("rigid_min_extent") = 0.0, py::arg("precompute_responses") = false, py::arg("force_qr") = false,
      py::arg("vertex_times") = py::none(),
      "Builds and factors a two-step ARAP path-editing problem (see solver/include/mocapedit/path_edit.h).\n\n"
      "rest (V,2) rest positions; triangles (T,3) int (i, j, k): vertex i in the frame j->k (step 1);\n"
      "edges (E,2) int (j, k) (step 2); rigid: list of (vertex indices, 'rotate'|'translate');\n"
      "handles (H,) vertex per handle; links (L,2) (a, b) meaning P_a - P_b = offset; weights are\n"
      "per term, +inf for hard handles and links (empty: all 1, i.e. soft). rigid_min_extent: rotating\n"
      "ranges smaller than this turn with the edges around them. precompute_responses: also solve\n"
      "step 1 once per handle and link so each path_edit_solve only solves step 2 (dragging).\n"
      "force_qr: use sparse QR for both steps. vertex_times (V,) float or None: the time of each\n"
      "vertex (shot times for group members); large group meshes use them to order their\n"
      "factorization by nested dissection. Keyword arguments only; the GIL is released.");
  m.def(
      "path_edit_solve",
      [](const mocapedit::PathEditData& data, const Trajectory2& handle_positions, const Trajectory2& link_offsets) {
        mocapedit::PathEditResult r;
        {
          py::gil_scoped_release release;
          mocapedit::PathEditSolve(data, handle_positions, link_offsets, r);
        }
        return r;
      },
      py::arg("data"), py::arg("handle_positions"), py::arg("link_offsets"),
      "Solves both steps for (H,2) handle positions and (L,2) link offsets (P_a - P_b). Raises\n"
      "ContradictionError (an InvalidInput) when hard constraints disagree. The GIL is released.");
  m.def(
      "path_edit_condition",
      [](const mocapedit::PathEditData& data) {
        py::gil_scoped_release release;
        return mocapedit::PathEditConditionEstimate(data);
      },
      py::arg("data"), "(step 1, step 2) estimated condition numbers of the factored normal matrices.");
  m.def(
      "chain_terms",
      [](const Trajectory2& rest, int first, int count, double min_baseline) {
        mocapedit::IndexTriples t(0, 3);
        mocapedit::IndexPairs e(0, 2);
        mocapedit::AppendChainTerms(rest, first, count, min_baseline, t, e);
        return py::make_tuple(t, e);
      },
      py::arg("rest"), py::arg("first"), py::arg("count"), py::arg("min_baseline"),
      "(triangles (T,3), edges (count-1,2)) shape terms of one agent's frames first..first+count-1.");
}
