// Internals of path editing (path_edit.h) shared by its source files: the rows before
// elimination, the elimination of hard constraints, each step's factored system, and the
// precomputed state behind PathEditData.
//
//   path_edit_precompute.cpp  validation, rigid ranges' masters, rows, PathEditPrecompute
//   path_edit_eliminate.cpp   hard links, rigid ranges and hard handles eliminated
//   path_edit_assemble.cpp    eliminated rows and their normal matrix
//   path_edit_factor.cpp      fill-reducing orders and the choice of factorization
//   path_edit_refine.cpp      one step's solve by refinement (normal equations or QR)
//   path_edit_solve.cpp       PathEditSolve: rigid shortcut, step 1, rotations, step 2
#pragma once

#include <Eigen/SPQRSupport>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "mocapedit/blas_lock.h"
#include "mocapedit/errors.h"
#include "mocapedit/path_edit.h"
#include "energy/two_step_energy.h"
#include "mocapedit/skyline_ldlt.h"
#include "supernodal_cholesky.h"

namespace mocapedit::detail {

using Cplx = std::complex<double>;
using CVec = Eigen::VectorXcd;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Refinement stops when the remaining error (the last correction times the estimated
// contraction cond * eps) is below this fraction of the problem's scale.
constexpr double kRefineTolerance = 1e-12;
constexpr int kMaxRefinements = 10;
// cond * eps above which refinement of the normal equations is not trusted: use QR.
constexpr double kLdltTrust = 0.05;
constexpr double kEps = 1.1102230246251565e-16;
// Hard constraints that disagree by more than this (plus kConsistencyRelative * scale) are
// reported as contradictions.
constexpr double kConsistencyAbsolute = 1e-7;
constexpr double kConsistencyRelative = 1e-12;
// Rigid-motion shortcut: constraints met by one rigid motion to this relative tolerance.
constexpr double kRigidTolerance = 1e-11;
// Normal matrices whose envelope LDLT (natural column order) costs at most this many
// multiply-adds per column are factored that way (single paths, chains of agents tied end
// to start); others in AMD order by a simplicial LDLT, or, when the AMD factor has dense
// fronts (group meshes), by CHOLMOD's supernodal Cholesky, which factors them with BLAS.
constexpr int64_t kSkylineCostPerColumn = 64;
constexpr int64_t kSkylineProfilePerColumn = 64;
constexpr int kSupernodalColumns = 2000;
// Parts of at most this many unknowns are not dissected further (nested_dissection.h):
// CAMD orders them. Over groups of 100 to 400 agents, leaves of 1,000 to 2,300 unknowns
// gave step 1 about the same CHOLMOD flop counts; 1,500 was never the worst.
constexpr int kDissectionLeaf = 1500;
// Problems with at least this many vertices build their two steps at once, order step 1
// two ways at once, and factor the two steps at once (when the BLAS may be called from two
// threads): on a group mesh (bench/bench_path.py) that beats the steps in turn and one
// thread per step.
constexpr int kParallelStepsVertices = 2000;
// CHOLMOD's flop count per factor entry above which its fronts are dense enough for the
// supernodal factorization (BLAS on dense blocks) to beat the simplicial one; CHOLMOD's own
// default. Both steps of a group mesh lie well above it, and there the supernodal
// factorization beats CHOLMOD's simplicial one and Eigen's AMD LDLT.
constexpr double kSupernodalFlopsPerEntry = 40;
// LDLT pivots below this fraction of the largest mean a singular system.
constexpr double kSingularPivot = 1e-13;

inline Cplx C(const Eigen::Ref<const Trajectory2>& m, Eigen::Index r) { return {m(r, 0), m(r, 1)}; }
inline double Conj(double x) { return x; }
inline Cplx Conj(const Cplx& x) { return std::conj(x); }

// ---------------------------------------------------------------------------------------
// Rows before elimination: sum_v coeff * x_v - target, CSR over vertices.

enum class TargetKind : unsigned char { kZero, kHandle, kLink, kEdge };

// Coefficients are kept in extended precision, as a double and its rounding error
// (coeff + coeff_low is the extended value exactly): the refinement residuals use them, so
// the problem solved is the one defined by the exact rest positions, not by their rounding.
struct Rows {
  std::vector<int> ptr{0};
  std::vector<int> vertex;
  std::vector<Cplx> coeff, coeff_low;
  std::vector<TargetKind> target;
  std::vector<int> target_index;  // handle, link or edge index
  std::vector<long double> sqrt_weight;

  int size() const { return rows_; }
  // Room for at most n rows of `entries` entries in all; Finish() trims to what was added.
  void Reserve(Eigen::Index n, Eigen::Index entries) {
    Resize(static_cast<size_t>(n), static_cast<size_t>(entries));
    ptr[0] = rows_ = entries_ = 0;
  }
  void Finish() { Resize(static_cast<size_t>(rows_), static_cast<size_t>(entries_)); }
  LCplx Extended(int p) const { return LCplx(coeff[p]) + LCplx(coeff_low[p]); }
  // A row of the energy (energy/two_step_energy.h) or any list of (vertex, coefficient).
  template <typename Entries>
  void Add(const Entries& entries, TargetKind kind, int index, double weight) {
    const long double s = weight == 1.0 ? 1.0L : std::sqrt(static_cast<long double>(weight));
    for (const auto& e : entries) Entry(e.first, weight == 1.0 ? LCplx(e.second) : LCplx(e.second) * s);
    Close(kind, index, s);
  }
  void Add(std::initializer_list<std::pair<int, LCplx>> entries, TargetKind kind, int index, double weight) {
    Add<std::initializer_list<std::pair<int, LCplx>>>(entries, kind, index, weight);
  }
  // A row of unit weight whose coefficients are exact in double precision.
  void AddExact(std::initializer_list<std::pair<int, double>> entries, TargetKind kind, int index) {
    for (const auto& e : entries) {
      vertex[entries_] = e.first;
      coeff[entries_] = e.second;
      coeff_low[entries_++] = 0.0;
    }
    Close(kind, index, 1.0L);
  }
  // A shape term of unit weight (its row, Row(term), without the weighting).
  void AddShape(const ShapeTerm<long double>& term, int index) {
    for (const auto& e : Row(term)) Entry(e.first, e.second);
    Close(TargetKind::kZero, index, 1.0L);
  }

 private:
  void Resize(size_t n, size_t entries) {
    ptr.resize(n + 1);
    target.resize(n);
    target_index.resize(n);
    sqrt_weight.resize(n);
    vertex.resize(entries);
    coeff.resize(entries);
    coeff_low.resize(entries);
  }
  void Entry(int v, const LCplx& c) {
    const Cplx hi(c);
    vertex[entries_] = v;
    coeff[entries_] = hi;
    coeff_low[entries_++] = Cplx(c - LCplx(hi));
  }
  void Close(TargetKind kind, int index, long double s) {
    ptr[rows_ + 1] = entries_;
    target[rows_] = kind;
    target_index[rows_] = index;
    sqrt_weight[rows_++] = s;
  }
  int rows_ = 0, entries_ = 0;
};

// ---------------------------------------------------------------------------------------
// Elimination of hard constraints: vertices tied by hard links (and rigid ranges) share
// one unknown up to known offsets; a hard handle fixes that unknown.

enum class TieKind : unsigned char { kLink, kRest, kRotated };

struct Tie {
  int a, b;            // x_a - x_b = offset
  TieKind kind;
  int index;           // link index (kLink) or rigid range (kRest, kRotated)
  LCplx rest;          // z_a - z_b for rigid ties
};

struct Elimination {
  int vertices = 0;
  std::vector<int> root;         // per vertex; -1 for similarity dependents
  std::vector<int> order;        // members in tree order, each root before its subtree
  std::vector<int> parent;       // per member, -1 for a root
  std::vector<int> parent_tie;   // tie to the parent
  std::vector<int> depth;
  std::vector<Tie> ties;
  std::vector<int> col;          // per root: column, or -1 when fixed
  std::vector<int> fix_handle;   // per root: hard handle fixing it, or -1
  std::vector<int> extra_handles;
  std::vector<int> extra_ties;
  // Similarity dependents (step 1 inside rotating ranges): x = (1-g) x_m1 + g x_m2.
  std::vector<int> dep_vertex, dep_m1, dep_m2;
  std::vector<LCplx> dep_gamma;
  int columns = 0;
  // Per vertex expression x_v = sum e_coeff * u[e_col] + beta_v, at most two terms; empty
  // for plain vertices (below), which are u[plain_col] alone.
  std::vector<int> e_ptr;
  std::vector<int> e_col;
  std::vector<LCplx> e_coeff;
  // Per vertex: its column when it is simply that unknown (x_v = u[col], no offset: a free
  // vertex tied to nothing), else -1.
  std::vector<int> plain_col;
};

// ---------------------------------------------------------------------------------------
// A factored normal matrix with its rectangular rows for refinement.

// A simplicial LDLT that also tells the size of its factor after the symbolic analysis.
template <typename Sparse, typename Ordering>
struct Ldlt : Eigen::SimplicialLDLT<Sparse, Eigen::Lower, Ordering> {
  Eigen::Index FactorNonZeros() const { return this->m_nonZerosPerCol.sum(); }
};


template <typename Scalar>
struct StepSystem {
  using Sparse = Eigen::SparseMatrix<Scalar, Eigen::ColMajor, int>;
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  int rows = 0, cols = 0;
  // Rectangular system after elimination, CSR: A u - c. a_val + a_low is the coefficient
  // in extended precision (exactly: a_low is its rounding error); the normal matrix uses
  // a_val, residuals use the extended values.
  std::vector<int> a_ptr{0};
  std::vector<int> a_col;
  std::vector<Scalar> a_val, a_low;
  // Rows whose constant part depends on beta (they touch tied or fixed vertices).
  std::vector<int> beta_rows;
  Sparse normal;  // lower triangle of A^H A (not built when use_skyline)
  SkylineLdlt<Scalar> skyline;
  bool use_skyline = false;
  double gershgorin = 0;  // bound on the largest eigenvalue of A^H A
  Ldlt<Sparse, Eigen::AMDOrdering<int>> amd;
  bool use_qr = false;
  std::unique_ptr<SupernodalCholesky<Scalar>> supernodal;
  bool dissected = false;  // supernodal factor in a nested-dissection order
  std::string solver = "none";
  double condition = 0;  // estimate of cond(A^H A)
  // Residuals need extended precision only when cond * eps is not negligible.
  bool extended = true;
  mutable std::once_flag qr_once;
  mutable std::unique_ptr<Eigen::SPQR<Sparse>> qr;

  // Solves (A^H A) x = r in place with the LDLT factor, for `k` right-hand sides stored
  // interleaved (x[i * k + c]).
  template <typename T>
  void SolveInterleaved(T* x, int k) const {
    if (supernodal) {
      static_assert(std::is_same<T, Scalar>::value, "a supernodal factor solves in its own scalar type");
      BlasLock lock;
      supernodal->Solve(x, k);
      return;
    }
    if (use_skyline) {
      skyline.Solve(x, k);
      return;
    }
    const auto& l = amd.matrixL().nestedExpression();
    const auto& dg = amd.vectorD();
    const int n = cols;
    std::vector<T> tmp;
    T* y = x;
    {  // y = P x
      tmp.resize(static_cast<size_t>(n) * k);
      const auto& perm = amd.permutationP().indices();
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < k; ++c) tmp[static_cast<size_t>(perm[i]) * k + c] = x[static_cast<size_t>(i) * k + c];
      y = tmp.data();
    }
    const int* outer = l.outerIndexPtr();
    const int* inner = l.innerIndexPtr();
    const Scalar* val = l.valuePtr();
    for (int j = 0; j < n; ++j)  // L y = y (unit lower, column-major)
      for (int p = outer[j]; p < outer[j + 1]; ++p)
        for (int c = 0; c < k; ++c) y[static_cast<size_t>(inner[p]) * k + c] -= val[p] * y[static_cast<size_t>(j) * k + c];
    for (int j = 0; j < n; ++j)
      for (int c = 0; c < k; ++c) y[static_cast<size_t>(j) * k + c] /= dg[j];
    for (int j = n - 1; j >= 0; --j)  // L^H y = y
      for (int p = outer[j]; p < outer[j + 1]; ++p)
        for (int c = 0; c < k; ++c) y[static_cast<size_t>(j) * k + c] -= Conj(val[p]) * y[static_cast<size_t>(inner[p]) * k + c];
    {  // x = P^-1 y
      const auto& perm = amd.permutationP().indices();
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < k; ++c) x[static_cast<size_t>(i) * k + c] = y[static_cast<size_t>(perm[i]) * k + c];
    }
  }
  void SolveNormalInPlace(Vector& r) const { SolveInterleaved(r.data(), 1); }
  const Eigen::SPQR<Sparse>& QR() const {
    std::call_once(qr_once, [this] {
      Sparse a(rows, cols);
      std::vector<Eigen::Triplet<Scalar>> t;
      t.reserve(a_val.size());
      for (int r = 0; r < rows; ++r)
        for (int p = a_ptr[r]; p < a_ptr[r + 1]; ++p) t.emplace_back(r, a_col[p], a_val[p]);
      a.setFromTriplets(t.begin(), t.end());
      a.makeCompressed();
      qr = std::make_unique<Eigen::SPQR<Sparse>>();
      BlasLock lock;
      qr->compute(a);
      if (qr->info() != Eigen::Success) throw NumericalError("PathEdit", "sparse QR failed");
    });
    return *qr;
  }
};

