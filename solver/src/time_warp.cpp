#include "mocapedit/time_warp.h"

#include <Eigen/SPQRSupport>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <set>
#include <sstream>

#include "mocapedit/blas_lock.h"
#include "union_find.h"

namespace mocapedit {

namespace {

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

using detail::UnionFind;

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

Forest BuildForest(int nodes, const std::vector<Edge>& edges) {
  const int ground = nodes - 1;
  Forest f;
  UnionFind uf(nodes);
  std::vector<std::vector<std::pair<int, int>>> adj(static_cast<size_t>(nodes));
  for (int e = 0; e < static_cast<int>(edges.size()); ++e) {
    const Edge& edge = edges[e];
    if (uf.Unite(edge.u, edge.v)) {
      f.tree.push_back(e);
      adj[edge.u].push_back({e, edge.v});
      adj[edge.v].push_back({e, edge.u});
    } else {
      f.redundant.push_back(e);
    }
  }
  f.cls.assign(nodes, -1);
  f.parent.assign(nodes, -1);
  f.parent_edge.assign(nodes, -1);
  f.depth.assign(nodes, 0);
  f.order.reserve(nodes);
  auto grow = [&](int start) {
    const int c = static_cast<int>(f.root.size());
    f.root.push_back(start);
    f.size.push_back(0);
    f.cls[start] = c;
    size_t head = f.order.size();
    f.order.push_back(start);
    while (head < f.order.size()) {
      const int n = f.order[head++];
      ++f.size[c];
      for (const auto& [e, m] : adj[n]) {
        if (f.cls[m] >= 0) continue;
        f.cls[m] = c;
        f.parent[m] = n;
        f.parent_edge[m] = e;
        f.depth[m] = f.depth[n] + 1;
        f.order.push_back(m);
      }
    }
  };
  grow(ground);
  for (int n = 0; n < ground; ++n)
    if (f.cls[n] < 0) grow(n);
  f.unknown.assign(f.root.size(), -1);
  for (size_t c = 1; c < f.root.size(); ++c) f.unknown[c] = f.unknowns++;
  return f;
}

// The edges on the tree path between two nodes of one class.
std::vector<int> TreePath(const Forest& f, int a, int b) {
  std::vector<int> path;
  while (a != b) {
    if (f.depth[a] >= f.depth[b]) {
      path.push_back(f.parent_edge[a]);
      a = f.parent[a];
    } else {
      path.push_back(f.parent_edge[b]);
      b = f.parent[b];
    }
  }
  return path;
}

// The linear system left once the equalities of a forest are eliminated, factored.
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

}  // namespace

struct TimeWarpComponent {
  std::vector<int> agents;      // problem agent indices
  std::vector<int> first;       // #agents + 1 node offsets
  int nodes = 0;                // frames; node `nodes` is the ground
  Eigen::VectorXd rest;         // #nodes rest times
  Eigen::VectorXd minimum;      // #nodes smallest interval to the next frame (0 at an agent's last frame)
  std::vector<char> has_next;   // #nodes: the next node is the same agent's next frame
  std::vector<int> node_agent;  // #nodes local agent
  std::vector<Edge> hard;       // hard equalities
  std::vector<SoftRow> soft;
  RowMatrix a;                  // least-squares rows over the nodes (weights applied)
  Forest forest;                // of the hard edges
  std::unique_ptr<Reduced> base;
  int max_iterations = 0;
  // Responses (TimeWarpPrecompute with responses): the unbounded solution is affine in the
  // constraint values the component reads, t = response0 + responses * values(params).
  std::vector<std::pair<EdgeKind, int>> params;  // (kTime or kSync, constraint index)
  Eigen::VectorXd response0;
  Eigen::MatrixXd responses;                     // #nodes by #params; empty: solve instead
};

TimeWarpConflict::TimeWarpConflict(Kind kind_, std::vector<int> time_constraints_,
                                   std::vector<int> sync_constraints_, double mismatch_, int agent_,
                                   int frame_a_, int frame_b_, double gap_, double minimum_,
                                   const std::string& what)
    : std::invalid_argument(what),
      kind(kind_),
      time_constraints(std::move(time_constraints_)),
      sync_constraints(std::move(sync_constraints_)),
      mismatch(mismatch_),
      agent(agent_),
      frame_a(frame_a_),
      frame_b(frame_b_),
      gap(gap_),
      minimum(minimum_) {}

TimeWarpData::TimeWarpData() = default;
TimeWarpData::~TimeWarpData() = default;
TimeWarpData::TimeWarpData(TimeWarpData&&) noexcept = default;
TimeWarpData& TimeWarpData::operator=(TimeWarpData&&) noexcept = default;

namespace {

// --- validation --------------------------------------------------------------------------

void Require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("TimeWarp: " + message);
}

// Messages are built only on failure: validation runs on every frame of every agent.
bool FrameOk(const TimeWarpProblem& p, int agent, int frame) {
  return agent >= 0 && agent < static_cast<int>(p.rest_times.size()) && frame >= 0 &&
         frame < p.rest_times[agent].size();
}

void CheckFrame(const TimeWarpProblem& p, int agent, int frame, const char* kind, Eigen::Index k) {
  if (FrameOk(p, agent, frame)) return;
  const std::string what = std::string(kind) + " " + std::to_string(k);
  Require(agent >= 0 && agent < static_cast<int>(p.rest_times.size()),
          what + ": agent " + std::to_string(agent) + " is not one of the " +
              std::to_string(p.rest_times.size()) + " agents");
  Require(false, what + ": frame " + std::to_string(frame) + " is outside agent " + std::to_string(agent) +
                     "'s frames 0.." + std::to_string(p.rest_times[agent].size() - 1));
}

void Validate(const TimeWarpProblem& p) {
  Require(p.min_interval_fraction > 0 && p.min_interval_fraction <= 1,
          "min_interval_fraction must be in (0, 1]");
  Require(std::isfinite(p.stretch_weight) && p.stretch_weight >= 0, "stretch_weight must be finite and >= 0");
  Require(std::isfinite(p.anchor_weight) && p.anchor_weight > 0, "anchor_weight must be finite and > 0");
  Require(p.min_intervals.empty() || p.min_intervals.size() == p.rest_times.size(),
          "min_intervals must be empty or hold one list per agent");
  for (size_t a = 0; a < p.rest_times.size(); ++a) {
    const Eigen::VectorXd& r = p.rest_times[a];
    const std::string who = "agent " + std::to_string(a);
    Require(r.size() > 0, who + " has no frames");
    Require(r.allFinite(), who + ": rest times must be finite");
    for (Eigen::Index i = 1; i < r.size(); ++i)
      if (!(r[i] > r[i - 1])) Require(false, who + ": rest times must increase (frame " + std::to_string(i) + ")");
    if (!p.min_intervals.empty() && p.min_intervals[a].size() > 0) {
      const Eigen::VectorXd& m = p.min_intervals[a];
      Require(m.size() == r.size() - 1, who + ": min_intervals needs one value per interval");
      Require(m.allFinite() && (m.array() > 0).all(), who + ": min_intervals must be finite and > 0");
    }
  }
  const auto t = p.time_frames.rows();
  Require(p.time_hard.size() == t && p.time_weights.size() == t,
          "time_hard and time_weights need one value per time constraint");
  for (Eigen::Index k = 0; k < t; ++k) {
    CheckFrame(p, p.time_frames(k, 0), p.time_frames(k, 1), "time constraint", k);
    if (!(std::isfinite(p.time_weights[k]) && p.time_weights[k] >= 0))
      Require(false, "time constraint " + std::to_string(k) + ": weight must be finite and >= 0");
  }
  const auto s = p.sync_frames.rows();
  Require(p.sync_hard.size() == s && p.sync_weights.size() == s,
          "sync_hard and sync_weights need one value per sync constraint");
  for (Eigen::Index k = 0; k < s; ++k) {
    CheckFrame(p, p.sync_frames(k, 0), p.sync_frames(k, 1), "sync constraint", k);
    CheckFrame(p, p.sync_frames(k, 2), p.sync_frames(k, 3), "sync constraint (target)", k);
    if (!(std::isfinite(p.sync_weights[k]) && p.sync_weights[k] >= 0))
      Require(false, "sync constraint " + std::to_string(k) + ": weight must be finite and >= 0");
  }
}

// --- building and factoring ----------------------------------------------------------------

// Node of (local agent, frame).
int Node(const TimeWarpComponent& c, int local_agent, int frame) { return c.first[local_agent] + frame; }

std::unique_ptr<Reduced> Factor(const TimeWarpComponent& c, const Forest& f) {
  auto r = std::make_unique<Reduced>();
  r->unknowns = f.unknowns;
  r->column.resize(c.nodes);
  for (int n = 0; n < c.nodes; ++n) r->column[n] = f.unknown[f.cls[n]];
  if (f.unknowns == 0) return r;
  std::vector<Triplet> normal;
  std::vector<std::pair<int, double>> row;
  for (int i = 0; i < c.a.outerSize(); ++i) {
    row.clear();
    for (RowMatrix::InnerIterator it(c.a, i); it; ++it)
      if (r->column[it.col()] >= 0) row.emplace_back(r->column[it.col()], it.value());
    for (const auto& [ci, vi] : row)
      for (const auto& [cj, vj] : row)
        if (ci >= cj) normal.emplace_back(ci, cj, vi * vj);
  }
  SparseMatrix m(f.unknowns, f.unknowns);
  m.setFromTriplets(normal.begin(), normal.end());
  r->ldlt.compute(m);
  bool ok = r->ldlt.info() == Eigen::Success;
  if (ok) {
    const Eigen::VectorXd d = r->ldlt.vectorD();
    const double top = d.cwiseAbs().maxCoeff();
    ok = top > 0 && d.minCoeff() > kSingularPivot * top;
  }
  if (!ok) {
    r->fallback = true;
    std::vector<Triplet> trip;
    for (int i = 0; i < c.a.outerSize(); ++i)
      for (RowMatrix::InnerIterator it(c.a, i); it; ++it)
        if (r->column[it.col()] >= 0) trip.emplace_back(i, r->column[it.col()], it.value());
    r->ap.resize(c.a.rows(), f.unknowns);
    r->ap.setFromTriplets(trip.begin(), trip.end());
    r->qr = std::make_unique<Eigen::SPQR<SparseMatrix>>();
    {
      BlasLock lock;  // SPQR runs in BLAS: see blas_lock.h
      r->qr->compute(r->ap);
    }
    if (r->qr->info() != Eigen::Success) throw std::runtime_error("TimeWarp: SPQR factorization failed");
  }
  return r;
}

// P' v: node values summed into the columns of their classes.
Eigen::VectorXd Gather(const Reduced& red, const Eigen::VectorXd& v) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(red.unknowns);
  for (size_t n = 0; n < red.column.size(); ++n)
    if (red.column[n] >= 0) out[red.column[n]] += v[static_cast<Eigen::Index>(n)];
  return out;
}

