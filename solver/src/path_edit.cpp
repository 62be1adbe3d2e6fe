#include "mocapedit/path_edit.h"

#include <Eigen/SPQRSupport>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <amd.h>
#include <camd.h>
#include <cholmod.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <numeric>
#include <sstream>

#include "mocapedit/blas_lock.h"
#include "mocapedit/nested_dissection.h"
#include "mocapedit/skyline_ldlt.h"
#include "mocapedit/two_threads.h"

namespace mocapedit {
namespace {

using Cplx = std::complex<double>;
using LCplx = std::complex<long double>;
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
// CAMD orders them. CHOLMOD flops of step 1 by leaf size (1,000 / 1,500 / 2,300): groups of
// 100 agents x 43 key frames 7.4e7 / 7.2e7 / 9.3e7 (AMD 1.25e8); 200 x 43: 3.5e8 / 3.5e8 /
// 3.5e8 (AMD 6.2e8); 100 x 85: 2.9e8 / 2.8e8 / 2.6e8 (AMD 4.1e8); 400 x 21: 1.7e8 /
// 1.6e8 / 1.7e8 (AMD 1.8e8).
constexpr int kDissectionLeaf = 1500;
// Problems with at least this many vertices build their two steps at once, order step 1
// two ways at once, and factor the two steps at once (when the BLAS may be called from two
// threads). Group of 100 agents x 43 key frames, setup and solve: median 63 ms against 78
// ms with the steps in turn (40 solves each, interleaved, two cores); the three phases
// against one thread per step: best 38.6 / 40.9 ms against 44.3 / 46.7 ms (60 each, two
// runs), medians 1.5 ms lower.
constexpr int kParallelStepsVertices = 2000;
// CHOLMOD's flop count per factor entry above which its fronts are dense enough for the
// supernodal factorization (BLAS on dense blocks) to beat the simplicial one; CHOLMOD's own
// default. Group of 100 agents x 43 key frames: step 1 has 262 flops per entry (supernodal
// 3.5x faster than simplicial), step 2 has 93 (supernodal 1.7x faster than CHOLMOD's
// simplicial, 1.6x faster than Eigen's AMD LDLT with its analysis).
constexpr double kSupernodalFlopsPerEntry = 40;
// LDLT pivots below this fraction of the largest mean a singular system.
constexpr double kSingularPivot = 1e-13;

Cplx C(const Eigen::Ref<const Trajectory2>& m, Eigen::Index r) { return {m(r, 0), m(r, 1)}; }
double Conj(double x) { return x; }
Cplx Conj(const Cplx& x) { return std::conj(x); }
// conj(a) * b, in scalar arithmetic (the vector form stalls on store forwarding).
inline double MulConj(double a, double b) { return a * b; }
inline Cplx MulConj(const Cplx& a, const Cplx& b) {
  return {a.real() * b.real() + a.imag() * b.imag(), a.real() * b.imag() - a.imag() * b.real()};
}

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
  void Add(std::initializer_list<std::pair<int, LCplx>> entries, TargetKind kind, int index, double weight) {
    const long double s = weight == 1.0 ? 1.0L : std::sqrt(static_cast<long double>(weight));
    for (const auto& e : entries) Entry(e.first, weight == 1.0 ? e.second : e.second * s);
    Close(kind, index, s);
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
  // The shape row of a triangle of unit weight: x_i + (c - 1) x_j - c x_k.
  void AddTriangle(int i, int j, int k, const LCplx& c, int index) {
    vertex[entries_] = i;
    coeff[entries_] = 1.0;
    coeff_low[entries_++] = 0.0;
    Entry(j, c - 1.0L);
    Entry(k, -c);
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

// Fill-reducing orders of a normal matrix to choose from (empty when not computed), each
// with AMD's or CAMD's count of its factorization's multiply-subtracts.
struct CandidateOrders {
  std::vector<int> dissection;  // CAMD within a nested dissection's sets
  std::vector<int> amd;
  double dissection_flops = kInf, amd_flops = kInf;
};

// CHOLMOD's supernodal Cholesky of a lower triangle.
template <typename Scalar>
class SupernodalCholesky {
 public:
  using Sparse = Eigen::SparseMatrix<Scalar, Eigen::ColMajor, int>;
  static constexpr int kXtype = std::is_same<Scalar, Cplx>::value ? CHOLMOD_COMPLEX : CHOLMOD_REAL;

  SupernodalCholesky() {
    cholmod_start(&c_);
    c_.print = 0;  // failures are reported by the return values (and fall back to QR)
    c_.supernodal = CHOLMOD_SUPERNODAL;
    c_.final_asis = 1;
    c_.quick_return_if_not_posdef = 1;
  }
  ~SupernodalCholesky() {
    if (f_) cholmod_free_factor(&f_, &c_);
    cholmod_finish(&c_);
  }
  SupernodalCholesky(const SupernodalCholesky&) = delete;
  SupernodalCholesky& operator=(const SupernodalCholesky&) = delete;

  // Symbolic analysis of `lower` (compressed) in the candidate order with fewer flops, or
  // in CHOLMOD's AMD order when there are none. Then Flops() and FactorNonZeros() describe
  // the factor, and Dissected() tells whether the dissection's order won.
  bool Analyze(Sparse& lower, const CandidateOrders& orders) {
    cholmod_sparse a = View(lower);
    c_.nmethods = 1;
    c_.postorder = 1;
    dissected_ = !orders.dissection.empty() && orders.dissection_flops < orders.amd_flops;
    const std::vector<int>& given = dissected_ ? orders.dissection : orders.amd;
    if (!given.empty()) {
      c_.method[0].ordering = CHOLMOD_GIVEN;
      f_ = cholmod_analyze_p(&a, const_cast<int*>(given.data()), nullptr, 0, &c_);
    } else {
      c_.method[0].ordering = CHOLMOD_AMD;
      f_ = cholmod_analyze(&a, &c_);
    }
    return f_ != nullptr && c_.status == CHOLMOD_OK;
  }
  bool Dissected() const { return dissected_; }
  double Flops() const { return c_.fl; }
  double FactorNonZeros() const { return c_.lnz; }
  // Numeric factorization; false unless the matrix is positive definite.
  bool Factorize(Sparse& lower) {
    cholmod_sparse a = View(lower);
    return cholmod_factorize(&a, f_, &c_) && c_.status == CHOLMOD_OK && f_->minor == f_->n;
  }
  // Solves in place for `k` right-hand sides stored interleaved (x[i * k + c]). Const and
  // safe from several threads at once: each call has its own CHOLMOD workspace.
  void Solve(Scalar* x, int k) const {
    const size_t n = f_->n;
    std::vector<Scalar> b(n * k);  // column-major
    for (size_t i = 0; i < n; ++i)
      for (int c = 0; c < k; ++c) b[c * n + i] = x[i * k + c];
    cholmod_dense bd{};
    bd.nrow = n;
    bd.ncol = k;
    bd.d = n;
    bd.nzmax = n * k;
    bd.x = b.data();
    bd.xtype = kXtype;
    bd.dtype = CHOLMOD_DOUBLE;
    cholmod_common c;
    cholmod_start(&c);
    c.print = 0;
    cholmod_dense* y = cholmod_solve(CHOLMOD_A, f_, &bd, &c);
    if (!y) {
      cholmod_finish(&c);
      throw std::runtime_error("PathEdit: CHOLMOD solve failed");
    }
    const Scalar* yx = static_cast<const Scalar*>(y->x);
    for (size_t i = 0; i < n; ++i)
      for (int c2 = 0; c2 < k; ++c2) x[i * k + c2] = yx[c2 * n + i];
    cholmod_free_dense(&y, &c);
    cholmod_finish(&c);
  }

 private:
  static cholmod_sparse View(Sparse& m) {
    cholmod_sparse a{};
    a.nrow = m.rows();
    a.ncol = m.cols();
    a.nzmax = m.nonZeros();
    a.p = m.outerIndexPtr();
    a.i = m.innerIndexPtr();
    a.x = m.valuePtr();
    a.stype = -1;  // lower triangle
    a.itype = CHOLMOD_INT;
    a.xtype = kXtype;
    a.dtype = CHOLMOD_DOUBLE;
    a.sorted = 1;
    a.packed = 1;
    return a;
  }

  cholmod_common c_;
  cholmod_factor* f_ = nullptr;
  bool dissected_ = false;
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
      if (qr->info() != Eigen::Success) throw std::runtime_error("PathEdit: sparse QR failed");
    });
    return *qr;
  }
};

}  // namespace