// Everything PathEditPrecompute builds: the validated inputs, both steps' rows, their
// elimination and factored systems (PathEditData holds it).
struct PathEditState {
  int vertices = 0;
  Trajectory2 rest;
  double scale = 1;  // largest rest coordinate, at least 1
  std::vector<Cplx> z;
  LCplx zl(int v) const { return LCplx(z[v]); }  // exact
  // Inputs kept for the solve.
  Eigen::VectorXi handles;
  Eigen::VectorXd handle_weights;
  IndexPairs links;
  Eigen::VectorXd link_weights;
  IndexPairs edges;
  std::vector<double> edge_length;  // #E rest length of each edge
  std::vector<RigidRange> rigid;
  std::vector<int> rigid_of;  // per vertex: rigid range or -1
  // Rotating ranges: masters in step 1 and whether the range takes its rotation from the
  // edges around it (too small to carry one).
  std::vector<int> master1, master2;
  std::vector<char> degenerate;
  std::vector<std::vector<int>> boundary_edges;  // per range: edges with one end inside
  bool has_translate = false;
  double rigid_min_extent = 0;
  std::vector<double> times;  // per vertex, or empty (PathEditProblem::vertex_times)

  Rows rows1, rows2;
  Elimination elim1, elim2;
  StepSystem<Cplx> step1;
  StepSystem<double> step2;
  // Interactive mode: step 1 is affine in the handle positions and link offsets, so
  // x1 = base + sum_h handle_response[h] * p_h + sum_l link_response[l] * o_l (complex).
  bool responses = false;
  std::vector<Cplx> response_base;
  std::vector<std::vector<Cplx>> handle_response, link_response;
  StepInfo response_info;
};