// The value an equality edge asks for.
double EdgeValue(const TimeWarpComponent& c, const Edge& e, const Eigen::VectorXd& times,
                 const Eigen::VectorXd& offsets) {
  switch (e.kind) {
    case EdgeKind::kTime: return times[e.id];
    case EdgeKind::kSync: return offsets[e.id];
    case EdgeKind::kInterval: return c.minimum[e.id];
  }
  return 0.0;
}

// Time of each node relative to its class root (the ground's time is 0).
Eigen::VectorXd Potentials(const TimeWarpComponent& c, const Forest& f, const std::vector<Edge>& edges,
                           const Eigen::VectorXd& times, const Eigen::VectorXd& offsets) {
  Eigen::VectorXd pot = Eigen::VectorXd::Zero(c.nodes + 1);
  for (int n : f.order) {
    const int e = f.parent_edge[n];
    if (e < 0) continue;
    const Edge& edge = edges[e];
    const double value = EdgeValue(c, edge, times, offsets);
    pot[n] = n == edge.u ? pot[edge.v] + value : pot[edge.u] - value;
  }
  return pot;
}

// Least-squares targets of the rows, for the displacement x = t - rest.
Eigen::VectorXd RowTargets(const TimeWarpComponent& c, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets) {
  Eigen::VectorXd r = Eigen::VectorXd::Zero(c.a.rows());
  for (const SoftRow& s : c.soft) {
    r[s.row] = s.kind == EdgeKind::kTime ? s.sqrt_weight * (times[s.id] - c.rest[s.u])
                                          : s.sqrt_weight * (offsets[s.id] - (c.rest[s.u] - c.rest[s.v]));
  }
  return r;
}