struct PathEditData {
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

namespace {

// ---------------------------------------------------------------------------------------
// Validation helpers.

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("PathEdit: " + what);
}

inline void CheckIndex(int v, int n, const char* what, Eigen::Index i) {
  if (__builtin_expect(static_cast<unsigned>(v) >= static_cast<unsigned>(n), 0)) {
    std::ostringstream s;
    s << what << " " << i << " refers to vertex " << v << ", outside 0.." << n - 1;
    Require(false, s.str());
  }
}

Eigen::VectorXd Weights(const Eigen::VectorXd& w, Eigen::Index n, const char* what, bool allow_inf) {
  if (w.size() == 0) return Eigen::VectorXd::Ones(n);
  if (w.size() != n)
    Require(false, std::string(what) + " weights: expected " + std::to_string(n) + ", got " +
                             std::to_string(w.size()));
  for (Eigen::Index i = 0; i < n; ++i) {
    const bool ok = w[i] >= 0 && (std::isfinite(w[i]) || (allow_inf && w[i] == kInf));
    if (!ok)
      Require(false, std::string(what) + " " + std::to_string(i) + " has weight " + std::to_string(w[i]) +
                    (allow_inf ? " (expected >= 0, or +inf for hard)" : " (expected a finite value >= 0)"));
  }
  return w;
}

// ---------------------------------------------------------------------------------------
// Elimination.

void BuildElimination(const PathEditData& d, bool step1, Elimination& e) {
  const int n = d.vertices;
  e.vertices = n;
  e.root.assign(n, 0);
  // Similarity dependents: every vertex of a (non-degenerate) rotating range but its masters.
  std::vector<char> dependent(n, 0);
  if (step1) {
    for (size_t r = 0; r < d.rigid.size(); ++r) {
      if (d.rigid[r].mode != RigidMode::kRotate || d.degenerate[r]) continue;
      const LCplx z1 = d.zl(d.master1[r]), z2 = d.zl(d.master2[r]);
      for (int v : d.rigid[r].vertices) {
        if (v == d.master1[r] || v == d.master2[r]) continue;
        dependent[v] = 1;
        e.dep_vertex.push_back(v);
        e.dep_m1.push_back(d.master1[r]);
        e.dep_m2.push_back(d.master2[r]);
        e.dep_gamma.push_back((d.zl(v) - z1) / (z2 - z1));
      }
    }
  }
  // Ties.
  for (Eigen::Index l = 0; l < d.links.rows(); ++l)
    if (d.link_weights[l] == kInf)
      e.ties.push_back({d.links(l, 0), d.links(l, 1), TieKind::kLink, static_cast<int>(l), {}});
  for (size_t r = 0; r < d.rigid.size(); ++r) {
    const RigidRange& range = d.rigid[r];
    const bool translate = range.mode == RigidMode::kTranslate || (step1 && d.degenerate[r]);
    if (step1 && !translate) continue;
    const int m = d.master1[r];
    for (int v : range.vertices)
      if (v != m)
        e.ties.push_back({v, m, translate ? TieKind::kRest : TieKind::kRotated, static_cast<int>(r),
                          d.zl(v) - d.zl(m)});
  }
  // Ties at each vertex, CSR.
  std::vector<int> adj_ptr(n + 1, 0), adj(2 * e.ties.size());
  for (const Tie& t : e.ties) ++adj_ptr[t.a + 1], ++adj_ptr[t.b + 1];
  for (int v = 0; v < n; ++v) adj_ptr[v + 1] += adj_ptr[v];
  {
    std::vector<int> at(adj_ptr.begin(), adj_ptr.end() - 1);
    for (size_t t = 0; t < e.ties.size(); ++t) {
      adj[at[e.ties[t].a]++] = static_cast<int>(t);
      adj[at[e.ties[t].b]++] = static_cast<int>(t);
    }
  }
  // Spanning forest, breadth first, roots in vertex order (deterministic).
  e.parent.assign(n, -1);
  e.parent_tie.assign(n, -1);
  e.depth.assign(n, 0);
  std::vector<char> seen(n, 0), tree_tie(e.ties.size(), 0);
  e.order.resize(n);
  size_t members = 0;  // written to order
  for (int s = 0; s < n; ++s) {
    if (dependent[s]) {
      e.root[s] = -1;
      continue;
    }
    if (seen[s]) continue;
    seen[s] = 1;
    size_t head = members;
    e.order[members++] = s;
    e.root[s] = s;
    while (head < members) {
      const int v = e.order[head++];
      for (int k = adj_ptr[v]; k < adj_ptr[v + 1]; ++k) {
        const int t = adj[k];
        const int w = e.ties[t].a == v ? e.ties[t].b : e.ties[t].a;
        if (seen[w]) continue;
        seen[w] = 1;
        tree_tie[t] = 1;
        e.parent[w] = v;
        e.parent_tie[w] = t;
        e.depth[w] = e.depth[v] + 1;
        e.root[w] = s;
        e.order[members++] = w;
      }
    }
  }
  e.order.resize(members);
  for (size_t t = 0; t < e.ties.size(); ++t)
    if (!tree_tie[t]) e.extra_ties.push_back(static_cast<int>(t));
  // Hard handles fix their class.
  e.fix_handle.assign(n, -1);
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    if (d.handle_weights[h] != kInf) continue;
    const int r = e.root[d.handles[h]];
    if (e.fix_handle[r] < 0)
      e.fix_handle[r] = static_cast<int>(h);
    else
      e.extra_handles.push_back(static_cast<int>(h));
  }
  // Columns in root (vertex) order keep a chain banded.
  e.col.assign(n, -1);
  e.columns = 0;
  for (int v = 0; v < n; ++v)
    if (e.root[v] == v && e.fix_handle[v] < 0) e.col[v] = e.columns++;
  // Plain vertices: a class of one free vertex.
  {
    std::vector<int> size(n, 0);
    for (int v : e.order) ++size[e.root[v]];
    e.plain_col.assign(n, -1);
    for (int v : e.order)
      if (e.root[v] == v && size[v] == 1 && e.fix_handle[v] < 0) e.plain_col[v] = e.col[v];
  }
  // Vertex expressions of the others: a member of a class with a column is that column; a
  // dependent is built from its masters (never dependents themselves).
  e.e_ptr.assign(n + 1, 0);
  std::vector<int> dep_of;
  if (!e.dep_vertex.empty()) {
    dep_of.assign(n, -1);
    for (size_t k = 0; k < e.dep_vertex.size(); ++k) dep_of[e.dep_vertex[k]] = static_cast<int>(k);
  }
  size_t most = 2 * e.dep_vertex.size();  // terms: two per dependent, one per other vertex
  for (int v = 0; v < n; ++v) most += !dependent[v] && e.plain_col[v] < 0;
  e.e_col.resize(most);
  e.e_coeff.resize(most);
  int terms = 0;  // written to e_col, e_coeff
  for (int v = 0; v < n; ++v) {
    if (dependent[v]) {
      const int k = dep_of[v];
      const LCplx g = e.dep_gamma[k];
      const int at = terms;
      auto add = [&](int master, LCplx c) {
        const int col = e.col[e.root[master]];
        if (col < 0) return;
        for (int q = at; q < terms; ++q)
          if (e.e_col[q] == col) {
            e.e_coeff[q] += c;
            return;
          }
        e.e_col[terms] = col;
        e.e_coeff[terms++] = c;
      };
      add(e.dep_m1[k], 1.0L - g);
      add(e.dep_m2[k], g);
    } else if (e.plain_col[v] < 0 && e.col[e.root[v]] >= 0) {
      e.e_col[terms] = e.col[e.root[v]];
      e.e_coeff[terms++] = 1.0L;
    }
    e.e_ptr[v + 1] = terms;
  }
  e.e_col.resize(terms);
  e.e_coeff.resize(terms);
}