// ---------------------------------------------------------------------------------------
// Hard constraints: the constant part of every vertex and its consistency.

// The tie path between two members of one tree, as constraint references.
inline void TiePath(const Elimination& e, int a, int b, std::vector<ConstraintRef>& out) {
  auto add = [&](int t) {
    const Tie& tie = e.ties[t];
    out.push_back({tie.kind == TieKind::kLink ? ConstraintRef::kLink : ConstraintRef::kRigid, tie.index});
  };
  while (a != b) {
    if (e.depth[a] >= e.depth[b]) {
      add(e.parent_tie[a]);
      a = e.parent[a];
    } else {
      add(e.parent_tie[b]);
      b = e.parent[b];
    }
  }
}

inline void Deduplicate(std::vector<ConstraintRef>& refs) {
  std::vector<ConstraintRef> out;
  for (const auto& r : refs)
    if (std::none_of(out.begin(), out.end(), [&](const auto& o) { return o.kind == r.kind && o.index == r.index; }))
      out.push_back(r);
  refs.swap(out);
}

inline std::string Describe(const std::vector<ConstraintRef>& refs) {
  std::ostringstream s;
  for (size_t i = 0; i < refs.size(); ++i) {
    static const char* names[] = {"handle", "link", "rigid range"};
    s << (i ? ", " : "") << names[refs[i].kind] << " " << refs[i].index;
  }
  return s.str();
}