// Minimises the energy over the times the forest leaves free. Returns #nodes times.
Eigen::VectorXd SolveReduced(const TimeWarpComponent& c, const Forest& f, const Reduced& red,
                             const Eigen::VectorXd& pot, const Eigen::VectorXd& targets) {
  // Displacement of each node with every free class at zero displacement of its root.
  Eigen::VectorXd offset(c.nodes);
  for (int n = 0; n < c.nodes; ++n) {
    const int cls = f.cls[n];
    offset[n] = f.unknown[cls] < 0 ? pot[n] - c.rest[n] : c.rest[f.root[cls]] + pot[n] - c.rest[n];
  }
  Eigen::VectorXd z;
  if (f.unknowns > 0) {
    if (red.fallback) {
      BlasLock lock;
      z = red.qr->solve(Eigen::VectorXd(targets - c.a * offset));
    } else {
      // Normal equations square the condition number of the interval-change rows (it grows
      // like n^4); corrected semi-normal equations (refinement on the least-squares
      // residual) recover the accuracy of a QR solve.
      z = red.ldlt.solve(Gather(red, c.a.transpose() * (targets - c.a * offset)));
      for (int step = 0; step < kMaxRefinementSteps; ++step) {
        Eigen::VectorXd x = offset;
        for (int n = 0; n < c.nodes; ++n)
          if (red.column[n] >= 0) x[n] += z[red.column[n]];
        const Eigen::VectorXd delta = red.ldlt.solve(Gather(red, c.a.transpose() * (targets - c.a * x)));
        z += delta;
        // Each step shrinks the error by about |delta| / |z|: stop once what is left,
        // |delta|^2 / |z|, is at the level of rounding.
        const double d = delta.cwiseAbs().maxCoeff(), scale = 1.0 + z.cwiseAbs().maxCoeff();
        if (d * d <= kRefinedError * scale * scale) break;
      }
    }
    if (!z.allFinite()) throw std::runtime_error("TimeWarp: the linear solve produced non-finite times");
  }
  Eigen::VectorXd t(c.nodes);
  for (int n = 0; n < c.nodes; ++n) {
    const int cls = f.cls[n];
    const int k = f.unknown[cls];
    // Known times are set from the constraint values themselves, so hard times are exact.
    t[n] = k < 0 ? pot[n] : c.rest[f.root[cls]] + z[k] + pot[n];
  }
  return t;
}