// The tie path between two members of one tree, as constraint references.
void TiePath(const Elimination& e, int a, int b, std::vector<ConstraintRef>& out) {
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

void Deduplicate(std::vector<ConstraintRef>& refs) {
  std::vector<ConstraintRef> out;
  for (const auto& r : refs)
    if (std::none_of(out.begin(), out.end(), [&](const auto& o) { return o.kind == r.kind && o.index == r.index; }))
      out.push_back(r);
  refs.swap(out);
}

std::string Describe(const std::vector<ConstraintRef>& refs) {
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
void ComputeBeta(const PathEditData& d, const Elimination& e, const Eigen::Ref<const Trajectory2>& handle_positions,
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
void CheckConsistency(const PathEditData& d, const Elimination& e, const Eigen::Ref<const Trajectory2>& handle_positions,
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
// Assembly of the eliminated rows and their normal matrix.

template <typename Scalar>
Scalar Cast(const Cplx& c);
template <>
Cplx Cast<Cplx>(const Cplx& c) { return c; }
template <>
double Cast<double>(const Cplx& c) { return c.real(); }

// When the envelope of A^H A in the natural column order is cheap to factor, assembles
// A^H A straight into the envelope factorization and returns true.
template <typename Scalar>
bool AssembleSkyline(StepSystem<Scalar>& s) {
  const int n = s.cols;
  std::vector<int> first(n);
  std::iota(first.begin(), first.end(), 0);
  for (int r = 0; r < s.rows; ++r) {
    if (s.a_ptr[r] == s.a_ptr[r + 1]) continue;
    const int lo = s.a_col[s.a_ptr[r]];  // columns are sorted within a row
    for (int p = s.a_ptr[r] + 1; p < s.a_ptr[r + 1]; ++p) first[s.a_col[p]] = std::min(first[s.a_col[p]], lo);
  }
  int64_t profile = 0;
  for (int i = 0; i < n; ++i) profile += i - first[i];
  if (profile > kSkylineProfilePerColumn * n) return false;
  if (SkylineLdlt<Scalar>::FactorCost(first) > kSkylineCostPerColumn * n) return false;
  s.use_skyline = true;
  s.skyline.Reset(first);
  // Entry (i, j), i >= j, of A^H A is sum_r conj(a_ri) a_rj.
  for (int r = 0; r < s.rows; ++r)
    for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
      const Scalar conj_i = Conj(s.a_val[p]);
      const int i = s.a_col[p];
      for (int q = s.a_ptr[r]; q <= p; ++q) s.skyline.Add(i, s.a_col[q], conj_i * s.a_val[q]);
    }
  s.gershgorin = s.skyline.GershgorinBound();
  return true;
}

// The eliminated rows A (CSR, extended and double precision) and the lower triangle of
// A^H A, by Gustavson's column-by-column product (or its envelope factorization).
template <typename Scalar>
void AssembleStep(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s) {
  s.cols = e.columns;
  s.rows = rows.size();
  // Each vertex of a row expands to at most two unknowns.
  const size_t most = rows.vertex.size() * 2;
  s.a_ptr.resize(static_cast<size_t>(s.rows) + 1);
  s.a_col.resize(most);
  s.a_val.resize(most);
  s.a_low.resize(most);
  s.a_ptr[0] = 0;
  int na = 0;  // entries written
  constexpr int kMax = 16;
  int cols[kMax];
  LCplx vals[kMax];
  for (int r = 0; r < s.rows; ++r) {
    int m = 0;
    bool plain = true;  // every vertex its own unknown: copy the coefficients as they are
    for (int p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) plain = plain && e.plain_col[rows.vertex[p]] >= 0;
    if (plain) {
      const int p0 = rows.ptr[r], count = rows.ptr[r + 1] - p0;
      if (count <= 3) {
        // Sort by column without branches (keys: column * 4 + entry).
        int64_t key[3] = {INT64_MAX, INT64_MAX, INT64_MAX};
        for (int k = 0; k < count; ++k) key[k] = int64_t{e.plain_col[rows.vertex[p0 + k]]} * 4 + k;
        auto order = [&](int a, int b) {
          const int64_t lo = std::min(key[a], key[b]), hi = std::max(key[a], key[b]);
          key[a] = lo;
          key[b] = hi;
        };
        order(0, 1);
        order(1, 2);
        order(0, 1);
        for (int k = 0; k < count; ++k) {
          const int p = p0 + static_cast<int>(key[k] & 3);
          s.a_col[na] = e.plain_col[rows.vertex[p]];
          s.a_val[na] = Cast<Scalar>(rows.coeff[p]);
          s.a_low[na++] = Cast<Scalar>(rows.coeff_low[p]);
        }
        s.a_ptr[r + 1] = na;
        continue;
      }
    }
    auto term = [&](int col, const LCplx& c) {
      int k = 0;
      while (k < m && cols[k] != col) ++k;
      if (k < m) {
        vals[k] += c;
      } else {
        if (m == kMax) throw std::logic_error("PathEdit: row with too many unknowns");
        cols[m] = col;
        vals[m++] = c;
      }
    };
    for (int p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
      const int v = rows.vertex[p];
      if (e.plain_col[v] >= 0) term(e.plain_col[v], rows.Extended(p));
      for (int q = e.e_ptr[v]; q < e.e_ptr[v + 1]; ++q)
        term(e.e_col[q], e.e_coeff[q] == 1.0L ? rows.Extended(p) : rows.Extended(p) * e.e_coeff[q]);
    }
    for (int a = 1; a < m; ++a)  // insertion sort by column
      for (int b = a; b > 0 && cols[b - 1] > cols[b]; --b) {
        std::swap(cols[b - 1], cols[b]);
        std::swap(vals[b - 1], vals[b]);
      }
    for (int k = 0; k < m; ++k) {
      s.a_col[na] = cols[k];
      const Scalar hi = Cast<Scalar>(Cplx(vals[k]));
      s.a_val[na] = hi;
      s.a_low[na++] = Cast<Scalar>(Cplx(vals[k] - LCplx(hi)));
    }
    s.a_ptr[r + 1] = na;
  }
  s.a_col.resize(na);
  s.a_val.resize(na);
  s.a_low.resize(na);
  if (AssembleSkyline(s)) return;
  // Columns of A: which rows touch each unknown.
  const int n = s.cols;
  std::vector<int> cptr(n + 1, 0);
  for (int c : s.a_col) ++cptr[c + 1];
  for (int j = 0; j < n; ++j) cptr[j + 1] += cptr[j];
  std::vector<int> centry(s.a_col.size()), crow(s.a_col.size()), fill(cptr.begin(), cptr.end() - 1);
  for (int r = 0; r < s.rows; ++r)
    for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
      centry[fill[s.a_col[p]]] = p;
      crow[fill[s.a_col[p]]++] = r;
    }
  std::vector<int> outer(n + 1, 0), inner, mark(n, -1);
  std::vector<Scalar> values;
  // Accumulate conj(a_qi) a_qj in plain doubles (complex temporaries stall the pipeline).
  constexpr int W = std::is_same<Scalar, Cplx>::value ? 2 : 1;
  const double* av = reinterpret_cast<const double*>(s.a_val.data());
  std::vector<double> acc(static_cast<size_t>(n) * W);
  inner.reserve(s.a_col.size() * 2);
  values.reserve(s.a_col.size() * 2);
  for (int j = 0; j < n; ++j) {
    const size_t start = inner.size();
    for (int k = cptr[j]; k < cptr[j + 1]; ++k) {
      const int r = crow[k];
      const double jr = av[W * centry[k]], ji = W == 2 ? av[W * centry[k] + 1] : 0.0;
      for (int q = s.a_ptr[r]; q < s.a_ptr[r + 1]; ++q) {
        const int i = s.a_col[q];
        if (i < j) continue;
        double* out = &acc[static_cast<size_t>(W) * i];
        if (mark[i] != j) {
          mark[i] = j;
          out[0] = 0.0;
          if (W == 2) out[W - 1] = 0.0;
          inner.push_back(i);
        }
        const double qr = av[W * q];
        if constexpr (W == 2) {
          const double qi = av[W * q + 1];
          out[0] += qr * jr + qi * ji;
          out[1] += qr * ji - qi * jr;
        } else {
          out[0] += qr * jr;
        }
      }
    }
    std::sort(inner.begin() + static_cast<std::ptrdiff_t>(start), inner.end());
    for (size_t k = start; k < inner.size(); ++k) {
      const double* v = &acc[static_cast<size_t>(W) * inner[k]];
      if constexpr (W == 2)
        values.push_back(Scalar(v[0], v[1]));
      else
        values.push_back(v[0]);
    }
    outer[j + 1] = static_cast<int>(inner.size());
  }
  s.normal.resize(n, n);
  s.normal.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), s.normal.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), s.normal.innerIndexPtr());
  std::copy(values.begin(), values.end(), s.normal.valuePtr());
  double lmax = 0;  // Gershgorin
  {
    std::vector<double> rowsum(n, 0.0);
    for (int j = 0; j < n; ++j)
      for (int p = outer[j]; p < outer[j + 1]; ++p) {
        const double a = std::abs(std::real(values[p])) + std::abs(std::imag(values[p]));  // >= |value|
        rowsum[j] += a;
        if (inner[p] != j) rowsum[inner[p]] += a;
      }
    for (double r : rowsum) lmax = std::max(lmax, r);
  }
  s.gershgorin = lmax;
}

