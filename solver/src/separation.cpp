#include "mocapedit/separation.h"
#include "mocapedit/skyline_ldlt.h"
#include "mocapedit/two_threads.h"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>

namespace mocapedit {
namespace {

using Complex = std::complex<double>;
using CSparse = Eigen::SparseMatrix<Complex>;
// One factored step of one agent, K = L D L^H. The agent's unknowns are its frames in
// order, then its ranges' few unknowns. Without ranges K is banded (bandwidth 2 in step 1,
// whose terms join three frames, 1 in step 2, whose terms join two) and is factored as an
// envelope (SkylineLdlt, a band being an envelope of constant width); with ranges, whose
// unknowns border the band, as a sparse matrix in the same order (no fill either way, so no
// ordering). Step 2's matrix is real (its terms are differences of positions and anchors);
// its complex right-hand sides are solved as two real ones.
template <typename Scalar>
class StepSolver {
 public:
  static constexpr int kMaxBand = 4;

  // Factors the n by n matrix summed from `triplets` (imaginary parts dropped when real).
  // Returns false when it is not positive definite.
  bool Factor(int n, const std::vector<Eigen::Triplet<Complex>>& triplets) {
    n_ = n;
    int band = 0;
    for (const auto& t : triplets) band = std::max(band, std::abs(t.row() - t.col()));
    banded_ = band <= kMaxBand;
    if (!banded_) {
      std::vector<Eigen::Triplet<Scalar>> converted;
      converted.reserve(triplets.size());
      for (const auto& t : triplets) converted.emplace_back(t.row(), t.col(), Convert(t.value()));
      Eigen::SparseMatrix<Scalar> k(n, n);
      k.setFromTriplets(converted.begin(), converted.end());
      sparse_.compute(k);
      return sparse_.info() == Eigen::Success;
    }
    std::vector<int> first(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) first[i] = std::max(0, i - band);
    band_.Reset(first);
    for (const auto& t : triplets)
      if (t.row() >= t.col()) band_.Add(t.row(), t.col(), Convert(t.value()));
    return band_.Factor();
  }

  // K^-1 b for each column of b (#n by m).
  Eigen::MatrixXcd Solve(const Eigen::MatrixXcd& b) const {
    if (!banded_) return SparseSolve(b);
    Eigen::MatrixXcd x = b;
    for (Eigen::Index c = 0; c < x.cols(); ++c) band_.Solve(x.col(c).data(), 1);
    return x;
  }

  // Columns `columns` of K^-1, #n by columns.size(); in column c only the rows from
  // min(columns[c], lowest) on are meant to be read (the band path leaves the rows above
  // undone: those of other columns follow from symmetry).
  Eigen::MatrixXcd InverseColumns(const std::vector<int>& columns, int lowest) const {
    const Eigen::Index m = static_cast<Eigen::Index>(columns.size());
    Eigen::MatrixXcd x = Eigen::MatrixXcd::Zero(n_, m);
    for (Eigen::Index c = 0; c < m; ++c) x(columns[static_cast<size_t>(c)], c) = 1.0;
    if (!banded_) return SparseSolve(x);
    for (Eigen::Index c = 0; c < m; ++c) {
      const int j = columns[static_cast<size_t>(c)];
      band_.SolveFrom(x.col(c).data(), j, std::min(j, lowest));  // the forward pass starts at the unit entry
    }
    return x;
  }

 private:
  static Scalar Convert(Complex v) {
    if constexpr (std::is_same_v<Scalar, double>) return v.real();
    else return v;
  }

  Eigen::MatrixXcd SparseSolve(const Eigen::MatrixXcd& b) const {
    if constexpr (std::is_same_v<Scalar, double>) {
      const Eigen::Index n = b.rows(), m = b.cols();
      Eigen::MatrixXd parts(n, 2 * m);
      parts.leftCols(m) = b.real();
      parts.rightCols(m) = b.imag();
      const Eigen::MatrixXd x = sparse_.solve(parts);
      Eigen::MatrixXcd out(n, m);
      out.real() = x.leftCols(m);
      out.imag() = x.rightCols(m);
      return out;
    } else {
      return sparse_.solve(b);
    }
  }

  int n_ = 0;
  bool banded_ = false;
  SkylineLdlt<Scalar> band_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<Scalar>, Eigen::Lower, Eigen::NaturalOrdering<int>> sparse_;
};

// Ground positions are complex numbers x + iy: step 1's shape terms are then linear with
// complex coefficients (a similarity is one complex factor), and step 2 acts on both
// coordinates alike.
Complex C(const Trajectory2& p, Eigen::Index i) { return {p(i, 0), p(i, 1)}; }

struct Range {
  int first = 0, last = 0;   // local vertices, inclusive
  int t1 = -1, m1 = -1;      // step-1 unknowns: translation, similarity factor (-1: none)
  int t2 = -1;               // step-2 unknown: translation
  Complex centroid;
};

// A local vertex as a combination of unknowns: z = sum a_j y_j + k.
struct Map {
  int j0 = -1, j1 = -1;
  Complex a0, a1, k;
};

struct Agent {
  int first = 0, count = 0;
  std::vector<int> free1, free2;  // per local vertex: unknown index, -1 inside a range
  std::vector<int> range;         // per local vertex: range index, -1 when free
  std::vector<Complex> s;         // per local vertex: rest minus its range's centroid
  std::vector<Range> ranges;
  std::vector<int> global_range;  // per range: index into SeparationProblem::rigid
  int n1 = 0, n2 = 0;
  StepSolver<Complex> step1;
  StepSolver<double> step2;
  Eigen::VectorXcd y1_rest;
  // Step-1 triangles: vertex i = (1 - mu) z_{i-1} + mu z_{i+1}.
  std::vector<int> tri;
  std::vector<Complex> mu;

