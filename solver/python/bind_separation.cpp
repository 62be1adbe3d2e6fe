#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <memory>

#include "mocapedit/separation.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Trajectory2;

class SeparationSolver {
 public:
  SeparationSolver(const Eigen::Ref<const Trajectory2>& rest, const Eigen::VectorXi& starts,
                   const std::vector<mocapedit::FrameRange>& rigid, double anchor_weight,
                   const Eigen::VectorXd& rates, const Eigen::VectorXd& anchor_frames, const Eigen::VectorXi& cut_into,
                   double still_extent,
                   double min_baseline, int threads) {
    mocapedit::SeparationProblem problem;
    problem.rest = rest;
    problem.starts = starts;
    problem.rigid = rigid;
    problem.anchor_weight = anchor_weight;
    problem.rates = rates;
    problem.anchor_frames = anchor_frames;
    problem.cut_into = cut_into;
    problem.still_extent = still_extent;
    problem.min_baseline = min_baseline;
    problem.threads = threads;
    py::gil_scoped_release release;
    mocapedit::SeparationPrecompute(problem, data_);
    cache_ = mocapedit::SeparationNewCache();
  }

  mocapedit::SeparationResult Solve(const Eigen::Ref<const Trajectory2>& direction, const Eigen::VectorXd& rhs,
                 const Eigen::VectorXd& softness, const Eigen::VectorXi& term_row, const Eigen::VectorXi& term_vertex,
                 const Eigen::VectorXd& term_weight, const Eigen::VectorXi& kind,
                 const Eigen::VectorXd& initial_forces, double tolerance, int max_sweeps,
                 const Eigen::VectorXd& initial_shape_forces, double relaxation, int64_t split_from) {
    mocapedit::SeparationRows rows;
    rows.direction = direction;
    rows.rhs = rhs;
    rows.softness = softness;
    rows.kind = kind;
    rows.initial_forces = initial_forces;
    rows.initial_shape_forces = initial_shape_forces;
    mocapedit::SeparationSettings settings;
    settings.tolerance = tolerance;
    settings.max_sweeps = max_sweeps;
    settings.relaxation = relaxation;
    settings.split_from = split_from;
    rows.term_row = term_row;
    rows.term_vertex = term_vertex;
    rows.term_weight = term_weight;
    mocapedit::SeparationResult result;
    {
      py::gil_scoped_release release;
      mocapedit::SeparationSolve(data_, rows, settings, *cache_, result);
    }
    return result;
  }

  int agents() const { return mocapedit::SeparationAgentCount(data_); }
  int vertices() const { return mocapedit::SeparationVertexCount(data_); }

 private:
  mocapedit::SeparationData data_;
  std::unique_ptr<mocapedit::SeparationCache, mocapedit::SeparationCacheDeleter> cache_;
};

}  // namespace