// beta: the constant part of every vertex (offsets from its class root, plus the fixed
// value of a fixed class). `tie_offset(t)` gives the offset of tie t.
template <typename T, typename TieOffset>
void ComputeBeta(const PathEditState& d, const Elimination& e, const Eigen::Ref<const Trajectory2>& handle_positions,
                 TieOffset tie_offset, std::vector<T>& beta) {
  const int n = e.vertices;
  beta.assign(n, T(0));
  for (int v : e.order) {
    const int p = e.parent[v];
    if (p < 0) continue;
    const Tie& t = e.ties[e.parent_tie[v]];
    const T o = T(tie_offset(e.parent_tie[v]));
    beta[v] = t.a == v ? beta[p] + o : beta[p] - o;
  }
  // A fixed class: its root sits where its first hard handle puts it. Roots come first in
  // `order`, so each root's value is set before its members read it.
  for (int v : e.order) {
    const int r = e.root[v];
    const int h = e.fix_handle[r];
    if (h < 0) continue;
    if (v == r)
      beta[v] = T(C(handle_positions, h)) - beta[d.handles[h]];  // beta[root] was 0
    else
      beta[v] += beta[r];
  }
  for (size_t k = 0; k < e.dep_vertex.size(); ++k) {
    const T g = T(e.dep_gamma[k]);
    beta[e.dep_vertex[k]] = (T(1) - g) * beta[e.dep_m1[k]] + g * beta[e.dep_m2[k]];
  }
}

