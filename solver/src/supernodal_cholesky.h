// CHOLMOD's supernodal Cholesky of a sparse Hermitian (or real symmetric) matrix given by
// its lower triangle, in a given or CHOLMOD's AMD order (internal).
#pragma once

#include <Eigen/Sparse>
#include <cholmod.h>

#include <complex>
#include <type_traits>
#include <vector>

#include "mocapedit/errors.h"

namespace mocapedit::detail {

// Fill-reducing orders of a normal matrix to choose from (empty when not computed), each
// with AMD's or CAMD's count of its factorization's multiply-subtracts.
struct CandidateOrders {
  std::vector<int> dissection;  // CAMD within a nested dissection's sets
  std::vector<int> amd;
  double dissection_flops = std::numeric_limits<double>::infinity();
  double amd_flops = std::numeric_limits<double>::infinity();
};

template <typename Scalar>
class SupernodalCholesky {
 public:
  using Sparse = Eigen::SparseMatrix<Scalar, Eigen::ColMajor, int>;
  static constexpr int kXtype = std::is_same<Scalar, std::complex<double>>::value ? CHOLMOD_COMPLEX : CHOLMOD_REAL;

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
      throw NumericalError("PathEdit", "CHOLMOD solve failed");
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

}  // namespace mocapedit::detail