  Map Map1(int i) const {
    Map m;
    if (free1[i] >= 0) {
      m.j0 = free1[i];
      m.a0 = 1.0;
      return m;
    }
    const Range& r = ranges[range[i]];
    m.j0 = r.t1;
    m.a0 = 1.0;
    if (r.m1 >= 0) {
      m.j1 = r.m1;
      m.a1 = s[i];
    }
    return m;
  }

  Map Map2(int i, const std::vector<Complex>& turn) const {
    Map m;
    if (free2[i] >= 0) {
      m.j0 = free2[i];
      m.a0 = 1.0;
      return m;
    }
    const int k = range[i];
    m.j0 = ranges[k].t2;
    m.a0 = 1.0;
    m.k = turn[k] * s[i];
    return m;
  }
};

// Accumulates sum |sum_i c_i z_i - beta|^2 over residuals into K (triplets) and b.
struct Normal {
  std::vector<Eigen::Triplet<Complex>> triplets;
  Eigen::VectorXcd b;
  std::vector<std::pair<int, Complex>> row;

  bool matrix = true;  // false: the right-hand side alone

  explicit Normal(int n, bool with_matrix = true) : b(Eigen::VectorXcd::Zero(n)), matrix(with_matrix) {}

  // Residual given as (map, coefficient) pairs; `beta` on the right-hand side.
  void Add(const std::vector<std::pair<Map, Complex>>& terms, Complex beta, double weight) {
    row.clear();
    for (const auto& [m, c] : terms) {
      row.emplace_back(m.j0, c * m.a0);
      if (m.j1 >= 0) row.emplace_back(m.j1, c * m.a1);
      beta -= c * m.k;
    }
    for (const auto& [j, aj] : row) {
      if (matrix)
        for (const auto& [k, ak] : row) triplets.emplace_back(j, k, weight * std::conj(aj) * ak);
      b[j] += weight * std::conj(aj) * beta;
    }
  }
};

double Seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

template <typename Fn>
void ParallelFor(int count, int threads, Fn fn) {
  threads = std::max(1, std::min(threads, count));
  OnThreads(threads, [&](int t) {
    for (int i = t; i < count; i += threads) fn(i);
  });
}

int ThreadCount(int requested, int64_t work) {
  int threads = requested > 0 ? requested : static_cast<int>(std::min(2u, std::max(1u, std::thread::hardware_concurrency())));
  return work < 20000 ? 1 : threads;
}

template <typename Scalar>
void Factor(StepSolver<Scalar>& solver, int n, const std::vector<Eigen::Triplet<Complex>>& triplets) {
  if (!solver.Factor(n, triplets))
    throw std::runtime_error("SeparationPrecompute: an agent's energy could not be factored");
}

}  // namespace

struct SeparationData {
  Trajectory2 rest;
  Eigen::VectorXi starts;
  std::vector<FrameRange> rigid;
  double anchor_weight = 0, still_extent = 0;
  int threads = 1;
  std::vector<Agent> agents;
  std::vector<int> agent_of;  // global vertex -> agent