void Collect(const std::vector<Edge>& edges, const std::vector<int>& ids, std::set<int>& time_ids,
             std::set<int>& sync_ids) {
  for (int e : ids) {
    if (edges[e].kind == EdgeKind::kTime) time_ids.insert(edges[e].id);
    if (edges[e].kind == EdgeKind::kSync) sync_ids.insert(edges[e].id);
  }
}

std::string Join(const std::set<int>& ids) {
  std::ostringstream s;
  bool first = true;
  for (int i : ids) {
    s << (first ? "" : ", ") << i;
    first = false;
  }
  return s.str();
}

// Hard edges that close a cycle must agree with the tree: else the constraints on the cycle contradict.
void CheckCycles(const TimeWarpComponent& c, const Eigen::VectorXd& pot, const Eigen::VectorXd& times,
                 const Eigen::VectorXd& offsets) {
  for (int e : c.forest.redundant) {
    const Edge& edge = c.hard[e];
    const double want = EdgeValue(c, edge, times, offsets);
    const double have = pot[edge.u] - pot[edge.v];
    const double scale = 1.0 + std::abs(want) + std::abs(pot[edge.u]) + std::abs(pot[edge.v]);
    if (std::abs(have - want) <= kConsistency * scale) continue;
    std::vector<int> ids = TreePath(c.forest, edge.u, edge.v);
    ids.push_back(e);
    std::set<int> time_ids, sync_ids;
    Collect(c.hard, ids, time_ids, sync_ids);
    std::ostringstream what;
    what << "TimeWarp: hard constraints contradict (time constraints [" << Join(time_ids)
         << "], sync constraints [" << Join(sync_ids) << "]): they disagree by " << std::abs(have - want)
         << " time codes";
    throw TimeWarpConflict(TimeWarpConflict::Kind::kCycle, {time_ids.begin(), time_ids.end()},
                           {sync_ids.begin(), sync_ids.end()}, std::abs(have - want), -1, -1, -1, 0.0, 0.0,
                           what.str());
  }
}

// --- the bounded problem -----------------------------------------------------------------

double Scale(const Eigen::VectorXd& t) { return 1.0 + (t.size() ? t.cwiseAbs().maxCoeff() : 0.0); }

