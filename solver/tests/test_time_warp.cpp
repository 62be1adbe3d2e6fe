#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>

#include "mocapedit/time_warp.h"

using mocapedit::Flags;
using mocapedit::TimeWarpConflict;
using mocapedit::TimeWarpProblem;
using mocapedit::TimeWarpResult;

namespace {

Eigen::VectorXd Range(int n, double start = 0.0, double step = 1.0) {
  return Eigen::VectorXd::LinSpaced(n, start, start + step * (n - 1));
}

struct Builder {
  TimeWarpProblem p;
  std::vector<double> times, offsets;
  explicit Builder(std::vector<Eigen::VectorXd> rest) { p.rest_times = std::move(rest); }
  Builder& Time(int agent, int frame, double time, bool hard = true, double weight = 1.0) {
    const auto k = p.time_frames.rows();
    p.time_frames.conservativeResize(k + 1, 2);
    p.time_frames.row(k) << agent, frame;
    p.time_hard.conservativeResize(k + 1);
    p.time_hard[k] = hard;
    p.time_weights.conservativeResize(k + 1);
    p.time_weights[k] = weight;
    times.push_back(time);
    return *this;
  }
  Builder& Sync(int agent, int frame, int target, int target_frame, double offset, bool hard = true,
                double weight = 1.0) {
    const auto k = p.sync_frames.rows();
    p.sync_frames.conservativeResize(k + 1, 4);
    p.sync_frames.row(k) << agent, frame, target, target_frame;
    p.sync_hard.conservativeResize(k + 1);
    p.sync_hard[k] = hard;
    p.sync_weights.conservativeResize(k + 1);
    p.sync_weights[k] = weight;
    offsets.push_back(offset);
    return *this;
  }
  Eigen::VectorXd Times() const { return Eigen::Map<const Eigen::VectorXd>(times.data(), times.size()); }
  Eigen::VectorXd Offsets() const { return Eigen::Map<const Eigen::VectorXd>(offsets.data(), offsets.size()); }
  TimeWarpResult Solve() const {
    TimeWarpResult r;
    mocapedit::TimeWarp(p, Times(), Offsets(), r);
    return r;
  }
};

TimeWarpResult SolveWith(const mocapedit::TimeWarpData& data, const Eigen::VectorXd& times,
                         const Eigen::VectorXd& offsets) {
  TimeWarpResult r;
  mocapedit::TimeWarpSolve(data, times, offsets, r);
  return r;
}

Eigen::VectorXd Intervals(const Eigen::VectorXd& t) { return t.tail(t.size() - 1) - t.head(t.size() - 1); }

void ExpectIncreasingAboveMinimum(const TimeWarpProblem& p, const TimeWarpResult& r) {
  for (size_t a = 0; a < p.rest_times.size(); ++a) {
    const Eigen::VectorXd d = Intervals(r.time_maps[a]);
    const Eigen::VectorXd rest = Intervals(p.rest_times[a]);
    for (Eigen::Index i = 0; i < d.size(); ++i)
      EXPECT_GE(d[i], p.min_interval_fraction * rest[i] - 1e-9) << "agent " << a << " interval " << i;
  }
}

// The energy the warp minimises, for one agent (no syncs), written out plainly.
double Energy(const TimeWarpProblem& p, const Eigen::VectorXd& times, const Eigen::VectorXd& t) {
  const Eigen::VectorXd& s = p.rest_times[0];
  const Eigen::VectorXd d = Intervals(t), ds = Intervals(s);
  double e = 0.0;
  for (Eigen::Index i = 1; i < d.size(); ++i) e += std::pow((ds[i] - ds[i - 1]) - (d[i] - d[i - 1]), 2);
  e += p.stretch_weight * (d - ds).squaredNorm();
  for (Eigen::Index k = 0; k < times.size(); ++k)
    if (!p.time_hard[k]) e += p.time_weights[k] * std::pow(t[p.time_frames(k, 1)] - times[k], 2);
  return e;
}

// The bounded optimum by brute force: every subset of intervals held at the minimum,
// solved densely with the hard constraints as Lagrange equalities; the best feasible wins.
Eigen::VectorXd BruteForce(const TimeWarpProblem& p, const Eigen::VectorXd& times) {
  const Eigen::VectorXd& s = p.rest_times[0];
  const int n = static_cast<int>(s.size());
  const double ws = std::sqrt(p.stretch_weight);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(2 * n + times.size(), n);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(a.rows());
  int row = 0;
  for (int i = 1; i + 1 < n; ++i, ++row) {
    a(row, i - 1) = 1, a(row, i) = -2, a(row, i + 1) = 1;
    b[row] = s[i - 1] - 2 * s[i] + s[i + 1];
  }
  for (int i = 0; i + 1 < n; ++i, ++row) {
    a(row, i) = -ws, a(row, i + 1) = ws;
    b[row] = ws * (s[i + 1] - s[i]);
  }
  for (Eigen::Index k = 0; k < times.size(); ++k)
    if (!p.time_hard[k]) {
      a(row, p.time_frames(k, 1)) = std::sqrt(p.time_weights[k]);
      b[row++] = std::sqrt(p.time_weights[k]) * times[k];
    }
  const Eigen::MatrixXd h = a.topRows(row).transpose() * a.topRows(row);
  const Eigen::VectorXd g = a.topRows(row).transpose() * b.head(row);
  Eigen::VectorXd best;
  double best_energy = std::numeric_limits<double>::infinity();
  for (int mask = 0; mask < (1 << (n - 1)); ++mask) {
    std::vector<std::pair<Eigen::VectorXd, double>> eq;
    for (Eigen::Index k = 0; k < times.size(); ++k)
      if (p.time_hard[k]) {
        Eigen::VectorXd c = Eigen::VectorXd::Zero(n);
        c[p.time_frames(k, 1)] = 1;
        eq.push_back({c, times[k]});
      }
    for (int i = 0; i + 1 < n; ++i)
      if (mask & (1 << i)) {
        Eigen::VectorXd c = Eigen::VectorXd::Zero(n);
        c[i] = -1, c[i + 1] = 1;
        eq.push_back({c, p.min_interval_fraction * (s[i + 1] - s[i])});
      }
    const int m = static_cast<int>(eq.size());
    Eigen::MatrixXd kkt = Eigen::MatrixXd::Zero(n + m, n + m);
    Eigen::VectorXd rhs(n + m);
    kkt.topLeftCorner(n, n) = h;
    rhs.head(n) = g;
    for (int j = 0; j < m; ++j) {
      kkt.block(0, n + j, n, 1) = eq[j].first;
      kkt.block(n + j, 0, 1, n) = eq[j].first.transpose();
      rhs[n + j] = eq[j].second;
    }
    Eigen::FullPivLU<Eigen::MatrixXd> lu(kkt);
    if (lu.rank() < n + m) continue;
    const Eigen::VectorXd t = lu.solve(rhs).head(n);
    bool ok = true;
    for (int i = 0; i + 1 < n; ++i) ok = ok && t[i + 1] - t[i] >= p.min_interval_fraction * (s[i + 1] - s[i]) - 1e-9;
    if (!ok) continue;
    const double e = Energy(p, times, t);
    if (e < best_energy) best_energy = e, best = t;
  }
  return best;
}

}  // namespace