  // Step-2 right-hand side of one agent for given edge vectors and range turns.
  Eigen::VectorXcd Step2Rhs(const Agent& ag, const std::vector<Complex>& edges,
                            const std::vector<Complex>& turn) const {
    Normal normal(ag.n2, false);
    std::vector<std::pair<Map, Complex>> terms;
    for (int i = 0; i + 1 < ag.count; ++i) {
      if (ag.range[i] >= 0 && ag.range[i] == ag.range[i + 1]) continue;
      terms = {{ag.Map2(i + 1, turn), 1.0}, {ag.Map2(i, turn), -1.0}};
      normal.Add(terms, edges[static_cast<size_t>(i)], 1.0);
    }
    for (int i = 0; i < ag.count; ++i) {
      terms = {{ag.Map2(i, turn), 1.0}};
      normal.Add(terms, C(rest, ag.first + i), anchor_weight);
    }
    return normal.b;
  }
};

int SeparationAgentCount(const SeparationData& data) { return static_cast<int>(data.agents.size()); }
int SeparationVertexCount(const SeparationData& data) { return static_cast<int>(data.rest.rows()); }

void SeparationPrecompute(const SeparationProblem& problem, std::shared_ptr<SeparationData>& out) {
  const Eigen::Index nv = problem.rest.rows();
  const Eigen::Index na = problem.starts.size() - 1;
  if (problem.starts.size() < 1 || problem.starts[0] != 0 || problem.starts[na] != nv)
    throw std::invalid_argument("SeparationPrecompute: starts must begin at 0 and end at the vertex count");
  for (Eigen::Index a = 0; a < na; ++a)
    if (problem.starts[a + 1] < problem.starts[a])
      throw std::invalid_argument("SeparationPrecompute: starts must not decrease");
  if (!problem.rest.allFinite()) throw std::invalid_argument("SeparationPrecompute: rest positions must be finite");
  if (!(problem.anchor_weight > 0.0) || !std::isfinite(problem.anchor_weight))
    throw std::invalid_argument("SeparationPrecompute: anchor_weight must be positive");
  if (!(problem.still_extent >= 0.0)) throw std::invalid_argument("SeparationPrecompute: still_extent must not be negative");

  auto data = std::make_shared<SeparationData>();
  data->rest = problem.rest;
  data->starts = problem.starts;
  data->rigid = problem.rigid;
  data->anchor_weight = problem.anchor_weight;
  data->still_extent = problem.still_extent;
  data->threads = ThreadCount(problem.threads, nv);
  data->agent_of.resize(static_cast<size_t>(nv));
  data->agents = std::vector<Agent>(static_cast<size_t>(na));
  for (Eigen::Index a = 0; a < na; ++a) {
    Agent& ag = data->agents[static_cast<size_t>(a)];
    ag.first = problem.starts[a];
    ag.count = problem.starts[a + 1] - problem.starts[a];
    ag.range.assign(static_cast<size_t>(ag.count), -1);
    ag.s.assign(static_cast<size_t>(ag.count), 0.0);
    for (int i = 0; i < ag.count; ++i) data->agent_of[static_cast<size_t>(ag.first + i)] = static_cast<int>(a);
  }
  for (size_t r = 0; r < problem.rigid.size(); ++r) {
    const auto [first, last] = problem.rigid[r];
    if (first < 0 || last < first || last >= nv)
      throw std::invalid_argument("SeparationPrecompute: rigid range " + std::to_string(r) + " is out of range");
    Agent& ag = data->agents[static_cast<size_t>(data->agent_of[static_cast<size_t>(first)])];
    if (data->agent_of[static_cast<size_t>(last)] != data->agent_of[static_cast<size_t>(first)])
      throw std::invalid_argument("SeparationPrecompute: rigid range " + std::to_string(r) + " spans two agents");
    Range range;
    range.first = first - ag.first;
    range.last = last - ag.first;
    for (int i = range.first; i <= range.last; ++i) {
      if (ag.range[i] >= 0) throw std::invalid_argument("SeparationPrecompute: rigid ranges overlap");
      ag.range[i] = static_cast<int>(ag.ranges.size());
    }
    ag.ranges.push_back(range);
    ag.global_range.push_back(static_cast<int>(r));
  }

  const double scale = 1.0 + (nv ? problem.rest.cwiseAbs().maxCoeff() : 0.0);
  const double tiny = std::max(problem.still_extent, 1e-12 * scale);
  ParallelFor(static_cast<int>(na), data->threads, [&](int a) {
    Agent& ag = data->agents[static_cast<size_t>(a)];
    if (ag.count == 0) return;
    const Trajectory2& p = data->rest;
    // Unknowns: free vertices in frame order, then each range's translation (and factor).
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
      if (extent > problem.still_extent) r.m1 = ag.n1++;
    }
    ag.y1_rest.resize(ag.n1);
    for (int i = 0; i < ag.count; ++i)
      if (ag.free1[i] >= 0) ag.y1_rest[ag.free1[i]] = C(p, ag.first + i);
    for (const Range& r : ag.ranges) {
      ag.y1_rest[r.t1] = r.centroid;
      if (r.m1 >= 0) ag.y1_rest[r.m1] = 1.0;
    }

    // Step 1: each inner frame in the frame of its two neighbours, and the anchors.
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
      one.Add(terms, C(p, ag.first + i), problem.anchor_weight);
    }
    Factor(ag.step1, ag.n1, one.triplets);

    // Step 2: each step between frames, and the anchors. Its matrix does not depend on
    // step 1 (only its right-hand side does).
    const std::vector<Complex> no_turn(ag.ranges.size(), 1.0);
    Normal two(ag.n2);
    for (int i = 0; i + 1 < ag.count; ++i) {
      if (ag.range[i] >= 0 && ag.range[i] == ag.range[i + 1]) continue;
      terms = {{ag.Map2(i + 1, no_turn), 1.0}, {ag.Map2(i, no_turn), -1.0}};
      two.Add(terms, 0.0, 1.0);
    }
    for (int i = 0; i < ag.count; ++i) {
      terms = {{ag.Map2(i, no_turn), 1.0}};
      two.Add(terms, 0.0, problem.anchor_weight);
    }
    Factor(ag.step2, ag.n2, two.triplets);
  });
  out = data;
}

namespace {

// Lists of (index, coefficient) pairs, one list per local row, stored one after another
// (a few allocations per agent rather than one per row).
struct RowLists {
  using Item = std::pair<int, Complex>;
  struct Span {
    const Item *first, *last;
    const Item* begin() const { return first; }
    const Item* end() const { return last; }
  };
  std::vector<int> start{0};  // #rows+1 offsets into items
  std::vector<Item> items;