// A time map for the hard constraints alone that keeps every interval at or above its
// minimum (the start of the active-set method), or a TimeWarpConflict naming the hard
// constraints that make that impossible. A system of difference constraints between the
// classes of the hard forest, solved by Bellman-Ford.
Eigen::VectorXd FeasibleStart(const TimeWarpComponent& c, const Eigen::VectorXd& pot) {
  const Forest& f = c.forest;
  const int ground = c.nodes;
  auto touched = [&](int n) { return f.size[f.cls[n]] > 1; };
  // Y[cls(b)] - Y[cls(a)] >= w for consecutive touched frames a < b of one agent.
  struct Gap { int a, b; double w, span; };
  std::vector<Gap> gaps;
  for (size_t la = 0; la < c.agents.size(); ++la) {
    int prev = -1;
    double span = 0.0;
    for (int n = c.first[la]; n < c.first[la + 1]; ++n) {
      if (touched(n)) {
        if (prev >= 0) gaps.push_back({prev, n, span - pot[n] + pot[prev], span});
        prev = n;
        span = 0.0;
      }
      if (c.has_next[n]) span += c.minimum[n];
    }
  }
  const int classes = static_cast<int>(f.root.size());
  Eigen::VectorXd dist = Eigen::VectorXd::Zero(classes);
  std::vector<int> pred(classes, -1);
  const double tol = kConsistency * Scale(pot);
  int last = -1;
  for (int iter = 0; iter <= classes; ++iter) {
    last = -1;
    for (int g = 0; g < static_cast<int>(gaps.size()); ++g) {
      const int from = f.cls[gaps[g].b], to = f.cls[gaps[g].a];
      const double d = dist[from] - gaps[g].w;
      if (d < dist[to] - tol) {
        dist[to] = d;
        pred[to] = g;
        last = to;
      }
    }
    if (last < 0) break;
  }
  if (last >= 0) {
    // A negative cycle: walk back onto it, then collect the hard constraints along it.
    int x = last;
    for (int i = 0; i < classes && pred[x] >= 0; ++i) x = f.cls[gaps[pred[x]].b];
    std::vector<int> cycle;  // gaps, in reverse
    int y = x;
    do {
      if (pred[y] < 0) break;
      cycle.push_back(pred[y]);
      y = f.cls[gaps[pred[y]].b];
    } while (y != x && static_cast<int>(cycle.size()) <= classes);
    std::set<int> time_ids, sync_ids;
    if (cycle.empty() || y != x) {
      cycle.clear();  // not traced: name every hard constraint of the component
      std::vector<int> all(c.hard.size());
      std::iota(all.begin(), all.end(), 0);
      Collect(c.hard, all, time_ids, sync_ids);
    }
    for (size_t i = 0; i < cycle.size(); ++i) {
      // The cycle leaves a class at the b-frame of one gap and enters it at the a-frame of the next.
      const Gap& in = gaps[cycle[i]];
      const Gap& out = gaps[cycle[(i + 1) % cycle.size()]];
      Collect(c.hard, TreePath(f, in.b, out.a), time_ids, sync_ids);
    }
    int agent = -1, fa = -1, fb = -1;
    double gap = 0.0, minimum = 0.0;
    if (cycle.size() == 1) {
      const Gap& g = gaps[cycle[0]];
      const int la = c.node_agent[g.a];
      agent = c.agents[la];
      fa = g.a - c.first[la];
      fb = g.b - c.first[la];
      gap = pot[g.b] - pot[g.a];
      minimum = g.span;
    }
    std::ostringstream what;
    what << "TimeWarp: hard constraints would run time backwards or below the minimum interval "
         << "(time constraints [" << Join(time_ids) << "], sync constraints [" << Join(sync_ids) << "])";
    throw TimeWarpConflict(TimeWarpConflict::Kind::kBackwards, {time_ids.begin(), time_ids.end()},
                           {sync_ids.begin(), sync_ids.end()}, 0.0, agent, fa, fb, gap, minimum, what.str());
  }
  const int ground_class = f.cls[ground];
  Eigen::VectorXd t(c.nodes);
  for (size_t la = 0; la < c.agents.size(); ++la) {
    const int begin = c.first[la], end = c.first[la + 1];
    std::vector<int> known;
    for (int n = begin; n < end; ++n)
      if (touched(n)) {
        t[n] = dist[f.cls[n]] - dist[ground_class] + pot[n];
        known.push_back(n);
      }
    if (known.empty()) {
      t.segment(begin, end - begin) = c.rest.segment(begin, end - begin);
      continue;
    }
    // Between known frames, spread the time in proportion to the minimum intervals' excess;
    // outside them, keep the rest intervals.
    for (int n = known.front() - 1; n >= begin; --n)
      t[n] = t[n + 1] - std::max(c.rest[n + 1] - c.rest[n], c.minimum[n]);
    for (int n = known.back() + 1; n < end; ++n)
      t[n] = t[n - 1] + std::max(c.rest[n] - c.rest[n - 1], c.minimum[n - 1]);
    for (size_t k = 0; k + 1 < known.size(); ++k) {
      const int a = known[k], b = known[k + 1];
      double span = 0.0, rest = 0.0;
      for (int n = a; n < b; ++n) {
        span += c.minimum[n];
        rest += c.rest[n + 1] - c.rest[n];
      }
      const double extra = std::max(0.0, (t[b] - t[a]) - span);
      for (int n = a + 1; n < b; ++n)
        t[n] = t[n - 1] + c.minimum[n - 1] + extra * (c.rest[n] - c.rest[n - 1]) / rest;
    }
  }
  return t;
}

Eigen::VectorXd Gradient(const TimeWarpComponent& c, const Eigen::VectorXd& t, const Eigen::VectorXd& targets) {
  return c.a.transpose() * (c.a * (t - c.rest) - targets);
}

struct ActiveSetOutcome {
  Eigen::VectorXd t;
  std::vector<char> at_minimum;  // #nodes: the interval to the next frame is held at its minimum
  int iterations = 0;
  bool fallback = false;
};

