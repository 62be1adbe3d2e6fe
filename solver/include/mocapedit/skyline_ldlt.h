// LDL^H factorization of a Hermitian (or real symmetric) positive definite matrix stored by
// its envelope ("skyline"): row i keeps the entries of columns first(i)..i-1 of its lower
// triangle, and the factor's rows fill exactly that envelope (no fill outside it). A band
// matrix is the special case first(i) = i - bandwidth; a chain with a few long-range terms
// (agents tied end to start, each with one term between its first and last frame) has a
// small envelope too, although its bandwidth is large.
//
// Use: Reset(first) with the envelope, Add(i, j, value) the lower-triangle entries (they
// accumulate), Factor(), then Solve as often as needed. Work and storage grow with the
// envelope, so callers check Profile() / FactorCost() and use a sparse factorization with a
// fill-reducing order when the envelope is large.
#pragma once

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

namespace mocapedit {

template <typename Scalar>  // double or std::complex<double>
class SkylineLdlt {
 public:
  // first  #N first column of each row's envelope (first[i] <= i; first[i] == i: the row
  //        has only its diagonal). Clears all values.
  void Reset(const std::vector<int>& first) {
    const int n = static_cast<int>(first.size());
    first_ = first;
    ptr_.assign(static_cast<size_t>(n) + 1, 0);
    for (int i = 0; i < n; ++i) ptr_[i + 1] = ptr_[i] + (i - first_[i]);
    val_.assign(static_cast<size_t>(ptr_[n]), Scalar(0));
    d_.assign(static_cast<size_t>(n), 0.0);
    ok_ = false;
  }

  // Number of stored off-diagonal entries (the envelope's size).
  int64_t Profile() const { return ptr_.empty() ? 0 : ptr_.back(); }

  // Multiply-adds of Factor() for the envelope `first` (one pass over it).
  static int64_t FactorCost(const std::vector<int>& first) {
    int64_t cost = 0;
    for (int i = 0; i < static_cast<int>(first.size()); ++i)
      for (int j = first[i]; j < i; ++j) cost += 1 + (j - std::max(first[i], first[j]));
    return cost + static_cast<int64_t>(first.size());
  }

  int size() const { return static_cast<int>(first_.size()); }

  // Adds `value` to entry (i, j) of the lower triangle, first(i) <= j <= i. The diagonal
  // is real: only the real part of a diagonal value is kept.
  void Add(int i, int j, const Scalar& value) {
    if (i == j)
      d_[i] += std::real(value);
    else
      val_[static_cast<size_t>(ptr_[i] + (j - first_[i]))] += value;
  }

  // Gershgorin bound on the largest eigenvalue: the largest row sum of the full (Hermitian)
  // matrix, each entry counted as |re| + |im| (>= its modulus). Call before Factor().
  double GershgorinBound() const {
    const int n = size();
    std::vector<double> sum(d_.begin(), d_.end());
    for (int i = 0; i < n; ++i) {
      for (int64_t p = ptr_[i]; p < ptr_[i + 1]; ++p) {
        const double a = std::abs(std::real(val_[p])) + std::abs(std::imag(val_[p]));
        sum[i] += a;
        sum[first_[i] + (p - ptr_[i])] += a;
      }
    }
    double m = 0;
    for (double s : sum) m = std::max(m, std::abs(s));
    return m;
  }

  // Factors in place. Returns false when a pivot is not positive (the matrix is not
  // positive definite to working precision); the factor is then unusable.
  bool Factor() {
    const int n = size();
    ok_ = false;
    Scalar* val = val_.data();
    for (int i = 0; i < n; ++i) {
      const int fi = first_[i];
      Scalar* li = val + ptr_[i] - fi;  // li[k]: entry (i, k), k in [fi, i)
      // w_ij = a_ij - sum_{k<j} w_ik conj(l_jk), with w_ik = l_ik d_k for k < j.
      for (int j = fi; j < i; ++j) {
        const int k0 = std::max(fi, first_[j]);
        const Scalar* lj = val + ptr_[j] - first_[j];
        li[j] -= Dot(li + k0, lj + k0, j - k0);
      }
      // d_i = a_ii - sum_k |w_ik|^2 / d_k, then l_ik = w_ik / d_k.
      double di = d_[i];
      for (int k = fi; k < i; ++k) {
        const Scalar w = li[k];
        const double inv = 1.0 / d_[k];
        di -= Norm(w) * inv;
        li[k] = w * inv;
      }
      if (!(di > 0) || !std::isfinite(di)) return false;
      d_[i] = di;
    }
    ok_ = true;
    return true;
  }

