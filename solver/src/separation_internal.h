// Internals of the separation solve (separation.h) shared by its source files: each
// agent's factored steps, the maps from its vertices to its unknowns, and the precomputed
// state behind SeparationData. The energy's terms come from energy/two_step_energy.h, as
// the path editor's do; here they are accumulated per agent through the maps.
//
//   separation_precompute.cpp  validation, each agent's unknowns and factored steps
//   separation.cpp             rows by agent, Schur blocks, the row forces, both steps
#pragma once

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "energy/two_step_energy.h"
#include "mocapedit/errors.h"
#include "mocapedit/separation.h"
#include "mocapedit/skyline_ldlt.h"
#include "mocapedit/two_threads.h"

namespace mocapedit::detail {

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
  // undone: those of other columns follow from symmetry). Scalar entries: a real K has a
  // real inverse, worked out in real arithmetic.
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> InverseColumns(const std::vector<int>& columns,
                                                                       int lowest) const {
    using Out = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
    const Eigen::Index m = static_cast<Eigen::Index>(columns.size());
    Out x = Out::Zero(n_, m);
    for (Eigen::Index c = 0; c < m; ++c) x(columns[static_cast<size_t>(c)], c) = Scalar(1.0);
    if (!banded_) {
      if constexpr (std::is_same_v<Scalar, double>) return sparse_.solve(x);
      else return SparseSolve(x);
    }
    // Four columns at a time (side by side, the same values as one by one: SolveFromBatch);
    // `columns` come sorted, so the four start close together. The forward passes start at
    // the unit entries.
    constexpr int kBatch = 4;
    Eigen::Index c = 0;
    if (m >= kBatch) {
      std::vector<Scalar> batch(static_cast<size_t>(n_) * kBatch);
      for (; c + kBatch <= m; c += kBatch) {
        std::fill(batch.begin(), batch.end(), Scalar(0.0));
        int firsts[kBatch], last = n_;
        for (int b = 0; b < kBatch; ++b) {
          firsts[b] = columns[static_cast<size_t>(c + b)];
          batch[static_cast<size_t>(firsts[b]) * kBatch + b] = Scalar(1.0);
          last = std::min(last, std::min(firsts[b], lowest));
        }
        band_.template SolveFromBatch<Scalar, kBatch>(batch.data(), firsts, last);
        for (int b = 0; b < kBatch; ++b)
          for (int i = std::min(firsts[b], lowest); i < n_; ++i)
            x(i, c + b) = batch[static_cast<size_t>(i) * kBatch + b];
      }
    }
    for (; c < m; ++c) {
      const int j = columns[static_cast<size_t>(c)];
      band_.SolveFrom(x.col(c).data(), j, std::min(j, lowest));
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
inline Complex C(const Trajectory2& p, Eigen::Index i) { return {p(i, 0), p(i, 1)}; }

// A rigid range of an agent: one similarity z -> t1 + m1 (z - centroid) in step 1 (a
// translation alone when it is too small to carry a rotation), one translation t2 of its
// rest shape turned by step 1's rotation in step 2 (energy/two_step_energy.h).
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
  double anchor = 0;              // its frames' anchor weight
  double shape_weight = 1.0;      // its step-1 shape terms' weight (SeparationProblem::rates)
  double edge_weight = 1.0;       // its step-2 edges' weight
  std::vector<double> anchor_frames;  // per local vertex (SeparationProblem::anchor_frames); empty: 1

  double Anchor(int i) const { return anchor_frames.empty() ? anchor : anchor * anchor_frames[static_cast<size_t>(i)]; }
  std::vector<int> cuts_before;   // per local vertex: cuts up to it (SeparationProblem::cut_into); empty: none

  // Whether a shape term over local vertices lo .. hi spans a cut.
  bool AcrossCut(int lo, int hi) const {
    return !cuts_before.empty() && cuts_before[static_cast<size_t>(hi)] != cuts_before[static_cast<size_t>(lo)];
  }
  StepSolver<Complex> step1;
  StepSolver<double> step2;
  Eigen::VectorXcd y1_rest;

  int RangeOf(int i) const { return range[static_cast<size_t>(i)]; }

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

// Accumulates sum weight |sum_v c_v z_v - beta|^2 over the energy's terms into K
// (triplets) and b, each vertex z_v replaced by its map to the unknowns.
struct Normal {
  std::vector<Eigen::Triplet<Complex>> triplets;
  Eigen::VectorXcd b;
  std::vector<std::pair<int, Complex>> row;

  bool matrix = true;  // false: the right-hand side alone

  explicit Normal(int n, bool with_matrix = true) : b(Eigen::VectorXcd::Zero(n)), matrix(with_matrix) {}

  // A term's row (energy/two_step_energy.h) of local vertices; map(v) gives v's Map.
  template <size_t N, typename MapFn>
  void Add(const TermRow<double, N>& term, const MapFn& map, Complex beta, double weight) {
    row.clear();
    for (const auto& [v, c] : term) {
      const Map m = map(v);
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

inline double Seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

template <typename Fn>
void ParallelFor(int count, int threads, Fn fn) {
  threads = std::max(1, std::min(threads, count));
  OnThreads(threads, [&](int t) {
    for (int i = t; i < count; i += threads) fn(i);
  });
}

inline int ThreadCount(int requested, int64_t work) {
  const int threads = requested > 0 ? requested : DefaultThreads();
  return work < 20000 ? 1 : threads;
}

// Everything SeparationPrecompute builds (SeparationData holds it).
struct SeparationState {
  Trajectory2 rest;
  Eigen::VectorXi starts;
  std::vector<FrameRange> rigid;
  double still_extent = 0;
  int threads = 1;
  std::vector<Agent> agents;
  std::vector<int> agent_of;  // global vertex -> agent

  // Step 2's terms of one agent into `normal`: each step j -> j+1 between frames (not
  // inside one range) at its target edges[j] (0 when `edges` is empty: for the matrix
  // alone), and the anchors at the rest positions; each range's shape turned by
  // turn[range].
  void Step2Terms(const Agent& ag, const std::vector<Complex>& edges, const std::vector<Complex>& turn,
                  Normal& normal) const {
    const auto map = [&](int i) { return ag.Map2(i, turn); };
    const auto range_of = [&](int i) { return ag.RangeOf(i); };
    ChainEdges(ag.count, [&](int j, int k) {
      if (!InOneRange(range_of, {j, k}) && !ag.AcrossCut(j, k))
        normal.Add(Row(EdgeTerm{j, k}), map, edges.empty() ? 0.0 : edges[static_cast<size_t>(j)], ag.edge_weight);
    });
    for (int i = 0; i < ag.count; ++i)
      normal.Add(AnchorRow(i), map, C(rest, ag.first + i), ag.Anchor(i));
  }

  // Step 2's targets from step 1's result (unknowns y1, positions z1) of one agent: each
  // step's edge (EdgeTarget) and each range's turn, the rotation of its similarity. A
  // range too small to carry a rotation keeps its source facing here, where the path
  // editor turns it with the step-1 edges entering and leaving it: avoidance moves a
  // standing agent within a detour whose turns in and out cancel, and the edges next to a
  // stand (a walker slowing down, tens of micrometres) turn by noise in step 1; on stages
  // of agents that stop in crossing flows, turning them so spun their bodies.
  void Step2Targets(const Agent& ag, const Eigen::VectorXcd& y1, const std::vector<Complex>& z1,
                    std::vector<Complex>& edges, std::vector<Complex>& turn) const {
    edges.resize(static_cast<size_t>(std::max(ag.count - 1, 0)));
    ChainEdges(ag.count, [&](int j, int k) {
      const Complex rest_edge = C(rest, ag.first + k) - C(rest, ag.first + j);
      edges[static_cast<size_t>(j)] =
          EdgeTarget(z1[static_cast<size_t>(k)] - z1[static_cast<size_t>(j)], std::sqrt(std::norm(rest_edge)), rest_edge);
    });
    turn.assign(ag.ranges.size(), 1.0);
    for (size_t r = 0; r < ag.ranges.size(); ++r)
      if (ag.ranges[r].m1 >= 0) turn[r] = RangeTurn(y1[ag.ranges[r].m1]);
  }

  // Step-2 right-hand side of one agent for given edge vectors and range turns.
  Eigen::VectorXcd Step2Rhs(const Agent& ag, const std::vector<Complex>& edges,
                            const std::vector<Complex>& turn) const {
    Normal normal(ag.n2, false);
    Step2Terms(ag, edges, turn, normal);
    return normal.b;
  }
};

}  // namespace mocapedit::detail