MOCAPEDIT_BINDINGS(BindSeparation) {
  using mocapedit::SeparationResult;
  py::class_<SeparationResult>(m, "SeparationResult", "Result of SeparationSolver.solve.")
      .def_readonly("positions", &SeparationResult::positions, py::return_value_policy::copy, "(V, 2) after step 2 (untouched agents keep rest)")
      .def_readonly("shape", &SeparationResult::shape, py::return_value_policy::copy, "(V, 2) after step 1")
      .def_readonly("forces", &SeparationResult::forces, py::return_value_policy::copy, "(R,) step-2 row forces: > 0 pushes the row value up")
      .def_readonly("shape_forces", &SeparationResult::shape_forces, py::return_value_policy::copy, "(R,) step-1 row forces")
      .def_readonly("residuals", &SeparationResult::residuals, py::return_value_policy::copy, "(R,) row value minus rhs after step 2")
      .def_readonly("rigid_angles", &SeparationResult::rigid_angles, py::return_value_policy::copy,
                    "rotation of each rigid range in step 2 (radians, CCW)")
      .def_readonly("moved_agents", &SeparationResult::moved_agents, py::return_value_policy::copy, "agents some row touched")
      .def_readonly("sweeps", &SeparationResult::sweeps, py::return_value_policy::copy, "Gauss-Seidel sweeps, both steps")
      .def_readonly("updates", &SeparationResult::updates, py::return_value_policy::copy, "row force changes the sweeps passed on")
      .def_readonly("inverse_columns", &SeparationResult::inverse_columns, py::return_value_policy::copy,
                    "back-substitutions for the agents' blocks (the rest were cached)")
      .def_readonly("converged", &SeparationResult::converged, py::return_value_policy::copy, "both steps met the tolerance")
      .def_readonly("regularized", &SeparationResult::regularized, py::return_value_policy::copy,
                    "the hard equality rows were dependent: a tiny softness was added")
      .def_readonly("seconds", &SeparationResult::seconds, py::return_value_policy::copy,
                    "(4,) wall seconds in the blocks, the sweeps, the responses and gathering the rows");
  py::class_<SeparationSolver>(
      m, "SeparationSolver",
      "Agents' paths kept by the two-step Laplacian energy (factored once), coupled by linear\n"
      "rows on ground positions that change from solve to solve (collision avoidance).\n\n"
      "rest: (V, 2) agents' paths concatenated; starts: (A+1,) first vertex of each agent, then V;\n"
      "rigid: inclusive global vertex ranges that move rigidly (stationary ranges);\n"
      "anchor_weight: pull of every frame towards its rest position, relative to the shape terms;\n"
      "rates: (A,) each agent's samples per unit of time, relative to the rate the weights hold at\n"
      "(empty: 1 for all): an agent at k weighs its anchors 1/k, its shape terms k^3 and its edges k,\n"
      "so that the same motion costs the same at any rate;\n"
      "anchor_frames: (V,) how many frames' time each vertex's anchor stands for, >= 1 (empty: 1;\n"
      "a pose held after its clip ends stands for the frames it is held);\n"
      "cut_into: (V,) 1 where the rest step into the vertex is a cut (empty: none): no shape term\n"
      "spans it;\n"
      "still_extent: ranges whose rest positions lie this close (stage units) only translate;\n"
      "min_baseline: each frame's shape term is framed by the nearest frames at least this far\n"
      "apart (stage units), as path_edit's chain terms.")
      .def(py::init<const Eigen::Ref<const Trajectory2>&, const Eigen::VectorXi&,
                    const std::vector<mocapedit::FrameRange>&, double, const Eigen::VectorXd&,
                    const Eigen::VectorXd&, const Eigen::VectorXi&, double, double, int>(),
           py::kw_only(), py::arg("rest"), py::arg("starts"), py::arg("rigid") = std::vector<mocapedit::FrameRange>{},
           py::arg("anchor_weight") = 1e-3, py::arg("rates") = Eigen::VectorXd(), py::arg("anchor_frames") = Eigen::VectorXd(),
           py::arg("cut_into") = Eigen::VectorXi(), py::arg("still_extent") = 1e-9,
           py::arg("min_baseline") = 0.0, py::arg("threads") = 0)
      .def("solve", &SeparationSolver::Solve, py::kw_only(), py::arg("direction"), py::arg("rhs"), py::arg("softness"),
           py::arg("term_row"), py::arg("term_vertex"), py::arg("term_weight"),
           py::arg("kind") = Eigen::VectorXi(), py::arg("initial_forces") = Eigen::VectorXd(),
           py::arg("tolerance") = 1e-6, py::arg("max_sweeps") = 500,
           py::arg("initial_shape_forces") = Eigen::VectorXd(), py::arg("relaxation") = 1.0, py::arg("split_from") = 1000000,
           "Solves both steps under R rows, each sum_t term_weight[t] * dot(direction[row], x[term_vertex[t]])\n"
           "= rhs[row] (kind 0), or >= rhs[row] (kind 1: a one-sided row, it only pushes); softness 0 = hard,\n"
           "else 1 / weight relative to the shape terms. initial_forces and initial_shape_forces: a previous\n"
           "solve's forces and shape_forces (warm starts of step 2 and step 1; with initial_forces alone both\n"
           "steps start from it);\n"
           "tolerance (stage units) and max_sweeps bound the Gauss-Seidel on one-sided rows; relaxation: its\n"
           "over-relaxation factor, in (0, 2); split_from: frames of the agents the rows touch from which the\n"
           "rows are swept in two halves of the crowd on two threads (the same forces on any thread count);\n"
           "below, or negative, all in time order on one thread.\n"
           "Returns a SeparationResult. Keyword arguments only.")
      .def_property_readonly("agents", &SeparationSolver::agents)
      .def_property_readonly("vertices", &SeparationSolver::vertices);
}
