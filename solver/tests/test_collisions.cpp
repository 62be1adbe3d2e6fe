#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "mocapedit/collisions.h"

using mocapedit::CapsuleSet;
using mocapedit::CollisionResult;
using mocapedit::CollisionSettings;
using mocapedit::Trajectory2;

namespace {

CapsuleSet Capsules(int agents, double radius = 0.3, double height = 1.8) {
  CapsuleSet c;
  c.radius = Eigen::VectorXd::Constant(agents, radius);
  c.height = Eigen::VectorXd::Constant(agents, height);
  c.base = Eigen::VectorXd::Zero(agents);
  return c;
}

// A dense random crowd: agents cross a square on straight lines at walking speed.
Trajectory2 Crossing(int agents, int samples, double side, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Trajectory2 p(static_cast<Eigen::Index>(agents) * samples, 2);
  for (int a = 0; a < agents; ++a) {
    const double x0 = side * u(rng), y0 = side * u(rng), h = 2 * M_PI * u(rng), v = 0.04 + 0.02 * u(rng);
    for (int k = 0; k < samples; ++k)
      p.row(static_cast<Eigen::Index>(k) * agents + a) << x0 + v * k * std::cos(h), y0 + v * k * std::sin(h);
  }
  return p;
}

void ExpectSame(const CollisionResult& x, const CollisionResult& y) {
  ASSERT_EQ(x.collisions.size(), y.collisions.size());
  for (size_t i = 0; i < x.collisions.size(); ++i) {
    const auto &a = x.collisions[i], &b = y.collisions[i];
    EXPECT_EQ(a.agent_a, b.agent_a);
    EXPECT_EQ(a.agent_b, b.agent_b);
    EXPECT_EQ(a.first, b.first);
    EXPECT_EQ(a.last, b.last);
    EXPECT_EQ(a.deepest, b.deepest);
    EXPECT_DOUBLE_EQ(a.depth, b.depth);
  }
  EXPECT_EQ(x.colliding_samples, y.colliding_samples);
  ASSERT_EQ(x.min_clearance.size(), y.min_clearance.size());
  for (Eigen::Index a = 0; a < x.min_clearance.size(); ++a) {
    EXPECT_EQ(x.min_clearance[a], y.min_clearance[a]) << "agent " << a;
    EXPECT_EQ(x.min_clearance_sample[a], y.min_clearance_sample[a]) << "agent " << a;
  }
}

}  // namespace

TEST(Collisions, ValidityRejectsBadInput) {
  Trajectory2 p = Trajectory2::Zero(4, 2);
  CollisionSettings s;
  {
    EXPECT_THROW(mocapedit::DetectCollisions(p, 3, Capsules(2), s), mocapedit::InvalidInput);  // rows
  }
  {
    CapsuleSet c = Capsules(2);
    c.radius[1] = 0.0;
    EXPECT_THROW(mocapedit::DetectCollisions(p, 2, c, s), mocapedit::InvalidInput);
  }
  {
    CapsuleSet c = Capsules(2);
    c.height[0] = -1.0;
    EXPECT_THROW(mocapedit::DetectCollisions(p, 2, c, s), mocapedit::InvalidInput);
  }
  {
    CapsuleSet c = Capsules(2);
    c.base.resize(1);
    EXPECT_THROW(mocapedit::DetectCollisions(p, 2, c, s), mocapedit::InvalidInput);
  }
  {
    CapsuleSet c = Capsules(2);
    c.active = {1};
    EXPECT_THROW(mocapedit::DetectCollisions(p, 2, c, s), mocapedit::InvalidInput);
  }
  {
    CollisionSettings bad;
    bad.margin = -0.1;
    EXPECT_THROW(mocapedit::DetectCollisions(p, 2, Capsules(2), bad), mocapedit::InvalidInput);
  }
  {
    Trajectory2 q = p;
    q(3, 1) = NAN;
    EXPECT_THROW(mocapedit::DetectCollisions(q, 2, Capsules(2), s), mocapedit::InvalidInput);
    // An inactive agent's positions are never read.
    CapsuleSet c = Capsules(2);
    c.active = {1, 0};
    c.radius[1] = 0.0;
    EXPECT_NO_THROW(mocapedit::DetectCollisions(q, 2, c, s));
  }
}