  size_t rows() const { return start.size() - 1; }
  Span row(size_t k) const { return {items.data() + start[k], items.data() + start[k + 1]}; }
  void Clear() {
    start.assign(1, 0);
    items.clear();
  }
  void CloseRow() { start.push_back(static_cast<int>(items.size())); }
  bool operator==(const RowLists& other) const { return start == other.start && items == other.items; }
};

// Entries of an agent's K^-1 between some of its unknowns, grown as rows touch new ones.
struct InverseBlock {
  std::vector<int> unknowns;      // cached unknowns, in the order of `inverse`
  std::vector<int> slot;          // per unknown of the step: index into `unknowns`, -1 if absent
  Eigen::MatrixXcd inverse;       // K^-1 restricted to `unknowns`

  // The last solve's rows of the agent (their terms), and their G and Schur block.
  RowLists terms, g;
  Eigen::MatrixXd s;
  int64_t columns = 0;  // back-substitutions done so far

  Complex At(int i, int j) const { return inverse(slot[static_cast<size_t>(i)], slot[static_cast<size_t>(j)]); }

  template <typename Solver>
  void Ensure(const Solver& solver, int n, const std::vector<int>& needed) {
    if (static_cast<int>(slot.size()) != n) {
      slot.assign(static_cast<size_t>(n), -1);
      unknowns.clear();
      inverse.resize(0, 0);
    }
    std::vector<int> missing;
    for (int j : needed)
      if (slot[static_cast<size_t>(j)] < 0) missing.push_back(j);
    // Forget unknowns no row needs any more once they outnumber the needed ones.
    if (static_cast<int>(unknowns.size()) + static_cast<int>(missing.size()) > 2 * static_cast<int>(needed.size()) + 32) {
      for (int j : unknowns) slot[static_cast<size_t>(j)] = -1;
      unknowns.clear();
      inverse.resize(0, 0);
      missing = needed;
    }
    if (missing.empty()) return;
    int lowest = n;  // of the unknowns cached already
    for (int j : unknowns) lowest = std::min(lowest, j);
    const Eigen::MatrixXcd x = solver.InverseColumns(missing, lowest);
    columns += static_cast<int64_t>(missing.size());
    const Eigen::Index old = static_cast<Eigen::Index>(unknowns.size());
    const Eigen::Index total = old + static_cast<Eigen::Index>(missing.size());
    Eigen::MatrixXcd grown(total, total);
    grown.topLeftCorner(old, old) = inverse;
    for (int j : missing) {
      slot[static_cast<size_t>(j)] = static_cast<int>(unknowns.size());
      unknowns.push_back(j);
    }
    // K is Hermitian: entry (i, j) of a new column j above min(j, lowest) is entry (j, i)
    // of the new column i, conjugated.
    for (Eigen::Index c = 0; c < static_cast<Eigen::Index>(missing.size()); ++c) {
      const int j = missing[static_cast<size_t>(c)];
      for (Eigen::Index i = 0; i < total; ++i) {
        const int at = unknowns[static_cast<size_t>(i)];
        grown(i, old + c) = at >= std::min(j, lowest) ? x(at, c) : std::conj(x(j, slot[static_cast<size_t>(at)] - old));
        grown(old + c, i) = std::conj(grown(i, old + c));
      }
    }
    inverse = std::move(grown);
  }
};

// The rows that touch one agent, and that agent's block of the Schur complement.
struct AgentRows {
  std::vector<int> rows;       // global rows, ascending
  RowLists terms;              // per local row: (local vertex, weight * direction)
  Eigen::MatrixXd s;           // local rows by local rows: Re(g^H K^-1 g)
  std::vector<double> base;    // per local row: its value without rows
  Eigen::VectorXcd y0;         // the step's unknowns without rows
  RowLists g;                  // per local row: (unknown, coefficient)
};

// Fills the agent's Schur block for one step: S = Re(G^H K^-1 G). A row's value is
// Re(sum conj(c) z) = Re(g^H y) + constant with g_j = c conj(a_j), so S only needs the
// entries of K^-1 between the unknowns the rows touch; those are kept in `cache` and
// only new unknowns cost a back-substitution. G and S depend on the rows' terms alone: when
// the agent's rows are those of the last solve (as re-sent rows whose linearisation did
// not change are), they are taken from `cache` as they are, and only the base values
// (which follow y0 and the map's constants) are worked out again.
template <typename Solver, typename MapFn>
void AgentBlock(const Solver& solver, int n, MapFn map, InverseBlock* cache, AgentRows* ar) {
  const int r = static_cast<int>(ar->rows.size());
  ar->base.assign(static_cast<size_t>(r), 0.0);
  const bool same = static_cast<int>(cache->slot.size()) == n && cache->terms == ar->terms;
  if (same) {
    ar->g = cache->g;
    ar->s = cache->s;
  } else {
    ar->g.Clear();
    ar->g.items.reserve(ar->terms.items.size() * 2);
  }
  std::vector<int> needed;
  std::vector<RowLists::Item> col;
  for (int k = 0; k < r; ++k) {
    auto add = [&](int j, Complex v) {
      for (auto& e : col)
        if (e.first == j) {
          e.second += v;
          return;
        }
      col.emplace_back(j, v);
    };
    col.clear();
    for (const auto& [i, c] : ar->terms.row(static_cast<size_t>(k))) {
      const Map m = map(i);
      if (!same) {
        add(m.j0, c * std::conj(m.a0));
        if (m.j1 >= 0) add(m.j1, c * std::conj(m.a1));
      }
      ar->base[static_cast<size_t>(k)] += std::real(std::conj(c) * m.k);
    }
    if (!same) {
      ar->g.items.insert(ar->g.items.end(), col.begin(), col.end());
      ar->g.CloseRow();
    }
    for (const auto& [j, gj] : ar->g.row(static_cast<size_t>(k))) {
      ar->base[static_cast<size_t>(k)] += std::real(std::conj(gj) * ar->y0[j]);
      if (!same) needed.push_back(j);
    }
  }
  if (same) return;
  std::sort(needed.begin(), needed.end());
  needed.erase(std::unique(needed.begin(), needed.end()), needed.end());
  cache->Ensure(solver, n, needed);
  ar->s.resize(r, r);
  for (int k = 0; k < r; ++k)
    for (int l = k; l < r; ++l) {
      Complex v = 0.0;
      for (const auto& [i, gi] : ar->g.row(static_cast<size_t>(k)))
        for (const auto& [j, gj] : ar->g.row(static_cast<size_t>(l))) v += std::conj(gi) * gj * cache->At(i, j);
      ar->s(k, l) = ar->s(l, k) = std::real(v);
    }
  cache->terms = ar->terms;
  cache->g = ar->g;
  cache->s = ar->s;
}

// The agent's unknowns under the row forces: y0 + K^-1 G lambda.
template <typename Solver>
Eigen::VectorXcd AgentResponse(const Solver& solver, const AgentRows& ar, const Eigen::VectorXd& forces) {
  Eigen::VectorXcd rhs = Eigen::VectorXcd::Zero(ar.y0.size());
  for (size_t k = 0; k < ar.rows.size(); ++k)
    for (const auto& [j, gj] : ar.g.row(k)) rhs[j] += gj * forces[ar.rows[k]];
  return ar.y0 + solver.Solve(rhs).col(0);
}

// Where a row sits in the agents' blocks.
struct RowSlot {
  int agent;  // index into the involved agents
  int local;  // index of the row in that agent's block
};

// The slots of every row, stored one row after another.
struct RowSlots {
  struct Span {
    const RowSlot *first, *last;
    const RowSlot* begin() const { return first; }
    const RowSlot* end() const { return last; }
  };
  std::vector<int> start;  // #R+1 offsets into items
  std::vector<RowSlot> items;