// Per column of a step's unknowns (cols x 3, row-major): the rest position of one of its
// vertices relative to the centroid of the vertices at that vertex's time, and the time.
// Empty without vertex times. Large factorizations are ordered by splitting along these
// (nested_dissection.h): a group is a formation (position about its centroid) by time.
std::vector<double> ColumnCoordinates(const PathEditData& d, const Elimination& e) {
  if (d.times.empty()) return {};
  const int n = d.vertices;
  std::vector<int> by_time(n);
  std::iota(by_time.begin(), by_time.end(), 0);
  std::stable_sort(by_time.begin(), by_time.end(), [&](int a, int b) { return d.times[a] < d.times[b]; });
  // Runs of equal times; a run with fewer than half the vertices of the largest (a
  // constrained frame of one agent) takes its centroid from the neighbouring full runs.
  std::vector<int> start{0};
  for (int k = 1; k < n; ++k)
    if (d.times[by_time[k]] != d.times[by_time[k - 1]]) start.push_back(k);
  start.push_back(n);
  const size_t runs = start.size() - 1;
  int most = 0;
  for (size_t r = 0; r < runs; ++r) most = std::max(most, start[r + 1] - start[r]);
  std::vector<Cplx> centroid(runs, Cplx(0));
  std::vector<size_t> full;
  for (size_t r = 0; r < runs; ++r) {
    const int count = start[r + 1] - start[r];
    if (count < 2 || 2 * count < most) continue;
    for (int k = start[r]; k < start[r + 1]; ++k) centroid[r] += d.z[by_time[k]];
    centroid[r] /= static_cast<double>(count);
    full.push_back(r);
  }
  auto run_time = [&](size_t r) { return d.times[by_time[start[r]]]; };
  for (size_t r = 0, f = 0; r < runs && !full.empty(); ++r) {
    while (f < full.size() && full[f] < r) ++f;  // full[f]: first full run at or after r
    if (f < full.size() && full[f] == r) continue;
    if (f == 0) {
      centroid[r] = centroid[full[0]];
    } else if (f == full.size()) {
      centroid[r] = centroid[full.back()];
    } else {
      const size_t a = full[f - 1], b = full[f];
      const double w = (run_time(r) - run_time(a)) / (run_time(b) - run_time(a));
      centroid[r] = (1 - w) * centroid[a] + w * centroid[b];
    }
  }
  std::vector<double> coords(static_cast<size_t>(e.columns) * 3, 0.0);
  std::vector<char> done(e.columns, 0);
  for (size_t r = 0; r < runs; ++r)
    for (int k = start[r]; k < start[r + 1]; ++k) {
      const int v = by_time[k];
      const int col = e.plain_col[v] >= 0 ? e.plain_col[v] : e.e_ptr[v] < e.e_ptr[v + 1] ? e.e_col[e.e_ptr[v]] : -1;
      if (col < 0 || done[col]) continue;
      done[col] = 1;
      const Cplx q = d.z[v] - centroid[r];
      coords[3 * col] = q.real();
      coords[3 * col + 1] = q.imag();
      coords[3 * col + 2] = d.times[v];
    }
  return coords;
}

// The orders of a step's normal matrix for the supernodal factorization to choose from:
// with vertex times, CAMD within a nested dissection by position and time, and AMD (whose
// order fills less on some meshes: a 5 x 5 block of 251 key frames, 1.14 times fewer
// flops; a 25 x 40 block of 21, 2.6 times fewer, where the formation's cross-section makes
// every separator large). Both on two threads when `two_threads`.
// None when the system is small, banded (skyline) or without times: Factor then asks
// CHOLMOD for its AMD order.
template <typename Scalar>
CandidateOrders OrderCandidates(const StepSystem<Scalar>& s, const PathEditData& d, const Elimination& e,
                                bool two_threads) {
  CandidateOrders o;
  if (s.use_skyline || s.cols < kSupernodalColumns || d.times.empty()) return o;
  const int n = s.cols;
  const int* ptr = s.normal.outerIndexPtr();
  const int* idx = s.normal.innerIndexPtr();
  auto dissect = [&] {
    const std::vector<double> coords = ColumnCoordinates(d, e);
    const Dissection parts = CoordinateDissection(n, ptr, idx, coords.data(), 3, kDissectionLeaf);
    std::vector<int> perm(n);
    double info[CAMD_INFO];
    if (camd_order(n, ptr, idx, perm.data(), nullptr, info, parts.set.data()) < CAMD_OK) return;
    o.dissection = std::move(perm);
    o.dissection_flops = info[CAMD_NMULTSUBS_LDL];
  };
  auto amd = [&] {
    std::vector<int> perm(n);
    double info[AMD_INFO];
    if (amd_order(n, ptr, idx, perm.data(), nullptr, info) < AMD_OK) return;
    o.amd = std::move(perm);
    o.amd_flops = info[AMD_NMULTSUBS_LDL];
  };
  if (two_threads) {
    OnTwoThreads(dissect, amd);
  } else {
    dissect();
    amd();
  }
  return o;
}

// Estimate of cond(A^H A): Gershgorin's bound over inverse iteration with the factor.
template <typename Scalar>
double EstimateCondition(const StepSystem<Scalar>& s) {
  const double lmax = s.gershgorin;
  typename StepSystem<Scalar>::Vector v(s.cols);
  for (int j = 0; j < s.cols; ++j) v[j] = Scalar(1.0 + 0.1 * ((j * 7919) % 13) / 13.0);
  // Inverse iteration from a smooth vector, whose component along the lowest (smoothest)
  // mode of these path Laplacians is large: one pass gives the smallest eigenvalue within a
  // small factor, which is all the refinement needs (it keeps a safety factor of 10).
  double lmin = 0;
  for (int it = 0; it < 1; ++it) {
    v /= v.norm();
    s.SolveNormalInPlace(v);
    lmin = 1.0 / v.norm();
  }
  return std::isfinite(lmin) && lmin > 0 ? lmax / lmin : kInf;
}

// Factors the normal matrix; uses QR when it is singular or too ill-conditioned for
// refinement of the normal equations to converge.
template <typename Scalar>
void Factor(StepSystem<Scalar>& s, const CandidateOrders& orders, bool force_qr) {
  if (s.cols == 0) {
    s.solver = "none";
    return;
  }
  bool ok = false;
  Eigen::VectorXd diag;
  bool simplicial = !s.use_skyline;
  if (s.use_skyline) {
    ok = s.skyline.Factor();
    if (ok) diag = Eigen::Map<const Eigen::VectorXd>(s.skyline.D().data(), s.cols);
  } else if (s.cols >= kSupernodalColumns) {
    // CHOLMOD's analysis (its AMD is several times faster than Eigen's) tells whether the
    // factor has dense fronts: many flops per factor entry.
    SerialCholmod();
    s.supernodal = std::make_unique<SupernodalCholesky<Scalar>>();
    const bool analyzed = s.supernodal->Analyze(s.normal, orders);
    s.dissected = s.supernodal->Dissected();
    if (analyzed &&
        s.supernodal->Flops() >= kSupernodalFlopsPerEntry * s.supernodal->FactorNonZeros()) {
      simplicial = false;
      BlasLock lock;
      ok = s.supernodal->Factorize(s.normal);  // fails unless positive definite
      if (ok) diag = Eigen::VectorXd::Ones(1);
      if (!ok) s.supernodal.reset();
    } else {
      s.supernodal.reset();
    }
  }
  if (simplicial) {
    s.amd.analyzePattern(s.normal);
    s.amd.factorize(s.normal);
    ok = s.amd.info() == Eigen::Success;
    if (ok) diag = s.amd.vectorD().real();
  }
  if (ok) {
    const double dmax = diag.maxCoeff(), dmin = diag.minCoeff();
    ok = dmax > 0 && dmin > kSingularPivot * dmax;
  }
  if (!ok) {
    s.use_qr = true;
    s.condition = kInf;
    s.solver = "SPQR (singular)";
    s.QR();
    return;
  }
  s.condition = EstimateCondition(s);
  s.extended = s.condition * kEps > 1e-9;
  s.solver = s.supernodal ? (s.dissected ? "CHOLMOD supernodal (nested dissection)" : "CHOLMOD supernodal")
             : s.use_skyline ? "LDLT"
                             : "LDLT (AMD)";
  if (force_qr || s.condition * kEps > kLdltTrust) {
    s.use_qr = true;
    s.solver = force_qr ? "SPQR" : "SPQR (ill-conditioned)";
    s.QR();
  }
}

