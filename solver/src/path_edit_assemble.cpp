// Assembly of the eliminated rows and their normal matrix (path_edit_internal.h).
#include "path_edit_internal.h"

#include <numeric>

namespace mocapedit::detail {
namespace {

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

// The eliminated rows A, CSR, in double precision and their rounding errors (a_low).
template <typename Scalar>
void AssembleRows(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s) {
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
        if (m == kMax) throw SolverError("PathEdit: internal error, a row with too many unknowns");
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
}

// Gershgorin's bound on the largest eigenvalue of a Hermitian matrix given by its lower
// triangle: the largest row sum, each entry counted as |re| + |im| (>= its modulus).
template <typename Sparse>
double GershgorinOfNormal(const Sparse& m) {
  const int n = static_cast<int>(m.cols());
  const int* outer = m.outerIndexPtr();
  const int* inner = m.innerIndexPtr();
  const auto* values = m.valuePtr();
  double lmax = 0;
  std::vector<double> rowsum(n, 0.0);
  for (int j = 0; j < n; ++j)
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      const double a = std::abs(std::real(values[p])) + std::abs(std::imag(values[p]));
      rowsum[j] += a;
      if (inner[p] != j) rowsum[inner[p]] += a;
    }
  for (double r : rowsum) lmax = std::max(lmax, r);
  return lmax;
}

// The lower triangle of A^H A, by Gustavson's column-by-column product.
template <typename Scalar>
void AssembleNormal(StepSystem<Scalar>& s) {
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
  s.gershgorin = GershgorinOfNormal(s.normal);
}

}  // namespace

template <typename Scalar>
void AssembleStep(const Rows& rows, const Elimination& e, StepSystem<Scalar>& s) {
  AssembleRows(rows, e, s);
  if (AssembleSkyline(s)) return;
  AssembleNormal(s);
}

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

template void AssembleStep(const Rows&, const Elimination&, StepSystem<Cplx>&);
template void AssembleStep(const Rows&, const Elimination&, StepSystem<double>&);
template void FindBetaRows(const Rows&, const Elimination&, StepSystem<Cplx>&);
template void FindBetaRows(const Rows&, const Elimination&, StepSystem<double>&);

}  // namespace mocapedit::detail