  // Diagonal of D after Factor().
  const std::vector<double>& D() const { return d_; }

  // Solves (L D L^H) x = b in place for `k` right-hand sides stored interleaved:
  // x[i * k + c] is entry i of right-hand side c. T: Scalar, or std::complex<double> when
  // Scalar is double (a real matrix applied to complex right-hand sides).
  template <typename T>
  void Solve(T* x, int k) const {
    if (k == 1)
      SolveK<T, 1>(x);
    else if (k == 2)
      SolveK<T, 2>(x);
    else
      for (int c = 0; c < k; ++c) SolveStrided(x + c, k);
  }

  // One right-hand side whose entries above `first` are zero (a unit vector e_first, for a
  // column of the inverse): the forward pass starts at `first`, and the backward pass stops
  // at `last` (<= first), leaving the entries above `last` undone. T as for Solve.
  template <typename T>
  void SolveFrom(T* x, int first, int last) const {
    const int n = size();
    const Scalar* val = val_.data();
    for (int i = first; i < n; ++i) {  // L y = b
      const int p0 = std::max(first_[i], first);
      const Scalar* li = val + ptr_[i] - first_[i];  // li[p]: entry (i, p)
      T s = x[i];
      for (int p = p0; p < i; ++p) s -= li[p] * x[p];
      x[i] = s;
    }
    for (int i = first; i < n; ++i) x[i] /= d_[i];  // D
    for (int i = n - 1; i >= last; --i) {  // L^H x = y, rows from `last` on
      const Scalar* li = val + ptr_[i] - first_[i];
      const T xi = x[i];
      for (int p = std::max(first_[i], last); p < i; ++p) x[p] -= Conj(li[p]) * xi;
    }
  }

  // SolveFrom for K right-hand sides at once, interleaved as for Solve (x[i * K + c] is entry
  // i of right-hand side c), right-hand side c zero above firsts[c]; the backward pass stops
  // at `last` for all. Entries of right-hand side c from min(firsts[c], last_c) on, for any
  // last_c >= last, are bit for bit those SolveFrom(x_c, firsts[c], last_c) gives: the products the shared passes add above an entry's first row
  // multiply zeros, and the backward pass never carries what it does below last_c upwards.
  // K independent recurrences run side by side (the one-column passes wait on each product).
  template <typename T, int K>
  void SolveFromBatch(T* x, const int* firsts, int last) const {
    const int n = size();
    int first = firsts[0];
    for (int c = 1; c < K; ++c) first = std::min(first, firsts[c]);
    const Scalar* val = val_.data();
    for (int i = first; i < n; ++i) {  // L y = b
      const int p0 = std::max(first_[i], first);
      const Scalar* li = val + ptr_[i] - first_[i];
      T s[K];
      for (int c = 0; c < K; ++c) s[c] = x[static_cast<size_t>(i) * K + c];
      for (int p = p0; p < i; ++p) {
        const Scalar l = li[p];
        for (int c = 0; c < K; ++c) s[c] -= l * x[static_cast<size_t>(p) * K + c];
      }
      for (int c = 0; c < K; ++c) x[static_cast<size_t>(i) * K + c] = s[c];
    }
    for (int i = first; i < n; ++i)  // D
      for (int c = 0; c < K; ++c) x[static_cast<size_t>(i) * K + c] /= d_[i];
    for (int i = n - 1; i >= last; --i) {  // L^H x = y, rows from `last` on
      const Scalar* li = val + ptr_[i] - first_[i];
      T xi[K];
      for (int c = 0; c < K; ++c) xi[c] = x[static_cast<size_t>(i) * K + c];
      for (int p = std::max(first_[i], last); p < i; ++p) {
        const Scalar l = Conj(li[p]);
        for (int c = 0; c < K; ++c) x[static_cast<size_t>(p) * K + c] -= l * xi[c];
      }
    }
  }