// Primal active-set method (Nocedal & Wright, algorithm 16.3) on the interval bounds
// t[n+1] - t[n] >= minimum[n], from a feasible start. A bound in the working set is one
// more equality edge of the forest; its multiplier is the gradient summed over the subtree
// it holds up.
ActiveSetOutcome ActiveSet(const TimeWarpComponent& c, Eigen::VectorXd t, const Eigen::VectorXd& t_unconstrained,
                           const Eigen::VectorXd& times, const Eigen::VectorXd& offsets,
                           const Eigen::VectorXd& targets) {
  ActiveSetOutcome out;
  std::set<int> working;
  std::vector<Edge> edges = c.hard;
  Forest forest = c.forest;
  Eigen::VectorXd t_star = t_unconstrained;
  auto rebuild = [&]() {
    edges = c.hard;
    for (int n : working) edges.push_back({n + 1, n, EdgeKind::kInterval, n});
    forest = BuildForest(c.nodes + 1, edges);
    const auto red = Factor(c, forest);
    out.fallback = out.fallback || red->fallback;
    t_star = SolveReduced(c, forest, *red, Potentials(c, forest, edges, times, offsets), targets);
  };
  const double scale = Scale(t);
  for (out.iterations = 1; out.iterations <= c.max_iterations; ++out.iterations) {
    const Eigen::VectorXd p = t_star - t;
    double alpha = 1.0;
    int block = -1;
    for (int n = 0; n < c.nodes; ++n) {
      // A bound the working set already fixes (its two frames in one class) cannot block.
      if (!c.has_next[n] || forest.cls[n] == forest.cls[n + 1]) continue;
      const double dp = p[n + 1] - p[n];
      if (dp >= -1e-14 * scale) continue;
      const double slack = std::max(0.0, t[n + 1] - t[n] - c.minimum[n]);
      if (slack / -dp < alpha) {
        alpha = slack / -dp;
        block = n;
      }
    }
    if (block >= 0) {
      t += alpha * p;
      working.insert(block);
      rebuild();
      continue;
    }
    t = t_star;
    // At the minimiser on the working set: drop the bound with the most negative multiplier.
    const Eigen::VectorXd g = Gradient(c, t, targets);
    Eigen::VectorXd sum = Eigen::VectorXd::Zero(c.nodes + 1);
    sum.head(c.nodes) = g;
    for (auto it = forest.order.rbegin(); it != forest.order.rend(); ++it)
      if (forest.parent[*it] >= 0) sum[forest.parent[*it]] += sum[*it];
    const double tol = 1e-9 * (1.0 + g.cwiseAbs().maxCoeff());
    int drop = -1;
    double worst = -tol;
    for (int n : working) {
      // The bound's node above the edge carries the subtree: lambda = sum * (+1 if it is the upper frame).
      const int child = forest.parent_edge[n + 1] >= 0 && edges[forest.parent_edge[n + 1]].kind == EdgeKind::kInterval &&
                                edges[forest.parent_edge[n + 1]].id == n
                            ? n + 1
                            : n;
      const double lambda = child == n + 1 ? sum[child] : -sum[child];
      if (lambda < worst) {
        worst = lambda;
        drop = n;
      }
    }
    if (drop < 0) break;
    working.erase(drop);
    rebuild();
  }
  out.t = t;
  out.at_minimum.assign(c.nodes, 0);
  for (int n : working) out.at_minimum[n] = 1;
  return out;
}

void BuildComponent(const TimeWarpProblem& p, const std::vector<int>& agents, const std::vector<int>& time_ids,
                    const std::vector<int>& sync_ids, TimeWarpComponent& c) {
  c.agents = agents;
  c.first.assign(1, 0);
  std::vector<int> local(p.rest_times.size(), -1);
  for (size_t la = 0; la < agents.size(); ++la) {
    local[agents[la]] = static_cast<int>(la);
    c.first.push_back(c.first.back() + static_cast<int>(p.rest_times[agents[la]].size()));
  }
  c.nodes = c.first.back();
  c.rest.resize(c.nodes);
  c.minimum = Eigen::VectorXd::Zero(c.nodes);
  c.has_next.assign(c.nodes, 0);
  c.node_agent.assign(c.nodes, 0);
  for (size_t la = 0; la < agents.size(); ++la) {
    const Eigen::VectorXd& r = p.rest_times[agents[la]];
    const int o = c.first[la];
    const auto count = r.size();
    c.rest.segment(o, count) = r;
    const bool given = !p.min_intervals.empty() && p.min_intervals[agents[la]].size() > 0;
    for (Eigen::Index i = 0; i < count; ++i) {
      c.node_agent[o + i] = static_cast<int>(la);
      if (i + 1 < count) {
        c.has_next[o + i] = 1;
        c.minimum[o + i] = given ? p.min_intervals[agents[la]][i] : p.min_interval_fraction * (r[i + 1] - r[i]);
      }
    }
  }
  const int ground = c.nodes;
  std::vector<Triplet> trip;
  int row = 0;
  const double sqrt_stretch = std::sqrt(p.stretch_weight);
  for (size_t la = 0; la < agents.size(); ++la) {
    const int o = c.first[la];
    const int count = c.first[la + 1] - o;
    for (int i = 1; i + 1 < count; ++i, ++row) {
      trip.emplace_back(row, o + i - 1, 1.0);
      trip.emplace_back(row, o + i, -2.0);
      trip.emplace_back(row, o + i + 1, 1.0);
    }
    if (sqrt_stretch > 0)
      for (int i = 0; i + 1 < count; ++i, ++row) {
        trip.emplace_back(row, o + i, -sqrt_stretch);
        trip.emplace_back(row, o + i + 1, sqrt_stretch);
      }
  }
  bool has_time = false;
  for (int k : time_ids) {
    const int n = Node(c, local[p.time_frames(k, 0)], p.time_frames(k, 1));
    if (p.time_hard[k]) {
      c.hard.push_back({n, ground, EdgeKind::kTime, k});
      has_time = true;
    } else if (p.time_weights[k] > 0) {
      const double w = std::sqrt(p.time_weights[k]);
      c.soft.push_back({row, EdgeKind::kTime, k, n, -1, w});
      trip.emplace_back(row++, n, w);
      has_time = true;
    }
  }
  std::set<int> synced;
  for (int k : sync_ids) {
    const int u = Node(c, local[p.sync_frames(k, 0)], p.sync_frames(k, 1));
    const int v = Node(c, local[p.sync_frames(k, 2)], p.sync_frames(k, 3));
    if (p.sync_hard[k]) {
      c.hard.push_back({u, v, EdgeKind::kSync, k});
    } else if (p.sync_weights[k] > 0) {
      const double w = std::sqrt(p.sync_weights[k]);
      c.soft.push_back({row, EdgeKind::kSync, k, u, v, w});
      trip.emplace_back(row, u, w);
      trip.emplace_back(row++, v, -w);
    } else {
      continue;
    }
    synced.insert(u);
    synced.insert(v);
  }
  if (!has_time) {
    const double w = std::sqrt(p.anchor_weight);
    for (int n : synced) trip.emplace_back(row++, n, w);
  }
  c.a.resize(row, c.nodes);
  c.a.setFromTriplets(trip.begin(), trip.end());
  c.forest = BuildForest(c.nodes + 1, c.hard);
  c.base = Factor(c, c.forest);
  c.max_iterations = p.max_active_set_iterations >= 0 ? p.max_active_set_iterations : 10 * c.nodes + 100;
}

}  // namespace

