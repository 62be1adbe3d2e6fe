// Orders and factorizations of the steps' normal matrices (path_edit_internal.h).
#include "path_edit_internal.h"
#include <amd.h>
#include <camd.h>

#include <numeric>

#include "mocapedit/nested_dissection.h"
#include "mocapedit/two_threads.h"

namespace mocapedit::detail {
namespace {

// Per column of a step's unknowns (cols x 3, row-major): the rest position of one of its
// vertices relative to the centroid of the vertices at that vertex's time, and the time.
// Empty without vertex times. Large factorizations are ordered by splitting along these
// (nested_dissection.h): a group is a formation (position about its centroid) by time.
std::vector<double> ColumnCoordinates(const PathEditState& d, const Elimination& e) {
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

}  // namespace

// The orders of a step's normal matrix for the supernodal factorization to choose from:
// with vertex times, CAMD within a nested dissection by position and time, and AMD (whose
// order fills less on some meshes: long thin ones, and wide short ones where the
// formation's cross-section makes every separator large). Both on two threads when
// `two_threads`.
// None when the system is small, banded (skyline) or without times: Factor then asks
// CHOLMOD for its AMD order.
template <typename Scalar>
CandidateOrders OrderCandidates(const StepSystem<Scalar>& s, const PathEditState& d, const Elimination& e,
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

namespace {

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

}  // namespace

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
    // CHOLMOD's analysis (its AMD is faster than Eigen's) tells whether the
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

template CandidateOrders OrderCandidates(const StepSystem<Cplx>&, const PathEditState&, const Elimination&, bool);
template CandidateOrders OrderCandidates(const StepSystem<double>&, const PathEditState&, const Elimination&, bool);
template void Factor(StepSystem<Cplx>&, const CandidateOrders&, bool);
template void Factor(StepSystem<double>&, const CandidateOrders&, bool);

}  // namespace mocapedit::detail