// Scratch vectors of one solve.
struct Work {
  std::vector<Cplx> rr;  // row residuals
};

// The correction for the residual of u: QR of the rectangular system, or the factored
// normal equations. Row residuals are accumulated in extended precision when T is, unless
// `coarse` (a first pass from a start far from the solution, whose correction only needs
// to be accurate to about cond * eps, as any pass's is).
template <typename Scalar, typename T>
void Correction(const StepSystem<Scalar>& s, const std::vector<T>& c, const CVec& u, Work& w,
                bool qr, bool coarse, CVec& delta) {
  w.rr.resize(s.rows);
  if (std::is_same<T, Cplx>::value || coarse) {  // double residuals are enough
    for (int r = 0; r < s.rows; ++r) {
      Cplx acc = Cplx(c[r]);
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) acc -= s.a_val[p] * u[s.a_col[p]];
      w.rr[r] = acc;
    }
  } else for (int r = 0; r < s.rows; ++r) {
    long double re = c[r].real(), im = c[r].imag();
    for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
      const LCplx a = LCplx(s.a_val[p]) + LCplx(s.a_low[p]);
      const long double ur = u[s.a_col[p]].real(), ui = u[s.a_col[p]].imag();
      re -= a.real() * ur - a.imag() * ui;
      im -= a.real() * ui + a.imag() * ur;
    }
    w.rr[r] = Cplx(static_cast<double>(re), static_cast<double>(im));
  }
  delta.resize(s.cols);
  if constexpr (std::is_same<Scalar, double>::value) {
    if (qr) {
      Eigen::MatrixX2d b(s.rows, 2);
      for (int r = 0; r < s.rows; ++r) b.row(r) << w.rr[r].real(), w.rr[r].imag();
      const auto& qr = s.QR();
      BlasLock lock;
      const Eigen::MatrixX2d x = qr.solve(b);
      for (int j = 0; j < s.cols; ++j) delta[j] = Cplx(x(j, 0), x(j, 1));
      return;
    }
    // A real system acts on x and y alike: solve both as interleaved right-hand sides.
    delta.setZero();
    double* g = reinterpret_cast<double*>(delta.data());
    for (int r = 0; r < s.rows; ++r)
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
        const double a = s.a_val[p] + s.a_low[p];
        g[2 * s.a_col[p]] += a * w.rr[r].real();
        g[2 * s.a_col[p] + 1] += a * w.rr[r].imag();
      }
    s.SolveInterleaved(g, 2);
  } else {
    if (qr) {
      Eigen::Map<const CVec> b(w.rr.data(), s.rows);
      const auto& qr = s.QR();
      BlasLock lock;
      delta = qr.solve(CVec(b));
      return;
    }
    delta.setZero();
    for (int r = 0; r < s.rows; ++r)
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p)
        delta[s.a_col[p]] += std::conj(s.a_val[p] + s.a_low[p]) * w.rr[r];
    s.SolveInterleaved(delta.data(), 1);
  }
}

// Solves min |A u - c| from the start u by refinement: each pass removes all but about
// cond * eps of the error (QR: about cond(A) * eps). Returns false when it does not converge.
template <typename Scalar, typename T>
bool Refine(const StepSystem<Scalar>& s, const std::vector<T>& c, double scale, CVec& u, StepInfo& info,
            bool qr) {
  Work w;
  CVec delta;
  const double rate = qr ? std::sqrt(std::max(s.condition, 1.0)) * kEps : s.condition * kEps;
  const double tol = kRefineTolerance * scale;
  double previous = kInf;
  info.refinements = 0;
  for (int it = 0; it < kMaxRefinements; ++it) {
    // Extended residuals: the first pass in double precision, the others extended (and
    // at least one of them).
    const bool coarse = std::is_same<T, LCplx>::value && it == 0;
    Correction(s, c, u, w, qr, coarse, delta);
    u += delta;
    const double size = delta.size() ? std::sqrt(delta.cwiseAbs2().maxCoeff()) : 0.0;
    info.refinements = it + 1;
    info.correction = size;
    if (!std::isfinite(size)) return false;
    // The error left is about rate * size: stop when that is below the tolerance.
    if (!coarse && (10 * rate * size <= tol || size <= tol)) return true;
    if (it >= 1 && size > 0.5 * previous) return size <= 1e-9 * scale;  // stagnation
    previous = size;
  }
  return false;
}

// ---------------------------------------------------------------------------------------

void ChooseMasters(const PathEditProblem& p, PathEditData& d, const std::vector<char>& hard_vertex) {
  const size_t nr = d.rigid.size();
  d.master1.assign(nr, -1);
  d.master2.assign(nr, -1);
  d.degenerate.assign(nr, 0);
  for (size_t r = 0; r < nr; ++r) {
    const auto& vs = d.rigid[r].vertices;
    std::vector<int> hard;
    for (int v : vs)
      if (hard_vertex[v]) hard.push_back(v);
    const bool rotate = d.rigid[r].mode == RigidMode::kRotate;
    if (rotate && hard.size() > 2) {
      std::vector<ConstraintRef> refs{{ConstraintRef::kRigid, static_cast<int>(r)}};
      std::vector<char> in(d.vertices, 0);
      for (int v : vs) in[v] = 1;
      for (Eigen::Index h = 0; h < p.handles.size(); ++h)
        if (in[p.handles[h]] && d.handle_weights[h] == kInf) refs.push_back({ConstraintRef::kHandle, static_cast<int>(h)});
      for (Eigen::Index l = 0; l < p.links.rows(); ++l)
        if ((in[p.links(l, 0)] || in[p.links(l, 1)]) && d.link_weights[l] == kInf)
          refs.push_back({ConstraintRef::kLink, static_cast<int>(l)});
      throw ContradictionError("a rotating rigid range holds hard constraints at " + std::to_string(hard.size()) +
                                   " vertices; it can hold at most two: " + Describe(refs),
                               refs, 0.0);
    }
    int m1 = hard.empty() ? vs.front() : hard[0];
    int m2 = -1;
    if (hard.size() >= 2) {
      m2 = hard[1];
    } else {
      // The farthest vertex from m1 (from the farthest from the first, if m1 is free).
      auto farthest = [&](int from) {
        int best = from;
        double bd = -1;
        for (int v : vs) {
          const double dd = std::abs(d.z[v] - d.z[from]);
          if (dd > bd) bd = dd, best = v;
        }
        return best;
      };
      if (hard.empty()) m1 = farthest(vs.front());
      m2 = farthest(m1);
    }
    d.master1[r] = m1;
    d.master2[r] = m2;
    if (rotate) {
      double extent = 0;
      for (int v : vs) extent = std::max(extent, std::abs(d.z[v] - d.z[m1]));
      const bool too_small = m2 == m1 || std::abs(d.z[m2] - d.z[m1]) <= std::max(p.rigid_min_extent, 1e-9 * d.scale);
      d.degenerate[r] = too_small;
      if (too_small && hard.size() == 2 && std::abs(d.z[hard[0]] - d.z[hard[1]]) > 0) d.degenerate[r] = 0;
    }
  }
}

}  // namespace

namespace {

// Rows whose constant part depends on beta: those touching a vertex that is not simply
// its own free unknown.
template <typename Scalar>
void FindBetaRows(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s) {
  s.beta_rows.clear();
  for (int r = 0; r < rows.size(); ++r)
    for (int p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p)
      if (e.plain_col[rows.vertex[p]] < 0) {
        s.beta_rows.push_back(r);
        break;
      }
}

void PrecomputeResponses(PathEditData& d);

}  // namespace