TEST(TimeWarp, ValidityRejectsBadInput) {
  const Eigen::VectorXd one = Eigen::VectorXd::Constant(1, 5.0), none(0);
  {
    Builder b({Eigen::VectorXd(0)});
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // an agent without frames
  }
  {
    Eigen::VectorXd rest(3);
    rest << 0, 2, 1;
    Builder b({rest});
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // rest times that go back
  }
  {
    Builder b({Range(10)});
    b.Time(0, 10, 3.0);
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // frame outside the clip
  }
  {
    Builder b({Range(10)});
    b.Sync(0, 2, 1, 2, 0.0);
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // target agent that does not exist
  }
  {
    Builder b({Range(10)});
    b.Time(0, 2, 3.0, false, -1.0);
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // negative weight
  }
  {
    Builder b({Range(10)});
    b.Time(0, 2, 3.0);
    b.p.time_weights.resize(0);
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // weights of the wrong length
  }
  for (double fraction : {0.0, 1.5}) {
    Builder b({Range(10)});
    b.p.min_interval_fraction = fraction;
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);
  }
  {
    Builder b({Range(10)});
    b.p.anchor_weight = 0.0;
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);
  }
  {
    Builder b({Range(10)});
    b.p.min_intervals = {Range(3)};
    EXPECT_THROW(b.Solve(), mocapedit::InvalidInput);  // min intervals of the wrong length
  }
  {
    Builder b({Range(10)});
    b.Time(0, 2, 3.0);
    mocapedit::TimeWarpData data;
    mocapedit::TimeWarpPrecompute(b.p, data);
    EXPECT_THROW(SolveWith(data, none, none), mocapedit::InvalidInput);  // one time is missing
    Eigen::VectorXd nan = Eigen::VectorXd::Constant(1, std::nan(""));
    EXPECT_THROW(SolveWith(data, nan, none), mocapedit::InvalidInput);
    EXPECT_NO_THROW(SolveWith(data, one, none));
  }
}

