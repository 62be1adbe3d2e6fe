// The minimum intervals of time warping: a feasible start and the primal active-set method
// (time_warp_internal.h).
#include "time_warp_internal.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

namespace mocapedit::detail {

namespace {

// Y[cls(b)] - Y[cls(a)] >= w between consecutive touched frames a < b of one agent: `span`
// is the least time the minimum intervals leave between them.
struct Gap {
  int a, b;
  double w, span;
};

// A frame whose class the hard constraints tie to other frames.
bool Touched(const Forest& f, int n) { return f.size[f.cls[n]] > 1; }

std::vector<Gap> Gaps(const TimeWarpComponent& c, const Eigen::VectorXd& pot) {
  std::vector<Gap> gaps;
  for (size_t la = 0; la < c.agents.size(); ++la) {
    int prev = -1;
    double span = 0.0;
    for (int n = c.first[la]; n < c.first[la + 1]; ++n) {
      if (Touched(c.forest, n)) {
        if (prev >= 0) gaps.push_back({prev, n, span - pot[n] + pot[prev], span});
        prev = n;
        span = 0.0;
      }
      if (c.has_next[n]) span += c.minimum[n];
    }
  }
  return gaps;
}

// The negative cycle Bellman-Ford found through class `last` (its predecessor gaps in
// `pred`): throws the TimeWarpConflict naming the hard constraints along it.
[[noreturn]] void ThrowBackwards(const TimeWarpComponent& c, const Eigen::VectorXd& pot, const std::vector<Gap>& gaps,
                                 const std::vector<int>& pred, int last) {
  const Forest& f = c.forest;
  const int classes = static_cast<int>(f.root.size());
  // Walk back onto the cycle, then collect the hard constraints along it.
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
  what << "hard constraints would run time backwards or below the minimum interval "
       << "(time constraints [" << Join(time_ids) << "], sync constraints [" << Join(sync_ids) << "])";
  throw TimeWarpConflict(TimeWarpConflict::Kind::kBackwards, {time_ids.begin(), time_ids.end()},
                         {sync_ids.begin(), sync_ids.end()}, 0.0, agent, fa, fb, gap, minimum, what.str());
}

// Every frame's time from the known frames' (t, where `known` flags them) of one agent's
// frames begin..end-1: between known frames, the time is spread in proportion to the
// minimum intervals' excess; outside them, the rest intervals are kept.
void SpreadBetweenKnown(const TimeWarpComponent& c, int begin, int end, const std::vector<int>& known,
                        Eigen::VectorXd& t) {
  if (known.empty()) {
    t.segment(begin, end - begin) = c.rest.segment(begin, end - begin);
    return;
  }
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

}  // namespace

// A system of difference constraints between the classes of the hard forest, solved by
// Bellman-Ford.
Eigen::VectorXd FeasibleStart(const TimeWarpComponent& c, const Eigen::VectorXd& pot) {
  const Forest& f = c.forest;
  const std::vector<Gap> gaps = Gaps(c, pot);
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
  if (last >= 0) ThrowBackwards(c, pot, gaps, pred, last);
  const int ground_class = f.cls[c.nodes];
  Eigen::VectorXd t(c.nodes);
  for (size_t la = 0; la < c.agents.size(); ++la) {
    const int begin = c.first[la], end = c.first[la + 1];
    std::vector<int> known;
    for (int n = begin; n < end; ++n)
      if (Touched(f, n)) {
        t[n] = dist[f.cls[n]] - dist[ground_class] + pot[n];
        known.push_back(n);
      }
    SpreadBetweenKnown(c, begin, end, known, t);
  }
  return t;
}

Eigen::VectorXd Gradient(const TimeWarpComponent& c, const Eigen::VectorXd& t, const Eigen::VectorXd& targets) {
  return c.a.transpose() * (c.a * (t - c.rest) - targets);
}


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

}  // namespace mocapedit::detail