// Throws ContradictionError when a tie closing a cycle, or a second hard handle on a
// class, disagrees with the values beta gives.
template <typename T, typename TieOffset>
void CheckConsistency(const PathEditState& d, const Elimination& e, const Eigen::Ref<const Trajectory2>& handle_positions,
                      TieOffset tie_offset, const std::vector<T>& beta) {
  const double tol = kConsistencyAbsolute + kConsistencyRelative * d.scale;
  auto fail = [](double miss, std::vector<ConstraintRef> refs) {
    Deduplicate(refs);
    std::ostringstream s;
    s << "hard constraints contradict each other by " << miss << ": " << Describe(refs);
    throw ContradictionError(s.str(), refs, miss);
  };
  for (int t : e.extra_ties) {
    const Tie& tie = e.ties[t];
    const double miss = static_cast<double>(std::abs(beta[tie.a] - beta[tie.b] - T(tie_offset(t))));
    if (miss > tol) {
      std::vector<ConstraintRef> refs{
          {tie.kind == TieKind::kLink ? ConstraintRef::kLink : ConstraintRef::kRigid, tie.index}};
      TiePath(e, tie.a, tie.b, refs);
      fail(miss, refs);
    }
  }
  for (int h : e.extra_handles) {
    const int v = d.handles[h];
    const double miss = static_cast<double>(std::abs(beta[v] - T(C(handle_positions, h))));
    if (miss > tol) {
      const int h0 = e.fix_handle[e.root[v]];
      std::vector<ConstraintRef> refs{{ConstraintRef::kHandle, h0}, {ConstraintRef::kHandle, h}};
      TiePath(e, v, d.handles[h0], refs);
      fail(miss, refs);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Functions of the other source files.

// path_edit_eliminate.cpp: the elimination of one step (step1: rotating ranges are
// similarity dependents of their masters; else they are tied by rotated rest offsets).
void BuildElimination(const PathEditState& d, bool step1, Elimination& e);

// path_edit_assemble.cpp: the eliminated rows, their normal matrix (or its envelope
// factorization), and the rows whose constants read beta.
template <typename Scalar>
void AssembleStep(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s);
template <typename Scalar>
void FindBetaRows(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s);

// path_edit_factor.cpp: fill-reducing orders for large systems, and the factorization.
template <typename Scalar>
CandidateOrders OrderCandidates(const StepSystem<Scalar>& s, const PathEditState& d, const Elimination& e,
                                bool two_threads);
template <typename Scalar>
void Factor(StepSystem<Scalar>& s, const CandidateOrders& orders, bool force_qr);

// path_edit_refine.cpp: min |A u - c| from the start u, for row constants c in double
// (T = Cplx) or extended (T = LCplx) precision.
template <typename Scalar, typename T>
void SolveStep(const StepSystem<Scalar>& s, const std::vector<T>& c, double scale, CVec& u, StepInfo& info);

// path_edit_solve.cpp: step 1 from scratch, starting from the similarity z -> a z + b;
// check: throw ContradictionError when hard constraints disagree.
void SolveShape(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                const Eigen::Ref<const Trajectory2>& link_offsets, Cplx a, Cplx b, double scale, bool check,
                std::vector<Cplx>& x1, StepInfo& info);

}  // namespace mocapedit::detail