TEST(Collisions, CapsuleClearanceOfVerticalCapsules) {
  EXPECT_NEAR(mocapedit::CapsuleClearance(1.0, 0.0, 0.3, 1.8, 0.0, 0.3, 1.8, 0.0), 0.4, 1e-12);
  EXPECT_NEAR(mocapedit::CapsuleClearance(0.3, 0.4, 0.3, 1.8, 0.0, 0.2, 1.8, 0.0), 0.0, 1e-12);
  // One agent on a balcony 3 above: axes [0.3, 1.5] and [3.3, 4.5] are 1.8 apart.
  EXPECT_NEAR(mocapedit::CapsuleClearance(0.0, 0.0, 0.3, 1.8, 0.0, 0.3, 1.8, 3.0), 1.8 - 0.6, 1e-12);
  // A capsule shorter than its diameter is a sphere at half its height.
  EXPECT_NEAR(mocapedit::CapsuleClearance(0.0, 0.0, 0.5, 0.4, 0.0, 0.5, 0.4, 3.0), 3.0 - 1.0, 1e-12);
}

TEST(Collisions, HeadOnPairGivesOneIntervalDeepestAtTheCrossing) {
  // Agent 0 walks +x from -5, agent 1 walks -x from +5, 0.1 per sample, 0.2 apart sideways.
  const int K = 101, A = 2;
  Trajectory2 p(K * A, 2);
  for (int k = 0; k < K; ++k) {
    p.row(k * A + 0) << -5.0 + 0.1 * k, 0.0;
    p.row(k * A + 1) << 5.0 - 0.1 * k, 0.2;
  }
  CollisionSettings s;
  s.margin = 0.1;
  s.report_distance = 1.0;
  const auto r = mocapedit::DetectCollisions(p, K, Capsules(A), s);
  ASSERT_EQ(r.collisions.size(), 1u);
  const auto& c = r.collisions[0];
  EXPECT_EQ(c.agent_a, 0);
  EXPECT_EQ(c.agent_b, 1);
  EXPECT_EQ(c.deepest, 50);
  EXPECT_NEAR(c.depth, 0.7 - 0.2, 1e-12);  // wanted 0.6 + 0.1, axes 0.2 apart
  // Colliding while the axes are closer than 0.7: |dx| = |10 - 0.2 k| < sqrt(0.49 - 0.04).
  const double half = std::sqrt(0.49 - 0.04);
  int first = K, last = -1;
  for (int k = 0; k < K; ++k)
    if (std::abs(-10.0 + 0.2 * k) < half) first = std::min(first, k), last = std::max(last, k);
  EXPECT_EQ(c.first, first);
  EXPECT_EQ(c.last, last);
  EXPECT_NEAR(r.min_clearance[0], 0.2 - 0.6, 1e-12);
  EXPECT_EQ(r.min_clearance_sample[1], 50);
}

TEST(Collisions, SeparateIntervalsAndInactiveAgents) {
  // Two agents meet twice (in, out, in again); a third one stands on agent 0's path but
  // does not collide.
  const int K = 30, A = 3;
  Trajectory2 p(K * A, 2);
  for (int k = 0; k < K; ++k) {
    const double x = (k < 10 || k >= 20) ? 0.2 : 3.0;
    p.row(k * A + 0) << 0.0, 0.0;
    p.row(k * A + 1) << x, 0.0;
    p.row(k * A + 2) << 0.0, 0.1;
  }
  CapsuleSet c = Capsules(A);
  c.active = {1, 1, 0};
  const auto r = mocapedit::DetectCollisions(p, K, c, CollisionSettings{});
  ASSERT_EQ(r.collisions.size(), 2u);
  EXPECT_EQ(r.collisions[0].first, 0);
  EXPECT_EQ(r.collisions[0].last, 9);
  EXPECT_EQ(r.collisions[1].first, 20);
  EXPECT_EQ(r.collisions[1].last, 29);
  EXPECT_TRUE(std::isinf(r.min_clearance[2]));
  EXPECT_EQ(r.min_clearance_sample[2], -1);
}