void AppendChainTerms(const Eigen::Ref<const Trajectory2>& rest, int first, int count, double min_baseline,
                      IndexTriples& triangles, IndexPairs& edges) {
  Require(first >= 0 && count >= 0 && first + count <= rest.rows(), "chain vertices outside the rest positions");
  Require(min_baseline >= 0 && std::isfinite(min_baseline), "min_baseline must be a finite value >= 0");
  std::vector<std::array<int, 3>> tri;
  tri.reserve(static_cast<size_t>(std::max(count - 2, 0)));
  for (int i = 1; i + 1 < count; ++i) {
    int a = i - 1, b = i + 1;
    const auto at = [&](int k) { return rest.row(first + k); };
    // Widen the frame symmetrically until its ends are min_baseline apart.
    while ((at(b) - at(a)).norm() < min_baseline || (at(b) - at(a)).norm() == 0.0) {
      if (a > 0 && (b + 1 >= count || i - a <= b - i))
        --a;
      else if (b + 1 < count)
        ++b;
      else
        break;
    }
    if ((at(b) - at(a)).norm() >= min_baseline && (at(b) - at(a)).norm() > 0.0)
      tri.push_back({first + i, first + a, first + b});
  }
  const Eigen::Index t0 = triangles.rows(), e0 = edges.rows();
  triangles.conservativeResize(t0 + static_cast<Eigen::Index>(tri.size()), 3);
  for (size_t k = 0; k < tri.size(); ++k)
    triangles.row(t0 + static_cast<Eigen::Index>(k)) << tri[k][0], tri[k][1], tri[k][2];
  const int ne = std::max(count - 1, 0);
  edges.conservativeResize(e0 + ne, 2);
  for (int k = 0; k < ne; ++k) edges.row(e0 + k) << first + k, first + k + 1;
}

namespace {

// Soft handles and links: rows of both steps.
void AddSoftRows(const PathEditProblem& p, const PathEditData& d, Rows& rows) {
  for (Eigen::Index h = 0; h < p.handles.size(); ++h)
    if (d.handle_weights[h] != kInf && d.handle_weights[h] > 0)
      rows.Add({{p.handles[h], 1.0L}}, TargetKind::kHandle, static_cast<int>(h), d.handle_weights[h]);
  for (Eigen::Index l = 0; l < p.links.rows(); ++l)
    if (d.link_weights[l] != kInf && d.link_weights[l] > 0)
      rows.Add({{p.links(l, 0), 1.0L}, {p.links(l, 1), -1.0L}}, TargetKind::kLink, static_cast<int>(l),
               d.link_weights[l]);
}

}  // namespace

void PathEditPrecompute(const PathEditProblem& p, std::shared_ptr<PathEditData>& out) {
  auto d = std::make_shared<PathEditData>();
  const int n = static_cast<int>(p.rest.rows());
  d->vertices = n;
  d->rest = p.rest;
  Require(p.rest.allFinite(), "rest positions must be finite");
  d->z.resize(n);
  d->scale = 1.0;
  for (int v = 0; v < n; ++v) {
    d->z[v] = C(p.rest, v);
    d->scale = std::max({d->scale, std::abs(p.rest(v, 0)), std::abs(p.rest(v, 1))});
  }
  const Eigen::VectorXd tw = Weights(p.triangle_weights, p.triangles.rows(), "triangle", false);
  const Eigen::VectorXd ew = Weights(p.edge_weights, p.edges.rows(), "edge", false);
  d->handle_weights = Weights(p.handle_weights, p.handles.size(), "handle", true);
  d->link_weights = Weights(p.link_weights, p.links.rows(), "link", true);
  d->handles = p.handles;
  d->links = p.links;
  d->edges = p.edges;
  for (Eigen::Index t = 0; t < p.triangles.rows(); ++t)
    for (int c = 0; c < 3; ++c) CheckIndex(p.triangles(t, c), n, "triangle", t);
  d->edge_length.resize(static_cast<size_t>(p.edges.rows()));
  for (Eigen::Index e = 0; e < p.edges.rows(); ++e) {
    for (int c = 0; c < 2; ++c) CheckIndex(p.edges(e, c), n, "edge", e);
    d->edge_length[e] = std::sqrt(std::norm(d->z[p.edges(e, 1)] - d->z[p.edges(e, 0)]));
  }
  for (Eigen::Index h = 0; h < p.handles.size(); ++h) CheckIndex(p.handles[h], n, "handle", h);
  for (Eigen::Index l = 0; l < p.links.rows(); ++l) {
    for (int c = 0; c < 2; ++c) CheckIndex(p.links(l, c), n, "link", l);
    if (p.links(l, 0) == p.links(l, 1)) Require(false, "link " + std::to_string(l) + " ties a vertex to itself");
  }
  d->rigid = p.rigid;
  d->rigid_of.assign(n, -1);
  for (size_t r = 0; r < d->rigid.size(); ++r) {
    if (d->rigid[r].vertices.empty()) Require(false, "rigid range " + std::to_string(r) + " is empty");
    for (int v : d->rigid[r].vertices) {
      CheckIndex(v, n, "rigid range", static_cast<Eigen::Index>(r));
      if (d->rigid_of[v] >= 0)
        Require(false, "rigid ranges " + std::to_string(d->rigid_of[v]) +
                                      " and " + std::to_string(r) + " share vertex " + std::to_string(v));
      d->rigid_of[v] = static_cast<int>(r);
    }
    if (d->rigid[r].mode == RigidMode::kTranslate) d->has_translate = true;
  }
  std::vector<char> hard_vertex(n, 0);
  for (Eigen::Index h = 0; h < p.handles.size(); ++h)
    if (d->handle_weights[h] == kInf) hard_vertex[p.handles[h]] = 1;
  for (Eigen::Index l = 0; l < p.links.rows(); ++l)
    if (d->link_weights[l] == kInf) hard_vertex[p.links(l, 0)] = hard_vertex[p.links(l, 1)] = 1;
  d->rigid_min_extent = p.rigid_min_extent;
  if (p.vertex_times.size() != 0) {
    Require(p.vertex_times.size() == n, "vertex times: expected " + std::to_string(n) + ", got " +
                                            std::to_string(p.vertex_times.size()));
    Require(p.vertex_times.allFinite(), "vertex times must be finite");
    d->times.assign(p.vertex_times.data(), p.vertex_times.data() + n);
  }
  ChooseMasters(p, *d, hard_vertex);
  d->boundary_edges.assign(d->rigid.size(), {});

  auto same_range = [&](std::initializer_list<int> vs) {
    const int r = d->rigid_of[*vs.begin()];
    if (r < 0) return false;
    for (int v : vs)
      if (d->rigid_of[v] != r) return false;
    return true;
  };
  d->rows1.Reserve(p.triangles.rows() + p.handles.size() + p.links.rows(),
                   3 * p.triangles.rows() + p.handles.size() + 2 * p.links.rows());
  d->rows2.Reserve(p.edges.rows() + p.handles.size() + p.links.rows(),
                   2 * p.edges.rows() + p.handles.size() + 2 * p.links.rows());
  // Step 1 rows: triangles, then soft handles and links.
  for (Eigen::Index t = 0; t < p.triangles.rows(); ++t) {
    const int i = p.triangles(t, 0), j = p.triangles(t, 1), k = p.triangles(t, 2);
    const Cplx frame = d->z[k] - d->z[j];
    if (!(std::norm(frame) > 1e-24 * d->scale * d->scale)) {
      std::ostringstream s;
      s << "triangle " << t << ": its frame vertices " << j << " and " << k << " share a rest position";
      Require(false, s.str());
    }
    if (tw[t] == 0 || same_range({i, j, k})) continue;
    const LCplx c = (d->zl(i) - d->zl(j)) / (d->zl(k) - d->zl(j));
    if (tw[t] == 1.0)
      d->rows1.AddTriangle(i, j, k, c, static_cast<int>(t));
    else
      d->rows1.Add({{i, 1.0L}, {j, c - 1.0L}, {k, -c}}, TargetKind::kZero, static_cast<int>(t), tw[t]);
  }
  AddSoftRows(p, *d, d->rows1);
  d->rows1.Finish();
  // The two steps' systems are independent until solved: a large problem builds them on
  // two threads, orders step 1 two ways on two threads, then factors both steps at once
  // (when the BLAS may be called from two threads). Group of 100 agents x 43 key frames:
  // the dissection's order and AMD's each take 2 to 3 ms, and step 1's factorization
  // (17 ms) is the longer of the two.
  auto assemble1 = [&] {
    BuildElimination(*d, true, d->elim1);
    AssembleStep(d->rows1, d->elim1, d->step1);
    FindBetaRows(d->rows1, d->elim1, d->step1);
  };
  auto assemble2 = [&] {
    // Step 2 rows: edges, then soft handles and links.
    for (Eigen::Index e = 0; e < p.edges.rows(); ++e) {
      const int j = p.edges(e, 0), k = p.edges(e, 1);
      const int rj = d->rigid_of[j], rk = d->rigid_of[k];
      if (rj != rk) {
        if (rj >= 0) d->boundary_edges[rj].push_back(static_cast<int>(e));
        if (rk >= 0) d->boundary_edges[rk].push_back(static_cast<int>(e));
      }
      if (ew[e] == 0 || j == k || same_range({j, k})) continue;
      if (ew[e] == 1.0)
        d->rows2.AddExact({{k, 1.0}, {j, -1.0}}, TargetKind::kEdge, static_cast<int>(e));
      else
        d->rows2.Add({{k, 1.0L}, {j, -1.0L}}, TargetKind::kEdge, static_cast<int>(e), ew[e]);
    }
    AddSoftRows(p, *d, d->rows2);
    d->rows2.Finish();
    BuildElimination(*d, false, d->elim2);
    AssembleStep(d->rows2, d->elim2, d->step2);
    FindBetaRows(d->rows2, d->elim2, d->step2);
  };
  const bool large = n >= kParallelStepsVertices;
  if (large) {
    OnTwoThreads(assemble1, assemble2);
  } else {
    assemble1();
    assemble2();
  }
  // Step 2 in CHOLMOD's AMD order: its edges (no triangles) fill less, and a dissection
  // measured no fewer flops (group of 100 agents x 43 key frames: 1.67e7 against 1.68e7).
  const CandidateOrders orders1 = OrderCandidates(d->step1, *d, d->elim1, large);
  auto factor1 = [&] { Factor(d->step1, orders1, p.force_qr); };
  auto factor2 = [&] { Factor(d->step2, CandidateOrders{}, p.force_qr); };
  if (large && Blas().concurrent) {
    OnTwoThreads(factor1, factor2);
  } else {
    factor1();
    factor2();
  }
  if (p.precompute_responses) PrecomputeResponses(*d);
  out = std::move(d);
}