  Span row(int r) const {
    return {items.data() + start[static_cast<size_t>(r)], items.data() + start[static_cast<size_t>(r) + 1]};
  }
};

// Solves the mixed complementarity problem on the Schur complement,
//   (S + D) lambda = q              on equality rows,
//   lambda >= 0, (S + D) lambda - q >= 0, complementary   on "at least" rows,
// by projected Gauss-Seidel from `forces`, then meets the equality rows exactly for the
// unilateral forces found. Returns the sweeps used.
int SolveRows(const std::vector<AgentRows*>& blocks, const RowSlots& slots,
              const SeparationRows& in, const SeparationSettings& settings, Eigen::VectorXd& forces,
              bool* regularized, bool* converged, int64_t* updates) {
  const int nr = static_cast<int>(in.rhs.size());
  Eigen::VectorXd q = in.rhs;
  Eigen::VectorXd diag = in.softness;
  for (int r = 0; r < nr; ++r)
    for (const RowSlot& sl : slots.row(r)) {
      q[r] -= blocks[static_cast<size_t>(sl.agent)]->base[static_cast<size_t>(sl.local)];
      diag[r] += blocks[static_cast<size_t>(sl.agent)]->s(sl.local, sl.local);
    }
  auto unilateral = [&](int r) { return in.kind.size() && in.kind[r] != 0; };
  for (int r = 0; r < nr; ++r)
    if (unilateral(r)) forces[r] = std::max(forces[r], 0.0);
  // S lambda, kept up to date as forces change, as each agent's part u = S_a lambda_a (a
  // row's value is the sum of its agents' parts): a force change is then one contiguous
  // column update per agent.
  std::vector<Eigen::VectorXd> u(blocks.size());
  for (size_t b = 0; b < blocks.size(); ++b) {
    const AgentRows* ar = blocks[b];
    Eigen::VectorXd f(static_cast<Eigen::Index>(ar->rows.size()));
    for (size_t k = 0; k < ar->rows.size(); ++k) f[static_cast<Eigen::Index>(k)] = forces[ar->rows[k]];
    u[b] = ar->s * f;
  }
  auto value = [&](int r) {
    double sum = 0.0;
    for (const RowSlot& sl : slots.row(r)) sum += u[static_cast<size_t>(sl.agent)][sl.local];
    return sum;
  };
  *converged = false;
  int sweep = 0;
  bool any_unilateral = false;
  for (int r = 0; r < nr; ++r) any_unilateral = any_unilateral || unilateral(r);
  if (any_unilateral) {
    for (sweep = 1; sweep <= settings.max_sweeps; ++sweep) {
      double change = 0.0;
      for (int r = 0; r < nr; ++r) {
        if (!(diag[r] > 0.0)) continue;
        double f = forces[r] + settings.relaxation * (q[r] - value(r) - in.softness[r] * forces[r]) / diag[r];
        if (unilateral(r)) f = std::max(f, 0.0);
        const double delta = f - forces[r];
        // A change below the tolerance is not worth passing on to the other rows.
        if (std::abs(delta) * diag[r] <= settings.tolerance) continue;
        forces[r] = f;
        ++*updates;
        change = std::max(change, std::abs(delta) * diag[r]);
        for (const RowSlot& sl : slots.row(r))
          u[static_cast<size_t>(sl.agent)].noalias() += blocks[static_cast<size_t>(sl.agent)]->s.col(sl.local) * delta;
      }
      if (change <= settings.tolerance) {
        *converged = true;
        break;
      }
    }
    sweep = std::min(sweep, settings.max_sweeps);
  } else {
    *converged = true;
  }

  // Equality rows exactly: (S_EE + D_E) lambda_E = q_E - S_EU lambda_U.
  std::vector<int> eq_index(static_cast<size_t>(nr), -1);
  std::vector<int> eq_rows;
  for (int r = 0; r < nr; ++r)
    if (!unilateral(r)) {
      eq_index[static_cast<size_t>(r)] = static_cast<int>(eq_rows.size());
      eq_rows.push_back(r);
    }
  const int ne = static_cast<int>(eq_rows.size());
  if (ne == 0) return sweep;
  Eigen::VectorXd rhs(ne);
  std::vector<Eigen::Triplet<double>> trip;
  for (int e = 0; e < ne; ++e) {
    rhs[e] = q[eq_rows[static_cast<size_t>(e)]];
    trip.emplace_back(e, e, in.softness[eq_rows[static_cast<size_t>(e)]]);
  }
  for (const AgentRows* ar : blocks)
    for (size_t k = 0; k < ar->rows.size(); ++k) {
      const int ek = eq_index[static_cast<size_t>(ar->rows[k])];
      if (ek < 0) continue;
      for (size_t l = 0; l < ar->rows.size(); ++l) {
        const double skl = ar->s(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(l));
        const int el = eq_index[static_cast<size_t>(ar->rows[l])];
        if (el >= 0)
          trip.emplace_back(ek, el, skl);
        else
          rhs[ek] -= skl * forces[ar->rows[l]];
      }
    }
  Eigen::SparseMatrix<double> see(ne, ne);
  see.setFromTriplets(trip.begin(), trip.end());
  double largest = 0.0;
  for (int e = 0; e < ne; ++e) largest = std::max(largest, see.coeff(e, e));
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(see);
  const bool dependent = ldlt.info() != Eigen::Success ||
                         (ne && ldlt.vectorD().minCoeff() <= 1e-13 * std::max(largest, 1e-300));
  if (dependent) {
    // Hard rows that repeat or contradict each other: as nearly hard as arithmetic allows.
    *regularized = true;
    for (int e = 0; e < ne; ++e) see.coeffRef(e, e) += 1e-10 * std::max(largest, 1e-300);
    ldlt.compute(see);
    if (ldlt.info() != Eigen::Success) throw std::runtime_error("SeparationSolve: the equality rows could not be solved");
  }
  const Eigen::VectorXd fe = ldlt.solve(rhs);
  for (int e = 0; e < ne; ++e) forces[eq_rows[static_cast<size_t>(e)]] = fe[e];
  return sweep;
}

}  // namespace