TEST(TimeWarp, OneTimeConstraintShiftsWithoutStretching) {
  Eigen::VectorXd rest(6);
  rest << 0, 1, 3, 4, 4.5, 7;  // uneven samples keep their own intervals
  Builder b({rest, Range(240)});
  b.Time(0, 2, 10.25).Time(1, 100, 37.5);
  const TimeWarpResult r = b.Solve();
  EXPECT_LT((r.time_maps[0] - (rest.array() + 7.25).matrix()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((r.time_maps[1] - (Range(240).array() - 62.5).matrix()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(r.time_residuals.maxCoeff(), 0.0);  // a hard time is set, not solved for
  EXPECT_EQ(r.solver[0], "LDLT");
  EXPECT_EQ(r.component[0], 0);
  EXPECT_EQ(r.component[1], 1);
}

TEST(TimeWarp, TwoTimeConstraintsStretchSmoothlyBetweenThem) {
  Builder b({Range(100)});
  b.Time(0, 20, 20.0).Time(0, 60, 80.0);  // frames 20..60 play at 2/3 speed
  const TimeWarpResult r = b.Solve();
  EXPECT_LT(r.time_residuals.maxCoeff(), 1e-9);
  const Eigen::VectorXd d = Intervals(r.time_maps[0]);
  // With nothing else asked, the interval-change energy keeps the new speed throughout.
  EXPECT_NEAR(d.minCoeff(), 1.5, 1e-3);
  EXPECT_NEAR(d.maxCoeff(), 1.5, 1e-3);
  ExpectIncreasingAboveMinimum(b.p, r);
}

TEST(TimeWarp, ThreeBeatsAreHitExactlyAndSmoothly) {
  Builder b({Range(120)});
  b.Time(0, 20, 24.0).Time(0, 50, 48.0).Time(0, 90, 96.0);
  const TimeWarpResult r = b.Solve();
  EXPECT_LT(r.time_residuals.maxCoeff(), 1e-9);
  const Eigen::VectorXd d = Intervals(r.time_maps[0]);
  // Smooth: successive intervals change little.
  EXPECT_LT((d.tail(d.size() - 1) - d.head(d.size() - 1)).cwiseAbs().maxCoeff(), 0.02);
  ExpectIncreasingAboveMinimum(b.p, r);
  EXPECT_EQ(r.min_enforced[0], 0);
}

TEST(TimeWarp, SyncHoldsWhicheverAgentIsRetimed) {
  for (int retimed : {0, 1}) {
    Builder b({Range(60), Range(80, 5.0)});
    b.Sync(0, 30, 1, 40, 2.5);  // agent 0's frame 30 plays 2.5 after agent 1's frame 40
    b.Time(retimed, retimed == 0 ? 10 : 70, retimed == 0 ? 3.0 : 90.0);
    b.Time(retimed, retimed == 0 ? 50 : 20, retimed == 0 ? 70.0 : 20.0);
    const TimeWarpResult r = b.Solve();
    EXPECT_LT(r.sync_residuals[0], 1e-9) << "retimed " << retimed;
    EXPECT_NEAR(r.time_maps[0][30] - r.time_maps[1][40], 2.5, 1e-9);
    EXPECT_LT(r.time_residuals.maxCoeff(), 1e-9);
    EXPECT_EQ(r.component[0], r.component[1]);
    // The agent that is not retimed only shifts.
    const int other = 1 - retimed;
    const Eigen::VectorXd d = Intervals(r.time_maps[other]) - Intervals(b.p.rest_times[other]);
    EXPECT_LT(d.cwiseAbs().maxCoeff(), 1e-9);
    ExpectIncreasingAboveMinimum(b.p, r);
  }
}

TEST(TimeWarp, AHandshakeWithoutTimeConstraintsMeetsHalfWay) {
  Builder b({Range(50, 0.0), Range(50, 10.0)});
  b.Sync(0, 30, 1, 20, 0.0);  // at rest frame 30 of agent 0 plays at 30 and frame 20 of agent 1 at 30 too
  b.Sync(0, 40, 1, 30, 0.0).Time(0, 0, 0.0, false, 0.0);  // a zero-weight soft constraint changes nothing
  b.offsets = {4.0, 4.0};
  const TimeWarpResult r = b.Solve();
  EXPECT_LT(r.sync_residuals.maxCoeff(), 1e-9);
  EXPECT_NEAR(r.time_maps[0][30] - 30.0, 2.0, 1e-6);
  EXPECT_NEAR(r.time_maps[1][20] - 30.0, -2.0, 1e-6);
  EXPECT_LT((Intervals(r.time_maps[0]).array() - 1.0).abs().maxCoeff(), 1e-9);
}

TEST(TimeWarp, UnconstrainedAgentsKeepTheirRestMap) {
  Builder b({Range(10), Range(10), Range(10)});
  b.Time(1, 5, 8.0).Time(2, 5, 0.0, false, 0.0);
  const TimeWarpResult r = b.Solve();
  EXPECT_EQ(r.component[0], -1);
  EXPECT_EQ(r.component[2], -1);
  EXPECT_EQ(r.solver[0], "rest");
  EXPECT_TRUE((r.time_maps[0].array() == Range(10).array()).all());
  EXPECT_NEAR(r.time_residuals[1], 5.0, 1e-12);  // reported, not met
}

TEST(TimeWarp, ContradictingHardConstraintsNameThemselves) {
  {
    Builder b({Range(20)});
    b.Time(0, 5, 5.0).Time(0, 5, 7.0);
    try {
      b.Solve();
      FAIL() << "expected a conflict";
    } catch (const TimeWarpConflict& e) {
      EXPECT_EQ(e.kind, TimeWarpConflict::Kind::kCycle);
      EXPECT_EQ(e.time_constraints, (std::vector<int>{0, 1}));
      EXPECT_NEAR(e.mismatch, 2.0, 1e-12);
    }
  }
  {
    Builder b({Range(20), Range(20), Range(20), Range(20)});
    b.Sync(0, 3, 1, 3, 1.0).Sync(1, 3, 2, 3, 1.0).Sync(2, 3, 0, 3, 1.0).Sync(3, 1, 0, 1, 0.0);
    try {
      b.Solve();
      FAIL() << "expected a conflict";
    } catch (const TimeWarpConflict& e) {
      EXPECT_EQ(e.kind, TimeWarpConflict::Kind::kCycle);
      EXPECT_EQ(e.sync_constraints, (std::vector<int>{0, 1, 2}));  // not the fourth, off the cycle
      EXPECT_NEAR(e.mismatch, 3.0, 1e-12);
    }
  }
  {
    Builder b({Range(20), Range(20)});
    b.Time(0, 2, 4.0).Sync(1, 6, 0, 2, 1.0).Time(1, 6, 9.0);
    try {
      b.Solve();
      FAIL() << "expected a conflict";
    } catch (const TimeWarpConflict& e) {
      EXPECT_EQ(e.time_constraints, (std::vector<int>{0, 1}));
      EXPECT_EQ(e.sync_constraints, (std::vector<int>{0}));
    }
  }
}

TEST(TimeWarp, ConstraintsThatRunTimeBackwardsAreRejected) {
  {
    Builder b({Range(30)});
    b.Time(0, 5, 3.0).Time(0, 10, 20.0).Time(0, 20, 15.0);
    try {
      b.Solve();
      FAIL() << "expected a conflict";
    } catch (const TimeWarpConflict& e) {
      EXPECT_EQ(e.kind, TimeWarpConflict::Kind::kBackwards);
      EXPECT_EQ(e.time_constraints, (std::vector<int>{1, 2}));
      EXPECT_EQ(e.agent, 0);
      EXPECT_EQ(e.frame_a, 10);
      EXPECT_EQ(e.frame_b, 20);
      EXPECT_NEAR(e.gap, -5.0, 1e-12);
      EXPECT_NEAR(e.minimum, 1.0, 1e-12);
    }
  }
  {
    // Forwards, but faster than the minimum interval allows: 10 frames in 0.5 time codes.
    Builder b({Range(30)});
    b.Time(0, 10, 20.0).Time(0, 20, 20.5);
    EXPECT_THROW(b.Solve(), TimeWarpConflict);
    b.times[1] = 21.0;  // exactly the minimum: every interval between sits at it
    const TimeWarpResult r = b.Solve();
    EXPECT_NEAR(Intervals(r.time_maps[0]).segment(10, 10).maxCoeff(), 0.1, 1e-9);
    ExpectIncreasingAboveMinimum(b.p, r);
  }
  {
    // Crossed syncs between two agents: each alone is fine, together time runs backwards.
    Builder b({Range(60), Range(60)});
    b.Sync(0, 10, 1, 50, 0.0).Sync(0, 20, 1, 40, 0.0).Time(0, 0, 0.0);
    try {
      b.Solve();
      FAIL() << "expected a conflict";
    } catch (const TimeWarpConflict& e) {
      EXPECT_EQ(e.kind, TimeWarpConflict::Kind::kBackwards);
      EXPECT_EQ(e.sync_constraints, (std::vector<int>{0, 1}));
      EXPECT_TRUE(e.time_constraints.empty());
    }
  }
}

TEST(TimeWarp, TheMinimumIntervalHoldsAndTheBoundedOptimumIsFound) {
  // Soft constraints that ask for time to run backwards between frames 3 and 8.
  Builder b({Range(12)});
  b.Time(0, 3, 9.0, false, 50.0).Time(0, 8, 5.0, false, 50.0);
  b.p.min_interval_fraction = 0.25;
  const TimeWarpResult r = b.Solve();
  ExpectIncreasingAboveMinimum(b.p, r);
  EXPECT_GT(r.min_enforced[0], 0);
  EXPECT_GT(r.iterations[0], 0);
  EXPECT_NEAR(r.min_interval[0], 0.25, 1e-9);
  const Eigen::VectorXd best = BruteForce(b.p, b.Times());
  ASSERT_EQ(best.size(), 12);
  EXPECT_LT((r.time_maps[0] - best).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_NEAR(Energy(b.p, b.Times(), r.time_maps[0]), Energy(b.p, b.Times(), best), 1e-9);
}

TEST(TimeWarp, TheBoundedOptimumWithHardAndSoftConstraints) {
  Builder b({Range(11)});
  b.Time(0, 0, 0.0).Time(0, 10, 6.0).Time(0, 5, 5.5, false, 20.0);  // soft: most of the time early
  b.p.min_interval_fraction = 0.3;
  const TimeWarpResult r = b.Solve();
  ExpectIncreasingAboveMinimum(b.p, r);
  EXPECT_LT(r.time_residuals.head(2).maxCoeff(), 1e-9);
  const Eigen::VectorXd best = BruteForce(b.p, b.Times());
  ASSERT_EQ(best.size(), 11);
  EXPECT_LT((r.time_maps[0] - best).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_GT(r.min_enforced[0], 0);
}

TEST(TimeWarp, PrecomputeOnceSolveForNewValues) {
  Builder b({Range(200), Range(200, 3.0)});
  b.Time(0, 20, 25.0).Time(0, 150, 140.0).Sync(1, 100, 0, 100, 0.5);
  mocapedit::TimeWarpData data;
  mocapedit::TimeWarpPrecompute(b.p, data);
  EXPECT_EQ(data.components.size(), 1u);
  for (double end : {140.0, 170.0, 200.0}) {
    b.times[1] = end;
    const TimeWarpResult once = b.Solve();
    const TimeWarpResult again = SolveWith(data, b.Times(), b.Offsets());
    EXPECT_LT((once.time_maps[1] - again.time_maps[1]).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(again.time_maps[0][150], end, 1e-9);
    EXPECT_LT(again.sync_residuals[0], 1e-9);
  }
}

TEST(TimeWarp, ResponsesGiveTheSolveForAnyValues) {
  // Hard and soft times, a hard and a soft sync, and a free agent: re-solved from the
  // responses as the values change, including values that push an interval below its
  // minimum (the active set then takes over), against solving from scratch.
  Builder b({Range(300), Range(300, 2.0), Range(50)});
  b.Time(0, 20, 25.0).Time(0, 250, 240.0).Time(1, 200, 410.0, false, 0.5);
  b.Sync(1, 100, 0, 100, 0.5).Sync(1, 10, 0, 30, 3.0, false, 2.0);
  b.p.min_interval_fraction = 0.5;
  mocapedit::TimeWarpData plain, fast;
  mocapedit::TimeWarpPrecompute(b.p, plain);
  TimeWarpProblem with_responses = b.p;
  with_responses.precompute_responses = true;
  mocapedit::TimeWarpPrecompute(with_responses, fast);
  ASSERT_EQ(fast.components.size(), 1u);
  int bounded = 0;
  for (double end : {240.0, 300.0, 160.0, 145.0}) {  // the last ones squeeze frames 20..250
    b.times[1] = end;
    b.offsets[0] = end / 100.0;
    const TimeWarpResult solved = SolveWith(plain, b.Times(), b.Offsets());
    const TimeWarpResult summed = SolveWith(fast, b.Times(), b.Offsets());
    for (int a = 0; a < 3; ++a)  // as accurate as the solve: 1e-11 of the times
      EXPECT_LT((solved.time_maps[a] - summed.time_maps[a]).cwiseAbs().maxCoeff(),
                1e-11 * (1 + solved.time_maps[a].cwiseAbs().maxCoeff())) << "end " << end;
    EXPECT_EQ(summed.time_residuals[0], 0.0);  // hard times are set, not summed
    EXPECT_EQ(summed.time_residuals[1], 0.0);
    EXPECT_LT(summed.sync_residuals[0], 1e-9);
    EXPECT_EQ(solved.min_enforced, summed.min_enforced);
    ExpectIncreasingAboveMinimum(b.p, summed);
    bounded += summed.min_enforced.sum() > 0;
  }
  EXPECT_GT(bounded, 0);  // the active set was needed at least once
}

TEST(TimeWarp, ASingularSystemFallsBackToSpqr) {
  Builder b({Range(40)});
  b.p.stretch_weight = 0.0;  // one constraint leaves the stretch undetermined
  b.Time(0, 10, 14.0);
  const TimeWarpResult r = b.Solve();
  EXPECT_EQ(r.solver[0], "SPQR fallback");
  EXPECT_LT(r.time_residuals[0], 1e-9);
  ExpectIncreasingAboveMinimum(b.p, r);
}

TEST(TimeWarp, LongClipsStayAccurate) {
  // The normal equations of a second-difference energy are badly conditioned (n^4).
  Builder b({Range(20000)});
  b.Time(0, 4000, 4010.25);
  const TimeWarpResult r = b.Solve();
  EXPECT_LT((r.time_maps[0] - (Range(20000).array() + 10.25).matrix()).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(TimeWarp, TheActiveSetReleasesBoundsItNoLongerNeeds) {
  // Uneven samples, a hard span squeezed close to its minimum and a soft pull: the path to
  // the optimum holds some intervals at the minimum that the optimum lets go again.
  Eigen::VectorXd rest(12);
  rest << 0.0, 1.0667, 2.3442, 3.7078, 4.5657, 5.2770, 6.4313, 7.5717, 8.1188, 9.2207, 10.6630, 11.4094;
  Builder b({rest});
  b.Time(0, 1, 2.7313, false, 6.6124).Time(0, 4, 4.9906).Time(0, 9, 6.9170);
  b.p.min_interval_fraction = 0.4136;
  const TimeWarpResult r = b.Solve();
  ExpectIncreasingAboveMinimum(b.p, r);
  const Eigen::VectorXd best = BruteForce(b.p, b.Times());
  ASSERT_EQ(best.size(), 12);
  EXPECT_LT((r.time_maps[0] - best).cwiseAbs().maxCoeff(), 1e-6);
}
