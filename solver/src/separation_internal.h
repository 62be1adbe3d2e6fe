// Internals of the separation solve (separation.h) shared by its source files: each
// agent's factored steps, the maps from its vertices to its unknowns, and the precomputed
// state behind SeparationData.
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
inline Complex C(const Trajectory2& p, Eigen::Index i) { return {p(i, 0), p(i, 1)}; }

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
  int threads = requested > 0 ? requested : static_cast<int>(std::min(2u, std::max(1u, std::thread::hardware_concurrency())));
  return work < 20000 ? 1 : threads;
}

// Everything SeparationPrecompute builds (SeparationData holds it).
struct SeparationState {
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

}  // namespace mocapedit::detail
