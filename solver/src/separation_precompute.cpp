// Validation, each agent's unknowns and its two factored steps (separation_internal.h).
#include "separation_internal.h"

namespace mocapedit {
namespace detail {
namespace {

constexpr char kWhere[] = "SeparationPrecompute";

template <typename Scalar>
void Factor(StepSolver<Scalar>& solver, int n, const std::vector<Eigen::Triplet<Complex>>& triplets) {
  if (!solver.Factor(n, triplets)) throw NumericalError(kWhere, "an agent's energy could not be factored");
}

void Validate(const SeparationProblem& problem) {
  const Eigen::Index nv = problem.rest.rows();
  const Eigen::Index na = problem.starts.size() - 1;
  if (problem.starts.size() < 1 || problem.starts[0] != 0 || problem.starts[na] != nv)
    throw InvalidInput(kWhere, "starts must begin at 0 and end at the vertex count");
  for (Eigen::Index a = 0; a < na; ++a)
    if (problem.starts[a + 1] < problem.starts[a]) throw InvalidInput(kWhere, "starts must not decrease");
  if (!problem.rest.allFinite()) throw InvalidInput(kWhere, "rest positions must be finite");
  if (!(problem.anchor_weight > 0.0) || !std::isfinite(problem.anchor_weight))
    throw InvalidInput(kWhere, "anchor_weight must be positive");
  if (!(problem.still_extent >= 0.0)) throw InvalidInput(kWhere, "still_extent must not be negative");
}

// Each agent's vertices, and the rigid ranges inside it.
void SetUpAgents(const SeparationProblem& problem, SeparationState& data) {
  const Eigen::Index nv = problem.rest.rows();
  const Eigen::Index na = problem.starts.size() - 1;
  data.agent_of.resize(static_cast<size_t>(nv));
  data.agents = std::vector<Agent>(static_cast<size_t>(na));
  for (Eigen::Index a = 0; a < na; ++a) {
    Agent& ag = data.agents[static_cast<size_t>(a)];
    ag.first = problem.starts[a];
    ag.count = problem.starts[a + 1] - problem.starts[a];
    ag.range.assign(static_cast<size_t>(ag.count), -1);
    ag.s.assign(static_cast<size_t>(ag.count), 0.0);
    for (int i = 0; i < ag.count; ++i) data.agent_of[static_cast<size_t>(ag.first + i)] = static_cast<int>(a);
  }
  for (size_t r = 0; r < problem.rigid.size(); ++r) {
    const auto [first, last] = problem.rigid[r];
    if (first < 0 || last < first || last >= nv)
      throw InvalidInput(kWhere, "rigid range " + std::to_string(r) + " is out of range");
    Agent& ag = data.agents[static_cast<size_t>(data.agent_of[static_cast<size_t>(first)])];
    if (data.agent_of[static_cast<size_t>(last)] != data.agent_of[static_cast<size_t>(first)])
      throw InvalidInput(kWhere, "rigid range " + std::to_string(r) + " spans two agents");
    Range range;
    range.first = first - ag.first;
    range.last = last - ag.first;
    for (int i = range.first; i <= range.last; ++i) {
      if (ag.range[i] >= 0) throw InvalidInput(kWhere, "rigid ranges overlap");
      ag.range[i] = static_cast<int>(ag.ranges.size());
    }
    ag.ranges.push_back(range);
    ag.global_range.push_back(static_cast<int>(r));
  }
}

// Unknowns: free vertices in frame order, then each range's translation (and factor).
void NumberUnknowns(const Trajectory2& p, double still_extent, Agent& ag) {
  ag.free1.assign(static_cast<size_t>(ag.count), -1);
  ag.free2.assign(static_cast<size_t>(ag.count), -1);
  int n = 0;
  for (int i = 0; i < ag.count; ++i)
    if (ag.range[i] < 0) ag.free1[i] = ag.free2[i] = n++;
  ag.n1 = ag.n2 = n;
  for (Range& r : ag.ranges) {
    Complex sum = 0.0;
    for (int i = r.first; i <= r.last; ++i) sum += C(p, ag.first + i);
    r.centroid = sum / double(r.last - r.first + 1);
    double extent = 0.0;
    for (int i = r.first; i <= r.last; ++i) {
      ag.s[i] = C(p, ag.first + i) - r.centroid;
      extent = std::max(extent, std::abs(ag.s[i]));
    }
    r.t1 = ag.n1++;
    r.t2 = ag.n2++;
    if (extent > still_extent) r.m1 = ag.n1++;
  }
  ag.y1_rest.resize(ag.n1);
  for (int i = 0; i < ag.count; ++i)
    if (ag.free1[i] >= 0) ag.y1_rest[ag.free1[i]] = C(p, ag.first + i);
  for (const Range& r : ag.ranges) {
    ag.y1_rest[r.t1] = r.centroid;
    if (r.m1 >= 0) ag.y1_rest[r.m1] = 1.0;
  }
}

// Step 1: each inner frame in the frame of its two neighbours, and the anchors. `tiny`:
// neighbours closer than this frame nothing.
void FactorShape(const Trajectory2& p, double anchor_weight, double tiny, Agent& ag) {
  Normal one(ag.n1);
  std::vector<std::pair<Map, Complex>> terms;
  for (int i = 1; i + 1 < ag.count; ++i) {
    if (ag.range[i] >= 0 && ag.range[i - 1] == ag.range[i] && ag.range[i + 1] == ag.range[i]) continue;
    const Complex e = C(p, ag.first + i + 1) - C(p, ag.first + i - 1);
    const Complex d = C(p, ag.first + i) - C(p, ag.first + i - 1);
    Complex mu;
    if (std::abs(e) > tiny) {
      mu = d / e;
    } else if (std::abs(d) <= tiny) {
      mu = 0.5;  // standing still: the frame stays between its neighbours
    } else {
      continue;  // turns back on itself: no frame to express it in
    }
    ag.tri.push_back(i);
    ag.mu.push_back(mu);
    terms = {{ag.Map1(i), 1.0}, {ag.Map1(i - 1), -(1.0 - mu)}, {ag.Map1(i + 1), -mu}};
    one.Add(terms, 0.0, 1.0);
  }
  for (int i = 0; i < ag.count; ++i) {
    terms = {{ag.Map1(i), 1.0}};
    one.Add(terms, C(p, ag.first + i), anchor_weight);
  }
  Factor(ag.step1, ag.n1, one.triplets);
}

// Step 2: each step between frames, and the anchors. Its matrix does not depend on step 1
// (only its right-hand side does).
void FactorScale(double anchor_weight, Agent& ag) {
  const std::vector<Complex> no_turn(ag.ranges.size(), 1.0);
  Normal two(ag.n2);
  std::vector<std::pair<Map, Complex>> terms;
  for (int i = 0; i + 1 < ag.count; ++i) {
    if (ag.range[i] >= 0 && ag.range[i] == ag.range[i + 1]) continue;
    terms = {{ag.Map2(i + 1, no_turn), 1.0}, {ag.Map2(i, no_turn), -1.0}};
    two.Add(terms, 0.0, 1.0);
  }
  for (int i = 0; i < ag.count; ++i) {
    terms = {{ag.Map2(i, no_turn), 1.0}};
    two.Add(terms, 0.0, anchor_weight);
  }
  Factor(ag.step2, ag.n2, two.triplets);
}

}  // namespace
}  // namespace detail

SeparationData::SeparationData() = default;
SeparationData::~SeparationData() = default;
SeparationData::SeparationData(SeparationData&&) noexcept = default;
SeparationData& SeparationData::operator=(SeparationData&&) noexcept = default;

int SeparationAgentCount(const SeparationData& data) { return data.state ? static_cast<int>(data.state->agents.size()) : 0; }
int SeparationVertexCount(const SeparationData& data) { return data.state ? static_cast<int>(data.state->rest.rows()) : 0; }

void SeparationPrecompute(const SeparationProblem& problem, SeparationData& out) {
  using namespace detail;
  Validate(problem);
  auto data = std::make_unique<SeparationState>();
  const Eigen::Index nv = problem.rest.rows();
  data->rest = problem.rest;
  data->starts = problem.starts;
  data->rigid = problem.rigid;
  data->anchor_weight = problem.anchor_weight;
  data->still_extent = problem.still_extent;
  data->threads = ThreadCount(problem.threads, nv);
  SetUpAgents(problem, *data);
  const double scale = 1.0 + (nv ? problem.rest.cwiseAbs().maxCoeff() : 0.0);
  const double tiny = std::max(problem.still_extent, 1e-12 * scale);
  const int na = static_cast<int>(data->agents.size());
  ParallelFor(na, data->threads, [&](int a) {
    Agent& ag = data->agents[static_cast<size_t>(a)];
    if (ag.count == 0) return;
    NumberUnknowns(data->rest, problem.still_extent, ag);
    FactorShape(data->rest, problem.anchor_weight, tiny, ag);
    FactorScale(problem.anchor_weight, ag);
  });
  out.state = std::move(data);
}

}  // namespace mocapedit
