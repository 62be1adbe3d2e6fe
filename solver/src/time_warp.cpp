#include "mocapedit/time_warp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include "time_warp_internal.h"
#include "union_find.h"

namespace mocapedit {

TimeWarpData::TimeWarpData() = default;
TimeWarpData::~TimeWarpData() = default;
TimeWarpData::TimeWarpData(TimeWarpData&&) noexcept = default;
TimeWarpData& TimeWarpData::operator=(TimeWarpData&&) noexcept = default;

namespace detail {
namespace {

constexpr char kWhere[] = "TimeWarp";

// Messages are built only on failure: validation runs on every frame of every agent.
bool FrameOk(const TimeWarpProblem& p, int agent, int frame) {
  return agent >= 0 && agent < static_cast<int>(p.rest_times.size()) && frame >= 0 &&
         frame < p.rest_times[agent].size();
}

void CheckFrame(const TimeWarpProblem& p, int agent, int frame, const char* kind, Eigen::Index k) {
  if (FrameOk(p, agent, frame)) return;
  const std::string what = std::string(kind) + " " + std::to_string(k);
  Require(agent >= 0 && agent < static_cast<int>(p.rest_times.size()), kWhere,
          what + ": agent " + std::to_string(agent) + " is not one of the " + std::to_string(p.rest_times.size()) +
              " agents");
  throw InvalidInput(kWhere, what + ": frame " + std::to_string(frame) + " is outside agent " + std::to_string(agent) +
                                 "'s frames 0.." + std::to_string(p.rest_times[agent].size() - 1));
}

void Validate(const TimeWarpProblem& p) {
  Require(p.min_interval_fraction > 0 && p.min_interval_fraction <= 1, kWhere,
          "min_interval_fraction must be in (0, 1]");
  Require(std::isfinite(p.stretch_weight) && p.stretch_weight >= 0, kWhere, "stretch_weight must be finite and >= 0");
  Require(std::isfinite(p.anchor_weight) && p.anchor_weight > 0, kWhere, "anchor_weight must be finite and > 0");
  Require(p.min_intervals.empty() || p.min_intervals.size() == p.rest_times.size(), kWhere,
          "min_intervals must be empty or hold one list per agent");
  for (size_t a = 0; a < p.rest_times.size(); ++a) {
    const Eigen::VectorXd& r = p.rest_times[a];
    const std::string who = "agent " + std::to_string(a);
    Require(r.size() > 0, kWhere, who + " has no frames");
    Require(r.allFinite(), kWhere, who + ": rest times must be finite");
    for (Eigen::Index i = 1; i < r.size(); ++i)
      if (!(r[i] > r[i - 1]))
        throw InvalidInput(kWhere, who + ": rest times must increase (frame " + std::to_string(i) + ")");
    if (!p.min_intervals.empty() && p.min_intervals[a].size() > 0) {
      const Eigen::VectorXd& m = p.min_intervals[a];
      Require(m.size() == r.size() - 1, kWhere, who + ": min_intervals needs one value per interval");
      Require(m.allFinite() && (m.array() > 0).all(), kWhere, who + ": min_intervals must be finite and > 0");
    }
  }
  const auto t = p.time_frames.rows();
  Require(p.time_hard.size() == t && p.time_weights.size() == t, kWhere,
          "time_hard and time_weights need one value per time constraint");
  for (Eigen::Index k = 0; k < t; ++k) {
    CheckFrame(p, p.time_frames(k, 0), p.time_frames(k, 1), "time constraint", k);
    if (!(std::isfinite(p.time_weights[k]) && p.time_weights[k] >= 0))
      throw InvalidInput(kWhere, "time constraint " + std::to_string(k) + ": weight must be finite and >= 0");
  }
  const auto s = p.sync_frames.rows();
  Require(p.sync_hard.size() == s && p.sync_weights.size() == s, kWhere,
          "sync_hard and sync_weights need one value per sync constraint");
  for (Eigen::Index k = 0; k < s; ++k) {
    CheckFrame(p, p.sync_frames(k, 0), p.sync_frames(k, 1), "sync constraint", k);
    CheckFrame(p, p.sync_frames(k, 2), p.sync_frames(k, 3), "sync constraint (target)", k);
    if (!(std::isfinite(p.sync_weights[k]) && p.sync_weights[k] >= 0))
      throw InvalidInput(kWhere, "sync constraint " + std::to_string(k) + ": weight must be finite and >= 0");
  }
}

// Node of (local agent, frame).
int Node(const TimeWarpComponent& c, int local_agent, int frame) { return c.first[local_agent] + frame; }

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
    what << "hard constraints contradict (time constraints [" << Join(time_ids)
         << "], sync constraints [" << Join(sync_ids) << "]): they disagree by " << std::abs(have - want)
         << " time codes";
    throw TimeWarpConflict(TimeWarpConflict::Kind::kCycle, {time_ids.begin(), time_ids.end()},
                           {sync_ids.begin(), sync_ids.end()}, std::abs(have - want), -1, -1, -1, 0.0, 0.0,
                           what.str());
  }
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

// The components: agents linked by a (non-zero) sync constraint solve together. Fills
// data.agent_component; `members`, `time_ids`, `sync_ids` per component.
void SplitComponents(const TimeWarpProblem& problem, TimeWarpData& data, std::vector<std::vector<int>>& members,
                     std::vector<std::vector<int>>& time_ids, std::vector<std::vector<int>>& sync_ids) {
  const int agents = data.agents;
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
}

// Warps the time maps of one component's agents into `out`; returns its active-set
// iterations.
int SolveComponent(const TimeWarpComponent& c, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets,
                   TimeWarpResult& out) {
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
  int iterations = 0;
  for (int n = 0; n < c.nodes && feasible; ++n)
    feasible = !c.has_next[n] || t[n + 1] - t[n] >= c.minimum[n] - tol;
  if (!feasible) {
    ActiveSetOutcome bounded = ActiveSet(c, FeasibleStart(c, pot), t, times, offsets, targets);
    t = bounded.t;
    at_minimum = bounded.at_minimum;
    fallback = fallback || bounded.fallback;
    iterations = bounded.iterations;
  }
  for (int n = 0; n < c.nodes; ++n)
    if (c.has_next[n] && !(t[n + 1] - t[n] > 0))
      throw SolverError("TimeWarp: internal error, a warped time map does not increase");
  for (size_t la = 0; la < c.agents.size(); ++la) {
    const int a = c.agents[la];
    const int o = c.first[la], count = c.first[la + 1] - o;
    out.time_maps[a] = t.segment(o, count);
    out.solver[a] = fallback ? "SPQR fallback" : "LDLT";
    for (int n = o; n < o + count; ++n) out.min_enforced[a] += at_minimum[n];
  }
  return iterations;
}

// Each agent's smallest interval and each constraint's residual.
void Residuals(const TimeWarpData& data, const Eigen::VectorXd& times, const Eigen::VectorXd& offsets,
               TimeWarpResult& out) {
  const TimeWarpProblem& p = data.problem;
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
}

}  // namespace
}  // namespace detail

