#include "mocapedit/skyline_ldlt.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <complex>
#include <random>

using mocapedit::SkylineLdlt;
using Cplx = std::complex<double>;

namespace {

// A random Hermitian positive definite matrix whose lower triangle lies in the envelope
// `first`, every envelope entry nonzero (so a wrong index shows).
template <typename Scalar>
Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> Random(const std::vector<int>& first, unsigned seed) {
  const int n = static_cast<int>(first.size());
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> a = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>::Zero(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = first[i]; j < i; ++j) {
      Scalar v;
      if constexpr (std::is_same<Scalar, Cplx>::value)
        v = Cplx(u(rng), u(rng));
      else
        v = u(rng);
      a(i, j) = v;
      a(j, i) = Eigen::numext::conj(v);
    }
  // Diagonally dominant: positive definite.
  for (int i = 0; i < n; ++i) a(i, i) = 1.0 + a.row(i).cwiseAbs().sum();
  return a;
}

// The lower triangle of `a` in the envelope `first`, each entry added in two pieces, as
// assembly does.
template <typename Scalar, typename Matrix>
void Load(SkylineLdlt<Scalar>& f, const std::vector<int>& first, const Matrix& a) {
  f.Reset(first);
  for (int i = 0; i < static_cast<int>(first.size()); ++i)
    for (int j = first[i]; j <= i; ++j) {
      f.Add(i, j, a(i, j) * 0.25);
      f.Add(i, j, a(i, j) * 0.75);
    }
}

// A random matrix in the envelope `first` (as Random), loaded into f (not yet factored).
template <typename Scalar>
Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> LoadRandom(SkylineLdlt<Scalar>& f, const std::vector<int>& first,
                                                                 unsigned seed) {
  const auto a = Random<Scalar>(first, seed);
  Load(f, first, a);
  return a;
}

template <typename Scalar>
void CheckAgainstDense(const std::vector<int>& first, unsigned seed) {
  const int n = static_cast<int>(first.size());
  SkylineLdlt<Scalar> f;
  const auto a = LoadRandom(f, first, seed);
  const double rowsum = a.cwiseAbs().rowwise().sum().maxCoeff();
  EXPECT_GE(f.GershgorinBound(), rowsum * (1 - 1e-12));
  EXPECT_LE(f.GershgorinBound(), rowsum * std::sqrt(2.0));
  ASSERT_TRUE(f.Factor());
  // Two interleaved right-hand sides.
  Eigen::Matrix<Scalar, Eigen::Dynamic, 2> b = Eigen::Matrix<Scalar, Eigen::Dynamic, 2>::Random(n, 2);
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> x = b;
  f.Solve(x.data(), 2);
  const Eigen::Matrix<Scalar, Eigen::Dynamic, 2> expected = a.ldlt().solve(b);
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-12) << "n=" << n;
}

}  // namespace

TEST(SkylineLdlt, BandMatchesDenseSolve) {
  for (int bw : {0, 1, 2, 5}) {
    std::vector<int> first(40);
    for (int i = 0; i < 40; ++i) first[i] = std::max(0, i - bw);
    CheckAgainstDense<double>(first, 1 + bw);
    CheckAgainstDense<Cplx>(first, 11 + bw);
  }
}

TEST(SkylineLdlt, ChainWithLongRangeTermsMatchesDenseSolve) {
  // Three blocks of a chain, each row's envelope two back, plus a term between each block's
  // first and last row (the shape of a relay of agents with gauge links).
  std::vector<int> first(60);
  for (int i = 0; i < 60; ++i) first[i] = std::max(0, i - 2);
  first[19] = 0;
  first[39] = 19;
  first[59] = 39;
  first[25] = 24;  // a row narrower than its neighbours
  CheckAgainstDense<double>(first, 3);
  CheckAgainstDense<Cplx>(first, 4);
}

