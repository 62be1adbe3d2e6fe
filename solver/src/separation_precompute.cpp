// Validation, each agent's unknowns and its two factored steps (separation_internal.h).
#include "separation_internal.h"

#include <numeric>

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
  if (problem.rates.size() != 0 && problem.rates.size() != na)
    throw InvalidInput(kWhere, "rates must have one entry per agent, or none");
  for (Eigen::Index a = 0; a < problem.rates.size(); ++a)
    if (!(problem.rates[a] > 0.0) || !std::isfinite(problem.rates[a]))
      throw InvalidInput(kWhere, "rates must be positive and finite (agent " + std::to_string(a) + ")");
  if (problem.anchor_frames.size() != 0 &&
      (problem.anchor_frames.size() != nv || !problem.anchor_frames.allFinite() || (problem.anchor_frames.array() < 1.0).any()))
    throw InvalidInput(kWhere, "anchor_frames must have one finite entry >= 1 per vertex, or none");
  if (problem.cut_into.size() != 0 && problem.cut_into.size() != nv)
    throw InvalidInput(kWhere, "cut_into must have one entry per vertex, or none");
  if (!(problem.still_extent >= 0.0)) throw InvalidInput(kWhere, "still_extent must not be negative");
  if (!(problem.min_baseline >= 0.0) || !std::isfinite(problem.min_baseline))
    throw InvalidInput(kWhere, "min_baseline must be a finite value >= 0");
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
    const double k = problem.rates.size() ? problem.rates[a] : 1.0;
    ag.anchor = problem.anchor_weight / k;
    ag.shape_weight = k * k * k;
    ag.edge_weight = k;
    if (problem.anchor_frames.size() && (problem.anchor_frames.segment(ag.first, ag.count).array() != 1.0).any())
      ag.anchor_frames.assign(problem.anchor_frames.data() + ag.first, problem.anchor_frames.data() + ag.first + ag.count);
    if (problem.cut_into.size() && problem.cut_into.segment(ag.first + 1, std::max(ag.count - 1, 0)).any()) {
      ag.cuts_before.assign(static_cast<size_t>(ag.count), 0);
      for (int i = 1; i < ag.count; ++i)
        ag.cuts_before[static_cast<size_t>(i)] = ag.cuts_before[static_cast<size_t>(i - 1)] + (problem.cut_into[ag.first + i] != 0);
    }
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

// Unknowns: free vertices in frame order, then each range's translation (and factor, when
// its extent is above `small`).
void NumberUnknowns(const Trajectory2& p, double small, Agent& ag) {
  ag.free1.assign(static_cast<size_t>(ag.count), -1);
  ag.free2.assign(static_cast<size_t>(ag.count), -1);
  int n = 0;
  for (int i = 0; i < ag.count; ++i)
    if (ag.range[i] < 0) ag.free1[i] = ag.free2[i] = n++;
  ag.n1 = ag.n2 = n;
  const auto z = [&](int i) { return C(p, ag.first + i); };
  for (Range& r : ag.ranges) {
    Complex sum = 0.0;
    for (int i = r.first; i <= r.last; ++i) sum += z(i);
    r.centroid = sum / double(r.last - r.first + 1);
    for (int i = r.first; i <= r.last; ++i) ag.s[i] = z(i) - r.centroid;
    std::vector<int> members(static_cast<size_t>(r.last - r.first + 1));
    std::iota(members.begin(), members.end(), r.first);
    const auto [m1, m2] = RangeMasters(members, z);
    r.t1 = ag.n1++;
    r.t2 = ag.n2++;
    if (std::abs(z(m2) - z(m1)) > small) r.m1 = ag.n1++;
  }
  ag.y1_rest.resize(ag.n1);
  for (int i = 0; i < ag.count; ++i)
    if (ag.free1[i] >= 0) ag.y1_rest[ag.free1[i]] = z(i);
  for (const Range& r : ag.ranges) {
    ag.y1_rest[r.t1] = r.centroid;
    if (r.m1 >= 0) ag.y1_rest[r.m1] = 1.0;
  }
}

// Step 1: each inner frame in the frame of the frames around it at least `baseline` apart,
// and the anchors.
void FactorShape(const SeparationState& data, double baseline, Agent& ag) {
  Normal one(ag.n1);
  const auto map = [&](int i) { return ag.Map1(i); };
  const auto range_of = [&](int i) { return ag.RangeOf(i); };
  const auto z = [&](int i) { return C(data.rest, ag.first + i); };
  ChainFrames(data.rest, ag.first, ag.count, baseline, [&](int i, int a, int b) {
    if (!InOneRange(range_of, {i, a, b}) && !ag.AcrossCut(a, b))
      one.Add(Row(MakeShapeTerm(i, a, b, z(i), z(a), z(b))), map, 0.0, ag.shape_weight);
  });
  for (int i = 0; i < ag.count; ++i) one.Add(AnchorRow(i), map, C(data.rest, ag.first + i), ag.Anchor(i));
  Factor(ag.step1, ag.n1, one.triplets);
}

// Step 2: each step between frames, and the anchors. Its matrix does not depend on step 1
// (only its right-hand side does).
void FactorScale(const SeparationState& data, Agent& ag) {
  Normal two(ag.n2);
  data.Step2Terms(ag, {}, std::vector<Complex>(ag.ranges.size(), 1.0), two);
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
  data->still_extent = problem.still_extent;
  data->threads = ThreadCount(problem.threads, nv);
  SetUpAgents(problem, *data);
  const double scale = 1.0 + (nv ? problem.rest.cwiseAbs().maxCoeff() : 0.0);
  // Frames closer than still_extent stand still: they never frame a shape term.
  const double baseline = std::max({problem.min_baseline, problem.still_extent, 1e-12 * scale});
  const int na = static_cast<int>(data->agents.size());
  ParallelFor(na, data->threads, [&](int a) {
    Agent& ag = data->agents[static_cast<size_t>(a)];
    if (ag.count == 0) return;
    NumberUnknowns(data->rest, problem.still_extent, ag);
    FactorShape(*data, baseline, ag);
    FactorScale(*data, ag);
  });
  out.state = std::move(data);
}

}  // namespace mocapedit
