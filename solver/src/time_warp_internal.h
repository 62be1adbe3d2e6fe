// Internals of time warping (time_warp.h) shared by its source files: the equality
// edges and soft rows of a component, the spanning forest of its hard edges, the reduced
// system left once they are eliminated, and the bounded problem's active set.
//
//   time_warp.cpp         validation, components, TimeWarpPrecompute, TimeWarpSolve
//   time_warp_system.cpp  forests, the reduced system and its solve
//   time_warp_bounds.cpp  the minimum intervals: a feasible start and the active set
#pragma once

#include <Eigen/SPQRSupport>
#include <Eigen/SparseCholesky>

#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "mocapedit/errors.h"
#include "mocapedit/time_warp.h"

namespace mocapedit {
namespace detail {

using SparseMatrix = Eigen::SparseMatrix<double>;
using RowMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor>;
using Triplet = Eigen::Triplet<double>;

// Hard constraints fix a time within this of what they ask (well below the 1e-6 time codes
// the report calls met), relative to the size of the times involved.
constexpr double kConsistency = 1e-9;
// A pivot below this fraction of the largest one marks the normal equations singular.
constexpr double kSingularPivot = 1e-13;
constexpr int kMaxRefinementSteps = 4;
// Components reading at most this many constraint values keep responses to them (when asked).
constexpr int kMaxResponses = 16;
constexpr double kRefinedError = 1e-13;
constexpr char kTimeWarp[] = "TimeWarp";

enum class EdgeKind { kTime, kSync, kInterval };

// An equality t_u - t_v = value between two nodes; node `ground` has time 0.
struct Edge {
  int u, v;
  EdgeKind kind;
  int id;  // constraint index (kTime, kSync) or the interval's lower node (kInterval)
};

// A soft constraint's least-squares row.
struct SoftRow {
  int row;
  EdgeKind kind;  // kTime or kSync
  int id;
  int u, v;  // v = -1 for a time constraint
  double sqrt_weight;
};

// The spanning forest of a set of equality edges over nodes 0..nodes-1 (the last node is
// the ground). Each tree is one class of nodes whose times are tied together; a class
// holding the ground has known times, every other class is one unknown.
struct Forest {
  std::vector<int> cls;          // node -> class
  std::vector<int> root;         // class -> root node (the ground for a grounded class)
  std::vector<int> size;         // class -> node count
  std::vector<int> unknown;      // class -> column of the reduced system, -1 when grounded
  int unknowns = 0;
  std::vector<int> tree;         // edges of the forest
  std::vector<int> redundant;    // edges that close a cycle
  std::vector<int> order;        // nodes, each after its parent
  std::vector<int> parent;       // node -> parent node, -1 for a root
  std::vector<int> parent_edge;  // node -> edge to the parent, -1 for a root
  std::vector<int> depth;
};

// Least-squares rows A over the nodes; the reduced unknowns z are the free classes
// (x = P z + offset), and the normal equations P'A'A P z = P'A'(targets - A offset) are
// assembled directly from the rows. A banded chain per agent plus a few sync couplings
// factor with little fill in their natural order.
struct Reduced {
  std::vector<int> column;  // #nodes column of each node, -1 when its time is known
  int unknowns = 0;
  Eigen::SimplicialLDLT<SparseMatrix, Eigen::Lower, Eigen::NaturalOrdering<int>> ldlt;
  SparseMatrix ap;          // A P, kept for the SPQR fallback only
  std::unique_ptr<Eigen::SPQR<SparseMatrix>> qr;
  bool fallback = false;
};

}  // namespace detail

struct TimeWarpComponent {
  std::vector<int> agents;      // problem agent indices
  std::vector<int> first;       // #agents + 1 node offsets
  int nodes = 0;                // frames; node `nodes` is the ground
  Eigen::VectorXd rest;         // #nodes rest times
  Eigen::VectorXd minimum;      // #nodes smallest interval to the next frame (0 at an agent's last frame)
  std::vector<char> has_next;   // #nodes: the next node is the same agent's next frame
  std::vector<int> node_agent;  // #nodes local agent
  std::vector<detail::Edge> hard;       // hard equalities
  std::vector<detail::SoftRow> soft;
  detail::RowMatrix a;                  // least-squares rows over the nodes (weights applied)
  detail::Forest forest;                // of the hard edges
  std::unique_ptr<detail::Reduced> base;
  int max_iterations = 0;
  // Responses (TimeWarpPrecompute with responses): the unbounded solution is affine in the
  // constraint values the component reads, t = response0 + responses * values(params).
  std::vector<std::pair<detail::EdgeKind, int>> params;  // (kTime or kSync, constraint index)
  Eigen::VectorXd response0;
  Eigen::MatrixXd responses;                     // #nodes by #params; empty: solve instead
};

namespace detail {

// time_warp_system.cpp
Forest BuildForest(int nodes, const std::vector<Edge>& edges);
// The edges on the tree path between two nodes of one class.
std::vector<int> TreePath(const Forest& f, int a, int b);
// The reduced system of a component under the forest's equalities, factored.
std::unique_ptr<Reduced> Factor(const TimeWarpComponent& c, const Forest& f);
// The value an equality edge asks for.
double EdgeValue(const TimeWarpComponent& c, const Edge& e, const Eigen::VectorXd& times,
                 const Eigen::VectorXd& offsets);
// Time of each node relative to its class root (the ground's time is 0).
Eigen::VectorXd Potentials(const TimeWarpComponent& c, const Forest& f, const std::vector<Edge>& edges,
                           const Eigen::VectorXd& times, const Eigen::VectorXd& offsets);
// Least-squares targets of the rows, for the displacement x = t - rest.
Eigen::VectorXd RowTargets(const TimeWarpComponent& c, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets);
// Minimises the energy over the times the forest leaves free. Returns #nodes times.
Eigen::VectorXd SolveReduced(const TimeWarpComponent& c, const Forest& f, const Reduced& red,
                             const Eigen::VectorXd& pot, const Eigen::VectorXd& targets);
// The time and sync constraint indices of edges `ids`.
void Collect(const std::vector<Edge>& edges, const std::vector<int>& ids, std::set<int>& time_ids,
             std::set<int>& sync_ids);
// "1, 4, 7"
std::string Join(const std::set<int>& ids);
// 1 + the largest magnitude of t.
double Scale(const Eigen::VectorXd& t);

// time_warp_bounds.cpp
// A time map for the hard constraints alone that keeps every interval at or above its
// minimum (the start of the active-set method). Throws TimeWarpConflict naming the hard
// constraints that make that impossible.
Eigen::VectorXd FeasibleStart(const TimeWarpComponent& c, const Eigen::VectorXd& pot);

struct ActiveSetOutcome {
  Eigen::VectorXd t;
  std::vector<char> at_minimum;  // #nodes: the interval to the next frame is held at its minimum
  int iterations = 0;
  bool fallback = false;
};

// The bounded minimiser from a feasible start t (see time_warp_bounds.cpp).
ActiveSetOutcome ActiveSet(const TimeWarpComponent& c, Eigen::VectorXd t, const Eigen::VectorXd& t_unconstrained,
                           const Eigen::VectorXd& times, const Eigen::VectorXd& offsets,
                           const Eigen::VectorXd& targets);

}  // namespace detail
}  // namespace mocapedit