TEST(SkylineLdlt, RealMatrixSolvesComplexRightHandSides) {
  std::vector<int> first(30);
  for (int i = 0; i < 30; ++i) first[i] = std::max(0, i - 3);
  const auto a = Random<double>(first, 7);
  SkylineLdlt<double> f;
  f.Reset(first);
  for (int i = 0; i < 30; ++i)
    for (int j = first[i]; j <= i; ++j) f.Add(i, j, a(i, j));
  ASSERT_TRUE(f.Factor());
  Eigen::VectorXcd b = Eigen::VectorXcd::Random(30), x = b;
  f.Solve(x.data(), 1);
  EXPECT_LT((a.cast<Cplx>() * x - b).cwiseAbs().maxCoeff(), 1e-12);
  // Three interleaved right-hand sides (the general path).
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> b3 = Eigen::Matrix<double, Eigen::Dynamic, 3>::Random(30, 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> x3 = b3;
  f.Solve(x3.data(), 3);
  EXPECT_LT((a * x3 - b3).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(SkylineLdlt, CostAndProfileCountTheEnvelope) {
  std::vector<int> first{0, 0, 1, 0};
  SkylineLdlt<double> f;
  f.Reset(first);
  EXPECT_EQ(f.Profile(), 0 + 1 + 1 + 3);
  // Row 1: j=0 -> 1. Row 2: j=1 -> 1 + (1 - max(1, 0)) = 1. Row 3: j=0 -> 1, j=1 -> 1 + 1,
  // j=2 -> 1 + (2 - 1) = 2. Plus one per row.
  EXPECT_EQ(SkylineLdlt<double>::FactorCost(first), 1 + 1 + 1 + 2 + 2 + 4);
}

TEST(SkylineLdlt, IndefiniteOrSingularMatricesAreRefused) {
  SkylineLdlt<double> f;
  f.Reset({0, 0});
  f.Add(0, 0, 1.0);
  f.Add(1, 0, 1.0);
  f.Add(1, 1, 1.0);  // [[1, 1], [1, 1]]: singular
  EXPECT_FALSE(f.Factor());
  f.Reset({0, 0});
  f.Add(0, 0, 1.0);
  f.Add(1, 0, 2.0);
  f.Add(1, 1, 1.0);  // indefinite
  EXPECT_FALSE(f.Factor());
}

// Columns of the inverse by SolveFrom: exact from row `last` on, for bands and envelopes,
// real and complex.
template <typename Scalar>
void CheckInverseColumns(const std::vector<int>& first, unsigned seed) {
  const int n = static_cast<int>(first.size());
  SkylineLdlt<Scalar> f;
  const auto a = LoadRandom(f, first, seed);
  ASSERT_TRUE(f.Factor());
  const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> inverse = a.inverse();
  for (int column : {0, n / 3, n - 1})
    for (int last : {0, column / 2, column}) {
      std::vector<Cplx> x(static_cast<size_t>(n), Cplx(0.0));
      x[column] = 1.0;
      f.SolveFrom(x.data(), column, last);
      for (int i = last; i < n; ++i)
        EXPECT_LT(std::abs(x[i] - Cplx(inverse(i, column))), 1e-12)
            << "n=" << n << " column " << column << " last " << last << " row " << i;
    }
}

TEST(SkylineLdlt, InverseColumnsFromTheirUnitEntry) {
  for (int band : {1, 2, 4}) {
    std::vector<int> first(40);
    for (int i = 0; i < 40; ++i) first[i] = std::max(0, i - band);
    CheckInverseColumns<double>(first, 11 + band);
    CheckInverseColumns<Cplx>(first, 17 + band);
  }
  std::vector<int> envelope(30);
  for (int i = 0; i < 30; ++i) envelope[i] = i == 29 ? 0 : std::max(0, i - 2);  // one long row
  CheckInverseColumns<double>(envelope, 5);
  CheckInverseColumns<Cplx>(envelope, 6);
}