namespace {

// The component's unbounded solution for zero constraint values and its change per unit of
// each value it reads (at most kMaxResponses of them; more are solved for each time).
void BuildResponses(const TimeWarpData& data, TimeWarpComponent& c) {
  std::set<std::pair<EdgeKind, int>> params;
  for (const Edge& e : c.hard)
    if (e.kind != EdgeKind::kInterval) params.emplace(e.kind, e.id);
  for (const SoftRow& r : c.soft) params.emplace(r.kind, r.id);
  if (params.empty() || static_cast<int>(params.size()) > kMaxResponses) return;
  Eigen::VectorXd times = Eigen::VectorXd::Zero(data.time_constraints);
  Eigen::VectorXd offsets = Eigen::VectorXd::Zero(data.sync_constraints);
  auto solve = [&] {
    const Eigen::VectorXd pot = Potentials(c, c.forest, c.hard, times, offsets);
    return SolveReduced(c, c.forest, *c.base, pot, RowTargets(c, times, offsets));
  };
  c.params.assign(params.begin(), params.end());
  c.response0 = solve();
  c.responses.resize(c.nodes, static_cast<Eigen::Index>(c.params.size()));
  for (size_t j = 0; j < c.params.size(); ++j) {
    double& value = c.params[j].first == EdgeKind::kTime ? times[c.params[j].second] : offsets[c.params[j].second];
    value = 1.0;
    c.responses.col(static_cast<Eigen::Index>(j)) = solve() - c.response0;
    value = 0.0;
  }
}

}  // namespace

void TimeWarpPrecompute(const TimeWarpProblem& problem, TimeWarpData& data, bool responses) {
  Validate(problem);
  const int agents = static_cast<int>(problem.rest_times.size());
  data = TimeWarpData();
  data.agents = agents;
  data.time_constraints = static_cast<int>(problem.time_frames.rows());
  data.sync_constraints = static_cast<int>(problem.sync_frames.rows());
  data.problem = problem;

  // Agents linked by a (non-zero) sync constraint solve together.
  UnionFind uf(agents);
  std::vector<char> constrained(agents, 0);
  auto active = [&](bool hard, double weight) { return hard || weight > 0; };
  for (Eigen::Index k = 0; k < problem.time_frames.rows(); ++k)
    if (active(problem.time_hard[k], problem.time_weights[k])) constrained[problem.time_frames(k, 0)] = 1;
  for (Eigen::Index k = 0; k < problem.sync_frames.rows(); ++k)
    if (active(problem.sync_hard[k], problem.sync_weights[k])) {
      constrained[problem.sync_frames(k, 0)] = constrained[problem.sync_frames(k, 2)] = 1;
      uf.Unite(problem.sync_frames(k, 0), problem.sync_frames(k, 2));
    }
  std::vector<int> index_of_root(agents, -1);
  data.agent_component.assign(agents, -1);
  std::vector<std::vector<int>> members, time_ids, sync_ids;
  for (int a = 0; a < agents; ++a) {
    if (!constrained[a]) continue;
    const int r = uf.Find(a);
    if (index_of_root[r] < 0) {
      index_of_root[r] = static_cast<int>(members.size());
      members.emplace_back();
      time_ids.emplace_back();
      sync_ids.emplace_back();
    }
    data.agent_component[a] = index_of_root[r];
    members[index_of_root[r]].push_back(a);
  }
  for (Eigen::Index k = 0; k < problem.time_frames.rows(); ++k)
    if (active(problem.time_hard[k], problem.time_weights[k]))
      time_ids[data.agent_component[problem.time_frames(k, 0)]].push_back(static_cast<int>(k));
  for (Eigen::Index k = 0; k < problem.sync_frames.rows(); ++k)
    if (active(problem.sync_hard[k], problem.sync_weights[k]))
      sync_ids[data.agent_component[problem.sync_frames(k, 0)]].push_back(static_cast<int>(k));
  for (size_t k = 0; k < members.size(); ++k) {
    auto c = std::make_unique<TimeWarpComponent>();
    BuildComponent(problem, members[k], time_ids[k], sync_ids[k], *c);
    if (responses) BuildResponses(data, *c);
    data.components.push_back(std::move(c));
  }
}