void TimeWarpPrecompute(const TimeWarpProblem& problem, TimeWarpData& data) {
  using namespace detail;
  Validate(problem);
  data = TimeWarpData();
  data.agents = static_cast<int>(problem.rest_times.size());
  data.time_constraints = static_cast<int>(problem.time_frames.rows());
  data.sync_constraints = static_cast<int>(problem.sync_frames.rows());
  data.problem = problem;
  std::vector<std::vector<int>> members, time_ids, sync_ids;
  SplitComponents(problem, data, members, time_ids, sync_ids);
  for (size_t k = 0; k < members.size(); ++k) {
    auto c = std::make_unique<TimeWarpComponent>();
    BuildComponent(problem, members[k], time_ids[k], sync_ids[k], *c);
    if (problem.precompute_responses) BuildResponses(data, *c);
    data.components.push_back(std::move(c));
  }
}

void TimeWarpSolve(const TimeWarpData& data, const Eigen::Ref<const Eigen::VectorXd>& times_in,
                   const Eigen::Ref<const Eigen::VectorXd>& offsets_in, TimeWarpResult& out) {
  using namespace detail;
  Require(times_in.size() == data.time_constraints, kWhere, "times needs one value per time constraint");
  Require(offsets_in.size() == data.sync_constraints, kWhere, "offsets needs one value per sync constraint");
  Require(times_in.allFinite(), kWhere, "times must be finite");
  Require(offsets_in.allFinite(), kWhere, "offsets must be finite");
  const Eigen::VectorXd times = times_in, offsets = offsets_in;
  out = TimeWarpResult();
  out.time_maps = data.problem.rest_times;
  out.solver.assign(data.agents, "rest");
  out.min_enforced = Eigen::VectorXi::Zero(data.agents);
  out.component = Eigen::Map<const Eigen::VectorXi>(data.agent_component.data(), data.agents);
  out.iterations = Eigen::VectorXi::Zero(static_cast<Eigen::Index>(data.components.size()));
  for (size_t k = 0; k < data.components.size(); ++k)
    out.iterations[static_cast<Eigen::Index>(k)] = SolveComponent(*data.components[k], times, offsets, out);
  Residuals(data, times, offsets, out);
}

void TimeWarp(const TimeWarpProblem& problem, const Eigen::Ref<const Eigen::VectorXd>& times,
              const Eigen::Ref<const Eigen::VectorXd>& offsets, TimeWarpResult& result) {
  TimeWarpData data;
  TimeWarpPrecompute(problem, data);
  TimeWarpSolve(data, times, offsets, result);
}

}  // namespace mocapedit