struct SeparationCache {
  std::vector<InverseBlock> step1, step2;
};

void SeparationCacheDeleter::operator()(SeparationCache* cache) const { delete cache; }

std::unique_ptr<SeparationCache, SeparationCacheDeleter> SeparationNewCache() {
  return std::unique_ptr<SeparationCache, SeparationCacheDeleter>(new SeparationCache());
}

void SeparationSolve(const SeparationData& data, const SeparationRows& in, const SeparationSettings& settings,
                     SeparationCache& cache, SeparationResult& result) {
  result.seconds.setZero();
  double clock = Seconds();
  auto lap = [&](int phase) {
    const double now = Seconds();
    result.seconds[phase] += now - clock;
    clock = now;
  };
  if (cache.step1.size() != data.agents.size()) {
    cache.step1.assign(data.agents.size(), InverseBlock());
    cache.step2.assign(data.agents.size(), InverseBlock());
  }
  const Eigen::Index nr = in.rhs.size(), nt = in.term_row.size();
  const Eigen::Index nv = data.rest.rows();
  if (in.direction.rows() != nr || in.softness.size() != nr || in.term_vertex.size() != nt ||
      in.term_weight.size() != nt || (in.kind.size() && in.kind.size() != nr) ||
      (in.initial_forces.size() && in.initial_forces.size() != nr) ||
      (in.initial_shape_forces.size() && in.initial_shape_forces.size() != nr))
    throw std::invalid_argument("SeparationSolve: direction, rhs, softness, kind and initial forces need one entry "
                                "per row; term_row, term_vertex and term_weight one per term");
  if (!in.direction.allFinite() || !in.rhs.allFinite() || !in.term_weight.allFinite() || !in.softness.allFinite() ||
      !in.initial_forces.allFinite() || !in.initial_shape_forces.allFinite())
    throw std::invalid_argument("SeparationSolve: rows must be finite");
  if (nr && in.softness.minCoeff() < 0.0) throw std::invalid_argument("SeparationSolve: softness must not be negative");
  if (!(settings.tolerance > 0.0) || settings.max_sweeps < 1)
    throw std::invalid_argument("SeparationSolve: tolerance must be positive and max_sweeps at least 1");
  std::vector<char> has_term(static_cast<size_t>(nr), 0);
  for (Eigen::Index t = 0; t < nt; ++t) {
    if (in.term_row[t] < 0 || in.term_row[t] >= nr) throw std::invalid_argument("SeparationSolve: term row out of range");
    if (in.term_vertex[t] < 0 || in.term_vertex[t] >= nv)
      throw std::invalid_argument("SeparationSolve: term vertex out of range");
    if (in.term_weight[t] != 0.0) has_term[static_cast<size_t>(in.term_row[t])] = 1;
  }
  for (Eigen::Index r = 0; r < nr; ++r)
    if (!has_term[static_cast<size_t>(r)])
      throw std::invalid_argument("SeparationSolve: row " + std::to_string(r) + " has no term");

  // Terms by agent (in term order within a row); rows numbered locally per agent.
  const size_t na = data.agents.size();
  std::vector<AgentRows> agent_rows(na);
  {
    std::vector<int> count(na, 0), agent_of_term(static_cast<size_t>(nt), -1);
    for (Eigen::Index t = 0; t < nt; ++t) {
      if (in.term_weight[t] == 0.0) continue;  // an interpolation weight of zero touches nothing
      agent_of_term[static_cast<size_t>(t)] = data.agent_of[static_cast<size_t>(in.term_vertex[t])];
      ++count[static_cast<size_t>(agent_of_term[static_cast<size_t>(t)])];
    }
    std::vector<std::vector<std::pair<int, Eigen::Index>>> by_agent(na);  // (row, term)
    for (size_t a = 0; a < na; ++a) by_agent[a].reserve(static_cast<size_t>(count[a]));
    for (Eigen::Index t = 0; t < nt; ++t)
      if (agent_of_term[static_cast<size_t>(t)] >= 0)
        by_agent[static_cast<size_t>(agent_of_term[static_cast<size_t>(t)])].emplace_back(in.term_row[t], t);
    for (size_t a = 0; a < na; ++a) {
      auto& list = by_agent[a];
      if (list.empty()) continue;
      if (!std::is_sorted(list.begin(), list.end())) std::stable_sort(list.begin(), list.end());
      AgentRows& ar = agent_rows[a];
      ar.terms.items.reserve(list.size());
      for (size_t i = 0; i < list.size(); ++i) {
        const auto [row, t] = list[i];
        if (i > 0 && row != list[i - 1].first) ar.terms.CloseRow();
        if (i == 0 || row != list[i - 1].first) ar.rows.push_back(row);
        const Complex dir(in.direction(row, 0), in.direction(row, 1));
        ar.terms.items.emplace_back(in.term_vertex[t] - data.agents[a].first, in.term_weight[t] * dir);
      }
      ar.terms.CloseRow();
    }
  }
  std::vector<int> involved;
  std::vector<AgentRows*> blocks;
  for (size_t a = 0; a < na; ++a)
    if (!agent_rows[a].rows.empty()) {
      involved.push_back(static_cast<int>(a));
      blocks.push_back(&agent_rows[a]);
    }
  const int nq = static_cast<int>(involved.size());
  RowSlots slots;
  slots.start.assign(static_cast<size_t>(nr) + 1, 0);
  for (int q = 0; q < nq; ++q)
    for (int row : blocks[static_cast<size_t>(q)]->rows) ++slots.start[static_cast<size_t>(row) + 1];
  for (int r = 0; r < nr; ++r) slots.start[static_cast<size_t>(r) + 1] += slots.start[static_cast<size_t>(r)];
  slots.items.resize(static_cast<size_t>(slots.start[static_cast<size_t>(nr)]));
  {
    std::vector<int> fill(slots.start.begin(), slots.start.end() - 1);
    for (int q = 0; q < nq; ++q)
      for (size_t k = 0; k < blocks[static_cast<size_t>(q)]->rows.size(); ++k)
        slots.items[static_cast<size_t>(fill[static_cast<size_t>(blocks[static_cast<size_t>(q)]->rows[k])]++)] = {q, static_cast<int>(k)};
  }

  result.positions = data.rest;
  result.shape = data.rest;
  result.rigid_angles = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(data.rigid.size()));
  result.moved_agents = nq;
  result.regularized = false;
  result.converged = true;
  result.sweeps = 0;
  result.updates = 0;
  int64_t columns_before = 0;
  for (size_t a = 0; a < cache.step1.size(); ++a) columns_before += cache.step1[a].columns + cache.step2[a].columns;
  result.shape_forces = in.initial_shape_forces.size() ? in.initial_shape_forces
                        : in.initial_forces.size()     ? in.initial_forces
                                                       : Eigen::VectorXd::Zero(nr);
  result.forces = result.shape_forces;
  result.residuals = Eigen::VectorXd::Zero(nr);
  if (nr == 0) return;
  int64_t work = 0;
  for (int a : involved) work += data.agents[static_cast<size_t>(a)].count;
  const int threads = work < 20000 ? 1 : data.threads;

  // Step 1.
  lap(3);
  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(involved[static_cast<size_t>(q)])];
    AgentRows* ar = blocks[static_cast<size_t>(q)];
    ar->y0 = ag.y1_rest;
    AgentBlock(ag.step1, ag.n1, [&](int i) { return ag.Map1(i); },
               &cache.step1[static_cast<size_t>(involved[static_cast<size_t>(q)])], ar);
  });
  bool converged = true;
  lap(0);
  result.sweeps = SolveRows(blocks, slots, in, settings, result.shape_forces, &result.regularized, &converged,
                            &result.updates);
  lap(1);
  if (in.initial_shape_forces.size() && in.initial_forces.size()) result.forces = in.initial_forces;
  else result.forces = result.shape_forces;
  result.converged = converged;

  // Step 1's result turns each range and each step; step 2 restores the rest lengths.
  std::vector<std::vector<Complex>> turns(static_cast<size_t>(nq));
  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(involved[static_cast<size_t>(q)])];
    AgentRows* ar = blocks[static_cast<size_t>(q)];
    const Eigen::VectorXcd y1 = AgentResponse(ag.step1, *ar, result.shape_forces);
    std::vector<Complex> z1(static_cast<size_t>(ag.count));
    for (int i = 0; i < ag.count; ++i) {
      const Map m = ag.Map1(i);
      z1[static_cast<size_t>(i)] = m.a0 * y1[m.j0] + (m.j1 >= 0 ? m.a1 * y1[m.j1] : Complex(0.0)) + m.k;
      result.shape(ag.first + i, 0) = z1[static_cast<size_t>(i)].real();
      result.shape(ag.first + i, 1) = z1[static_cast<size_t>(i)].imag();
    }
    auto& turn = turns[static_cast<size_t>(q)];
    turn.assign(ag.ranges.size(), 1.0);
    for (size_t k = 0; k < ag.ranges.size(); ++k)
      if (ag.ranges[k].m1 >= 0 && std::abs(y1[ag.ranges[k].m1]) > 0.0)
        turn[k] = y1[ag.ranges[k].m1] / std::abs(y1[ag.ranges[k].m1]);
    std::vector<Complex> edges(static_cast<size_t>(std::max(ag.count - 1, 0)));
    for (int i = 0; i + 1 < ag.count; ++i) {
      const Complex rest_edge = C(data.rest, ag.first + i + 1) - C(data.rest, ag.first + i);
      const Complex e = z1[static_cast<size_t>(i + 1)] - z1[static_cast<size_t>(i)];
      edges[static_cast<size_t>(i)] = std::abs(e) > 0.0 ? e / std::abs(e) * std::abs(rest_edge) : rest_edge;
    }
    ar->y0 = ag.step2.Solve(data.Step2Rhs(ag, edges, turn)).col(0);
    AgentBlock(ag.step2, ag.n2, [&](int i) { return ag.Map2(i, turn); },
               &cache.step2[static_cast<size_t>(involved[static_cast<size_t>(q)])], ar);
  });
  lap(0);
  result.sweeps += SolveRows(blocks, slots, in, settings, result.forces, &result.regularized, &converged,
                             &result.updates);
  lap(1);
  result.converged = result.converged && converged;

  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(involved[static_cast<size_t>(q)])];
    const Eigen::VectorXcd y2 = AgentResponse(ag.step2, *blocks[static_cast<size_t>(q)], result.forces);
    const auto& turn = turns[static_cast<size_t>(q)];
    for (int i = 0; i < ag.count; ++i) {
      const Map m = ag.Map2(i, turn);
      const Complex z = m.a0 * y2[m.j0] + m.k;
      result.positions(ag.first + i, 0) = z.real();
      result.positions(ag.first + i, 1) = z.imag();
    }
    for (size_t k = 0; k < ag.ranges.size(); ++k) result.rigid_angles[ag.global_range[k]] = std::arg(turn[k]);
  });
  for (Eigen::Index t = 0; t < nt; ++t) {
    const int r = in.term_row[t], v = in.term_vertex[t];
    result.residuals[r] += in.term_weight[t] * (in.direction(r, 0) * result.positions(v, 0) +
                                                in.direction(r, 1) * result.positions(v, 1));
  }
  result.residuals -= in.rhs;
  result.inverse_columns = -columns_before;
  for (size_t a = 0; a < cache.step1.size(); ++a) result.inverse_columns += cache.step1[a].columns + cache.step2[a].columns;
  lap(2);
}

void SeparationSolve(const SeparationData& data, const SeparationRows& in, const SeparationSettings& settings,
                     SeparationResult& result) {
  SeparationCache cache;
  SeparationSolve(data, in, settings, cache, result);
}

}  // namespace mocapedit