TimeWarpResult TimeWarpSolve(const TimeWarpData& data, const Eigen::Ref<const Eigen::VectorXd>& times_in,
                             const Eigen::Ref<const Eigen::VectorXd>& offsets_in) {
  const TimeWarpProblem& p = data.problem;
  Require(times_in.size() == data.time_constraints, "times needs one value per time constraint");
  Require(offsets_in.size() == data.sync_constraints, "offsets needs one value per sync constraint");
  Require(times_in.allFinite(), "times must be finite");
  Require(offsets_in.allFinite(), "offsets must be finite");
  const Eigen::VectorXd times = times_in, offsets = offsets_in;
  TimeWarpResult out;
  out.time_maps = p.rest_times;
  out.solver.assign(data.agents, "rest");
  out.min_enforced = Eigen::VectorXi::Zero(data.agents);
  out.component = Eigen::Map<const Eigen::VectorXi>(data.agent_component.data(), data.agents);
  out.iterations = Eigen::VectorXi::Zero(static_cast<Eigen::Index>(data.components.size()));
  for (size_t k = 0; k < data.components.size(); ++k) {
    const TimeWarpComponent& c = *data.components[k];
    const Eigen::VectorXd pot = Potentials(c, c.forest, c.hard, times, offsets);
    CheckCycles(c, pot, times, offsets);
    const Eigen::VectorXd targets = RowTargets(c, times, offsets);
    Eigen::VectorXd t;
    if (c.responses.size()) {  // the unbounded solution from the responses
      t = c.response0;
      for (size_t j = 0; j < c.params.size(); ++j) {
        const auto [kind, id] = c.params[j];
        t.noalias() += (kind == EdgeKind::kTime ? times[id] : offsets[id]) * c.responses.col(static_cast<Eigen::Index>(j));
      }
      for (int n = 0; n < c.nodes; ++n)  // known times exactly, as SolveReduced gives them
        if (c.forest.unknown[c.forest.cls[n]] < 0) t[n] = pot[n];
    } else {
      t = SolveReduced(c, c.forest, *c.base, pot, targets);
    }
    bool fallback = c.base->fallback;
    std::vector<char> at_minimum(c.nodes, 0);
    const double tol = kConsistency * Scale(t);
    bool feasible = true;
    for (int n = 0; n < c.nodes && feasible; ++n)
      feasible = !c.has_next[n] || t[n + 1] - t[n] >= c.minimum[n] - tol;
    if (!feasible) {
      ActiveSetOutcome bounded = ActiveSet(c, FeasibleStart(c, pot), t, times, offsets, targets);
      t = bounded.t;
      at_minimum = bounded.at_minimum;
      fallback = fallback || bounded.fallback;
      out.iterations[static_cast<Eigen::Index>(k)] = bounded.iterations;
    }
    for (int n = 0; n < c.nodes; ++n)
      if (c.has_next[n] && !(t[n + 1] - t[n] > 0))
        throw std::runtime_error("TimeWarp: internal error, a warped time map does not increase");
    for (size_t la = 0; la < c.agents.size(); ++la) {
      const int a = c.agents[la];
      const int o = c.first[la], count = c.first[la + 1] - o;
      out.time_maps[a] = t.segment(o, count);
      out.solver[a] = fallback ? "SPQR fallback" : "LDLT";
      for (int n = o; n < o + count; ++n) out.min_enforced[a] += at_minimum[n];
    }
  }
  out.min_interval.resize(data.agents);
  for (int a = 0; a < data.agents; ++a) {
    const Eigen::VectorXd& m = out.time_maps[a];
    out.min_interval[a] = m.size() > 1 ? (m.tail(m.size() - 1) - m.head(m.size() - 1)).minCoeff()
                                       : std::numeric_limits<double>::infinity();
  }
  out.time_residuals.resize(data.time_constraints);
  for (int k = 0; k < data.time_constraints; ++k)
    out.time_residuals[k] = std::abs(out.time_maps[p.time_frames(k, 0)][p.time_frames(k, 1)] - times[k]);
  out.sync_residuals.resize(data.sync_constraints);
  for (int k = 0; k < data.sync_constraints; ++k)
    out.sync_residuals[k] = std::abs(out.time_maps[p.sync_frames(k, 0)][p.sync_frames(k, 1)] -
                                     out.time_maps[p.sync_frames(k, 2)][p.sync_frames(k, 3)] - offsets[k]);
  return out;
}

TimeWarpResult TimeWarp(const TimeWarpProblem& problem, const Eigen::Ref<const Eigen::VectorXd>& times,
                        const Eigen::Ref<const Eigen::VectorXd>& offsets) {
  TimeWarpData data;
  TimeWarpPrecompute(problem, data);
  return TimeWarpSolve(data, times, offsets);
}

}  // namespace mocapedit