 private:
  // K right-hand sides, interleaved (K known at compile time).
  template <typename T, int K>
  void SolveK(T* x) const {
    const int n = size();
    const Scalar* val = val_.data();
    for (int i = 0; i < n; ++i) {  // L y = b, row by row
      const Scalar* li = val + ptr_[i];
      const int m = i - first_[i];
      const T* y = x + static_cast<size_t>(first_[i]) * K;
      T s[K];
      for (int c = 0; c < K; ++c) s[c] = x[static_cast<size_t>(i) * K + c];
      if (m == 1) {  // chains: most rows hold one entry left of the diagonal
        for (int c = 0; c < K; ++c) s[c] -= li[0] * y[c];
      } else {
        for (int p = 0; p < m; ++p)
          for (int c = 0; c < K; ++c) s[c] -= li[p] * y[p * K + c];
      }
      for (int c = 0; c < K; ++c) x[static_cast<size_t>(i) * K + c] = s[c];
    }
    for (int i = 0; i < n; ++i) {  // D
      const double inv = 1.0 / d_[i];
      for (int c = 0; c < K; ++c) x[static_cast<size_t>(i) * K + c] *= inv;
    }
    for (int i = n - 1; i >= 0; --i) {  // L^H x = y: column i of L^H is row i of L
      const Scalar* li = val + ptr_[i];
      const int m = i - first_[i];
      T* y = x + static_cast<size_t>(first_[i]) * K;
      T xi[K];
      for (int c = 0; c < K; ++c) xi[c] = x[static_cast<size_t>(i) * K + c];
      if (m == 1) {
        const Scalar l = Conj(li[0]);
        for (int c = 0; c < K; ++c) y[c] -= l * xi[c];
      } else {
        for (int p = 0; p < m; ++p) {
          const Scalar l = Conj(li[p]);
          for (int c = 0; c < K; ++c) y[p * K + c] -= l * xi[c];
        }
      }
    }
  }
  // One right-hand side at stride k.
  template <typename T>
  void SolveStrided(T* x, int k) const {
    const int n = size();
    auto at = [&](int i) -> T& { return x[static_cast<size_t>(i) * k]; };
    for (int i = 0; i < n; ++i) {
      const Scalar* li = val_.data() + ptr_[i];
      T s = at(i);
      for (int p = 0; p < i - first_[i]; ++p) s -= li[p] * at(first_[i] + p);
      at(i) = s;
    }
    for (int i = 0; i < n; ++i) at(i) /= d_[i];
    for (int i = n - 1; i >= 0; --i) {
      const Scalar* li = val_.data() + ptr_[i];
      for (int p = 0; p < i - first_[i]; ++p) at(first_[i] + p) -= Conj(li[p]) * at(i);
    }
  }

  static double Norm(double a) { return a * a; }
  static double Norm(const std::complex<double>& a) { return a.real() * a.real() + a.imag() * a.imag(); }
  static double Conj(double a) { return a; }
  static std::complex<double> Conj(const std::complex<double>& a) { return std::conj(a); }
  // sum_p a[p] conj(b[p])
  static double Dot(const double* a, const double* b, int m) {
    double s0 = 0, s1 = 0;
    int p = 0;
    for (; p + 1 < m; p += 2) s0 += a[p] * b[p], s1 += a[p + 1] * b[p + 1];
    if (p < m) s0 += a[p] * b[p];
    return s0 + s1;
  }
  static std::complex<double> Dot(const std::complex<double>* a, const std::complex<double>* b, int m) {
    double re = 0, im = 0;
    const double* x = reinterpret_cast<const double*>(a);
    const double* y = reinterpret_cast<const double*>(b);
    for (int p = 0; p < m; ++p) {
      const double ar = x[2 * p], ai = x[2 * p + 1], br = y[2 * p], bi = y[2 * p + 1];
      re += ar * br + ai * bi;
      im += ai * br - ar * bi;
    }
    return {re, im};
  }

  std::vector<int> first_;
  std::vector<int64_t> ptr_;
  std::vector<Scalar> val_;
  std::vector<double> d_;
  bool ok_ = false;
};

}  // namespace mocapedit