namespace {

// c = sqrt(w) target - G beta, per row, in extended precision. Triangle rows have no
// target; only rows listed in beta_rows read beta.
template <typename Scalar, typename T>
void RowConstants(const Rows& rows, const StepSystem<Scalar>& s, const std::vector<T>& beta,
                  const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
                  const std::vector<Cplx>& edge_targets, std::vector<T>& c) {
  using R = typename T::value_type;
  c.resize(rows.size());
  for (int r = 0; r < rows.size(); ++r) {
    T t;
    switch (rows.target[r]) {
      case TargetKind::kZero: c[r] = T(0); continue;
      case TargetKind::kHandle: t = T(C(handle_positions, rows.target_index[r])); break;
      case TargetKind::kLink: t = T(C(link_offsets, rows.target_index[r])); break;
      case TargetKind::kEdge: t = T(edge_targets[rows.target_index[r]]); break;
    }
    c[r] = rows.sqrt_weight[r] == 1.0L ? t : t * static_cast<R>(rows.sqrt_weight[r]);
  }
  for (int r : s.beta_rows)
    for (int p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) c[r] -= T(rows.Extended(p)) * beta[rows.vertex[p]];
}

// Positions from unknowns: x_v = sum e u + beta_v (rounded once to double).
template <typename T>
void Expand(const Elimination& e, const CVec& u, const std::vector<T>& beta, std::vector<Cplx>& x) {
  x.resize(e.vertices);
  for (int v = 0; v < e.vertices; ++v) {
    if (e.plain_col[v] >= 0) {
      x[v] = u[e.plain_col[v]];
    } else if (e.e_ptr[v] == e.e_ptr[v + 1]) {
      x[v] = Cplx(beta[v]);
    } else {
      LCplx acc = LCplx(beta[v]);
      for (int q = e.e_ptr[v]; q < e.e_ptr[v + 1]; ++q) acc += e.e_coeff[q] * LCplx(u[e.e_col[q]]);
      x[v] = Cplx(acc);
    }
  }
}

// Starting unknowns: each column's root moved by the similarity z -> a z + b, or taken
// from `from`.
CVec Start(const Elimination& e, const std::vector<Cplx>& z, Cplx a, Cplx b, const std::vector<Cplx>* from) {
  CVec u(e.columns);
  for (int v = 0; v < e.vertices; ++v)
    if (e.root[v] == v && e.col[v] >= 0) u[e.col[v]] = from ? (*from)[v] : a * z[v] + b;
  return u;
}

template <typename Scalar, typename T>
void SolveStep(const StepSystem<Scalar>& s, const std::vector<T>& c, double scale, CVec& u, StepInfo& info) {
  info.solver = s.solver;
  info.unknowns = s.cols;
  info.refinements = 0;
  info.correction = 0;
  if (s.cols == 0) return;
  if (s.use_qr) {
    if (!Refine(s, c, scale, u, info, true)) info.solver += " (refinement did not converge)";
    return;
  }
  const CVec start = u;
  if (!Refine(s, c, scale, u, info, false)) {
    u = start;
    info.solver = "SPQR (ill-conditioned)";
    if (!Refine(s, c, scale, u, info, true)) info.solver += " (refinement did not converge)";
  }
}

// Step 1 from scratch, starting from the similarity z -> a z + b.
// One step: constants from the handle positions and offsets, refinement from u, positions.
// Extended precision where the step's conditioning needs it.
template <typename T, typename Scalar, typename TieOffset>
void SolveWith(const PathEditData& d, const Elimination& e, const Rows& rows, const StepSystem<Scalar>& s,
               const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
               TieOffset offset, const std::vector<Cplx>& edge_targets, bool check, double scale, CVec u,
               std::vector<Cplx>& x, StepInfo& info) {
  // Scratch kept per thread: the row constants are all written below, and resizing a
  // vector of extended complex values to the size it had costs nothing.
  thread_local std::vector<T> beta, c;
  ComputeBeta(d, e, handle_positions, offset, beta);
  if (check) CheckConsistency(d, e, handle_positions, offset, beta);
  RowConstants(rows, s, beta, handle_positions, link_offsets, edge_targets, c);
  SolveStep(s, c, scale, u, info);
  Expand(e, u, beta, x);
}

template <typename Scalar, typename TieOffset>
void Solve(const PathEditData& d, const Elimination& e, const Rows& rows, const StepSystem<Scalar>& s,
           const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
           TieOffset offset, const std::vector<Cplx>& edge_targets, bool check, double scale, CVec u,
           std::vector<Cplx>& x, StepInfo& info) {
  if (s.extended || s.use_qr)
    SolveWith<LCplx>(d, e, rows, s, handle_positions, link_offsets, offset, edge_targets, check, scale, u, x, info);
  else
    SolveWith<Cplx>(d, e, rows, s, handle_positions, link_offsets, offset, edge_targets, check, scale, u, x, info);
}

// Step 1 from scratch, starting from the similarity z -> a z + b.
void SolveShape(const PathEditData& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                const Eigen::Ref<const Trajectory2>& link_offsets, Cplx a, Cplx b, double scale, bool check,
                std::vector<Cplx>& x1, StepInfo& info) {
  auto offset = [&](int t) -> LCplx {
    const Tie& tie = d.elim1.ties[t];
    return tie.kind == TieKind::kLink ? LCplx(C(link_offsets, tie.index)) : tie.rest;
  };
  Solve(d, d.elim1, d.rows1, d.step1, handle_positions, link_offsets, offset, {}, check, scale,
        Start(d.elim1, d.z, a, b, nullptr), x1, info);
}

void PrecomputeResponses(PathEditData& d) {
  const Eigen::Index nh = d.handles.size(), nl = d.links.rows();
  Trajectory2 hp = Trajectory2::Zero(nh, 2), lo = Trajectory2::Zero(nl, 2);
  std::vector<Cplx> x;
  SolveShape(d, hp, lo, 0.0, 0.0, 1.0, false, x, d.response_info);
  d.response_base = x;
  auto response = [&](Trajectory2& values, Eigen::Index k, std::vector<Cplx>& out) {
    values(k, 0) = 1.0;
    StepInfo info;
    SolveShape(d, hp, lo, 0.0, 0.0, 1.0, false, x, info);
    values(k, 0) = 0.0;
    out.resize(x.size());
    for (size_t v = 0; v < x.size(); ++v) out[v] = x[v] - d.response_base[v];
    d.response_info.refinements = std::max(d.response_info.refinements, info.refinements);
  };
  d.handle_response.resize(static_cast<size_t>(nh));
  d.link_response.resize(static_cast<size_t>(nl));
  for (Eigen::Index h = 0; h < nh; ++h) response(hp, h, d.handle_response[static_cast<size_t>(h)]);
  for (Eigen::Index l = 0; l < nl; ++l) response(lo, l, d.link_response[static_cast<size_t>(l)]);
  d.responses = true;
}

}  // namespace