TEST(Collisions, GridMatchesAllPairsOnADenseRandomCrowd) {
  const int A = 300, K = 60;
  const Trajectory2 p = Crossing(A, K, 12.0, 7);
  CapsuleSet c = Capsules(A);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int a = 0; a < A; ++a) {
    c.radius[a] = 0.15 + 0.3 * u(rng);
    c.height[a] = 0.5 + 1.5 * u(rng);
    c.base[a] = u(rng) < 0.1 ? 2.0 : 0.0;
  }
  c.active.assign(A, 1);
  c.active[5] = c.active[17] = 0;
  CollisionSettings s;
  s.margin = 0.05;
  s.report_distance = 0.5;
  const auto brute = mocapedit::DetectCollisionsBruteForce(p, K, c, s);
  ASSERT_GT(brute.collisions.size(), 100u);
  for (int threads : {1, 2}) {
    s.threads = threads;
    const auto grid = mocapedit::DetectCollisions(p, K, c, s);
    ExpectSame(grid, brute);
    EXPECT_LT(grid.pair_tests, brute.pair_tests / 10);
  }
}

TEST(Collisions, FarApartCoordinatesAndNoAgents) {
  // Positions far from the origin, and a crowd spread over a wide range of cells.
  const int A = 50, K = 5;
  Trajectory2 p = Crossing(A, K, 8.0, 11);
  p.array() += 1e6;
  const auto grid = mocapedit::DetectCollisions(p, K, Capsules(A), CollisionSettings{});
  ExpectSame(grid, mocapedit::DetectCollisionsBruteForce(p, K, Capsules(A), CollisionSettings{}));
  const auto none = mocapedit::DetectCollisions(Trajectory2(0, 2), 10, Capsules(0), CollisionSettings{});
  EXPECT_TRUE(none.collisions.empty());
}

TEST(Collisions, WatchDistanceGathersNearMissesInTheSamePass) {
  // The near intervals at watch distance w are the collisions at margin w; the collisions
  // at the margin are those of a pass without watching.
  const int A = 200, K = 40;
  const Trajectory2 p = Crossing(A, K, 10.0, 5);
  CollisionSettings s;
  s.margin = 0.05;
  s.report_distance = 0.5;
  const auto plain = mocapedit::DetectCollisions(p, K, Capsules(A), s);
  CollisionSettings wide = s;
  wide.margin = 0.35;
  const auto at_watch = mocapedit::DetectCollisionsBruteForce(p, K, Capsules(A), wide);
  for (int threads : {1, 2}) {
    CollisionSettings watched = s;
    watched.watch_distance = 0.35;
    watched.threads = threads;
    const auto both = mocapedit::DetectCollisions(p, K, Capsules(A), watched);
    ExpectSame(both, plain);
    ASSERT_GT(at_watch.collisions.size(), plain.collisions.size());
    CollisionResult near = at_watch;
    near.collisions = both.near;
    near.colliding_samples = at_watch.colliding_samples;
    near.min_clearance = at_watch.min_clearance;
    near.min_clearance_sample = at_watch.min_clearance_sample;
    ExpectSame(near, at_watch);
  }
  CollisionSettings bad = s;
  bad.watch_distance = std::numeric_limits<double>::infinity();
  EXPECT_THROW(mocapedit::DetectCollisions(p, K, Capsules(A), bad), mocapedit::InvalidInput);
}
