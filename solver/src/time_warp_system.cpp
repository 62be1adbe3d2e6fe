// Forests of hard edges, the reduced system and its solve (time_warp_internal.h).
#include "time_warp_internal.h"

#include <sstream>

#include "mocapedit/blas_lock.h"
#include "union_find.h"

namespace mocapedit::detail {

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
    if (r->qr->info() != Eigen::Success) throw NumericalError(kTimeWarp, "SPQR factorization failed");
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
    if (!z.allFinite()) throw NumericalError(kTimeWarp, "the linear solve produced non-finite times");
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

double Scale(const Eigen::VectorXd& t) { return 1.0 + (t.size() ? t.cwiseAbs().maxCoeff() : 0.0); }

}  // namespace mocapedit::detail