void PathEditSolve(const PathEditData& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                   const Eigen::Ref<const Trajectory2>& link_offsets, PathEditResult& result) {
  const int n = d.vertices;
  if (handle_positions.rows() != d.handles.size())
    Require(false,
          "expected " + std::to_string(d.handles.size()) + " handle positions, got " +
              std::to_string(handle_positions.rows()));
  if (link_offsets.rows() != d.links.rows())
    Require(false, "expected " + std::to_string(d.links.rows()) +
                                                     " link offsets, got " + std::to_string(link_offsets.rows()));
  Require(handle_positions.allFinite() && link_offsets.allFinite(), "handle positions and link offsets must be finite");
  const int nr = static_cast<int>(d.rigid.size());
  result.rigid_angles = Eigen::VectorXd::Zero(nr);
  result.rigid_motion = false;
  result.rigid_angle = 0;
  double scale = d.scale;
  for (Eigen::Index h = 0; h < handle_positions.rows(); ++h)
    scale = std::max({scale, std::abs(handle_positions(h, 0)), std::abs(handle_positions(h, 1))});

  // Best rigid motion (and similarity, to start from) fitting the handles and link offsets.
  Cplx zbar = 0, pbar = 0;
  double wsum = 0;
  auto weight = [](double w) { return w == kInf ? 1.0 : std::min(w, 1.0); };
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    const double w = weight(d.handle_weights[h]);
    zbar += w * d.z[d.handles[h]];
    pbar += w * C(handle_positions, h);
    wsum += w;
  }
  if (wsum > 0) zbar /= wsum, pbar /= wsum;
  Cplx cross = 0;
  double zz = 0;
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    const double w = weight(d.handle_weights[h]);
    const Cplx dz = d.z[d.handles[h]] - zbar;
    cross += w * std::conj(dz) * (C(handle_positions, h) - pbar);
    zz += w * std::norm(dz);
  }
  for (Eigen::Index l = 0; l < d.links.rows(); ++l) {
    const double w = weight(d.link_weights[l]);
    const Cplx dz = d.z[d.links(l, 0)] - d.z[d.links(l, 1)];
    cross += w * std::conj(dz) * C(link_offsets, l);
    zz += w * std::norm(dz);
  }
  const Cplx rot = std::abs(cross) > 0 ? cross / std::abs(cross) : Cplx(1.0);
  const Cplx sim = zz > 0 && std::abs(cross) > 0 ? cross / zz : Cplx(1.0);

  // Constraints one rigid motion meets are met by exactly that motion.
  if (wsum > 0) {
    const Cplx shift = pbar - rot * zbar;
    const double tol = kRigidTolerance * scale;
    bool rigid = !(d.has_translate && rot != Cplx(1.0));
    for (Eigen::Index h = 0; rigid && h < d.handles.size(); ++h)
      if (d.handle_weights[h] > 0) rigid = std::abs(rot * d.z[d.handles[h]] + shift - C(handle_positions, h)) <= tol;
    for (Eigen::Index l = 0; rigid && l < d.links.rows(); ++l)
      if (d.link_weights[l] > 0)
        rigid = std::abs(rot * (d.z[d.links(l, 0)] - d.z[d.links(l, 1)]) - C(link_offsets, l)) <= tol;
    if (rigid) {
      result.positions.resize(n, 2);
      for (int v = 0; v < n; ++v) {
        const Cplx x = rot * d.z[v] + shift;
        result.positions.row(v) << x.real(), x.imag();
      }
      result.shape = result.positions;
      result.rigid_motion = true;
      result.rigid_angle = std::arg(rot);
      for (int r = 0; r < nr; ++r)
        result.rigid_angles[r] = d.rigid[r].mode == RigidMode::kRotate ? result.rigid_angle : 0.0;
      result.step1 = result.step2 = StepInfo{"rigid", 0, 0, 0};
      return;
    }
  }

  // Step 1: shape.
  std::vector<Cplx> x1;
  if (d.responses) {
    if (!d.elim1.extra_ties.empty() || !d.elim1.extra_handles.empty()) {
      std::vector<LCplx> beta;
      auto offset = [&](int t) -> LCplx {
        const Tie& tie = d.elim1.ties[t];
        return tie.kind == TieKind::kLink ? LCplx(C(link_offsets, tie.index)) : tie.rest;
      };
      ComputeBeta(d, d.elim1, handle_positions, offset, beta);
      CheckConsistency(d, d.elim1, handle_positions, offset, beta);
    }
    // x1 = base + sum of each response times its handle position or link offset, in one pass.
    std::vector<const Cplx*> resp;
    std::vector<Cplx> value;
    for (Eigen::Index h = 0; h < d.handles.size(); ++h)
      if (C(handle_positions, h) != Cplx(0.0)) resp.push_back(d.handle_response[h].data()), value.push_back(C(handle_positions, h));
    for (Eigen::Index l = 0; l < d.links.rows(); ++l)
      if (C(link_offsets, l) != Cplx(0.0)) resp.push_back(d.link_response[l].data()), value.push_back(C(link_offsets, l));
    x1.resize(n);
    const size_t m = resp.size();
    for (int i = 0; i < n; ++i) {
      Cplx acc = d.response_base[i];
      for (size_t k = 0; k < m; ++k) acc += resp[k][i] * value[k];
      x1[i] = acc;
    }
    result.step1 = d.response_info;
    result.step1.solver += " (precomputed responses)";
  } else {
    const Cplx sim_shift = wsum > 0 ? pbar - sim * zbar : Cplx(0.0);
    SolveShape(d, handle_positions, link_offsets, sim, sim_shift, scale, true, x1, result.step1);
  }

  // Rotation of each rotating range: its step-1 similarity, or (when it is too small to
  // carry one) the step-1 turn of the edges entering and leaving it.
  std::vector<LCplx> range_rot(nr, 1.0L);
  for (int r = 0; r < nr; ++r) {
    if (d.rigid[r].mode != RigidMode::kRotate) continue;
    LCplx q = 0;
    if (!d.degenerate[r]) {
      q = (LCplx(x1[d.master2[r]]) - LCplx(x1[d.master1[r]])) / (d.zl(d.master2[r]) - d.zl(d.master1[r]));
    } else {
      for (int e : d.boundary_edges[r]) {
        const int j = d.edges(e, 0), k = d.edges(e, 1);
        q += (LCplx(x1[k]) - LCplx(x1[j])) * std::conj(d.zl(k) - d.zl(j));
      }
    }
    const long double len = std::sqrt(std::norm(q));
    range_rot[r] = len > 0 ? q / len : LCplx(1.0L);
    result.rigid_angles[r] = std::atan2(static_cast<double>(range_rot[r].imag()), static_cast<double>(range_rot[r].real()));
  }

  // Step 2: each edge keeps its rest length along its step-1 direction.
  std::vector<Cplx> edge_targets(d.edges.rows());
  for (Eigen::Index e = 0; e < d.edges.rows(); ++e) {
    const int j = d.edges(e, 0), k = d.edges(e, 1);
    const Cplx dir = x1[k] - x1[j];
    const double dl = std::sqrt(std::norm(dir));
    edge_targets[e] = dl > 0 ? dir * (d.edge_length[e] / dl) : d.z[k] - d.z[j];
  }
  auto offset2 = [&](int t) -> LCplx {
    const Tie& tie = d.elim2.ties[t];
    switch (tie.kind) {
      case TieKind::kLink: return LCplx(C(link_offsets, tie.index));
      case TieKind::kRest: return tie.rest;
      case TieKind::kRotated: return range_rot[tie.index] * tie.rest;
    }
    return tie.rest;
  };
  std::vector<Cplx> x2;
  Solve(d, d.elim2, d.rows2, d.step2, handle_positions, link_offsets, offset2, edge_targets, true, scale,
        Start(d.elim2, d.z, 1.0, 0.0, &x1), x2, result.step2);

  // std::complex<double> is two doubles, real first: the same layout as a row of Trajectory2.
  using Rows2 = Eigen::Map<const Trajectory2>;
  result.positions = Rows2(reinterpret_cast<const double*>(x2.data()), n, 2);
  result.shape = Rows2(reinterpret_cast<const double*>(x1.data()), n, 2);
}

std::pair<double, double> PathEditConditionEstimate(const PathEditData& d) {
  return {d.step1.condition, d.step2.condition};
}

}  // namespace mocapedit
