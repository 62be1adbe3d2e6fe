#include <gtest/gtest.h>

#include <cmath>

#include "mocapedit/trajectory.h"

using mocapedit::Trajectory2;

TEST(Trajectory, ValidityRejectsBadRanges) {
  Trajectory2 p(4, 2);
  p << 0, 0, 1, 0, 2, 0, 3, 0;
  Eigen::VectorXd one(1);
  one << 0.0;
  {
    EXPECT_THROW(mocapedit::TangentHeadings(p, {{2, 9}}, one, 1e-9), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::TangentHeadings(p, {{3, 1}}, one, 1e-9), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::TangentHeadings(p, {}, one, 1e-9), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::DeformationTurns(p, p.topRows(3), {}, Eigen::VectorXd(), 2, 0.0), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::DeformationTurns(p, p, {{2, 9}}, one, 2, 0.0), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::DeformationTurns(p, p, {}, one, 2, 0.0), mocapedit::InvalidInput);
  }
}

TEST(Trajectory, LengthOfAStraightLineAndASquare) {
  Trajectory2 line(3, 2);
  line << 0, 0, 3, 4, 6, 8;
  EXPECT_NEAR(mocapedit::PathLength(line), 10.0, 1e-12);
  Trajectory2 square(5, 2);
  square << 0, 0, 1, 0, 1, 1, 0, 1, 0, 0;
  EXPECT_NEAR(mocapedit::PathLength(square), 4.0, 1e-12);
  const Eigen::VectorXd s = mocapedit::CumulativeArcLength(square);
  EXPECT_NEAR(s[0], 0.0, 1e-12);
  EXPECT_NEAR(s[2], 2.0, 1e-12);
  EXPECT_NEAR(s[4], 4.0, 1e-12);
}

TEST(Trajectory, HeadingsFollowACircleWithoutWrapping) {
  const int n = 400;  // two full turns
  Trajectory2 p(n, 2);
  for (int i = 0; i < n; ++i) {
    const double a = 4.0 * M_PI * i / (n - 1);
    p.row(i) << std::cos(a), std::sin(a);
  }
  const Eigen::VectorXd h = mocapedit::TangentHeadings(p, {}, Eigen::VectorXd(), 1e-12);
  for (int i = 1; i < n - 1; ++i) {
    const double a = 4.0 * M_PI * i / (n - 1);
    EXPECT_NEAR(h[i], a + M_PI / 2, 1e-3) << "frame " << i;
    EXPECT_LT(std::abs(h[i] - h[i - 1]), 0.1);
  }
}

TEST(Trajectory, StandingStillAndFixedRangesKeepAHeading) {
  Trajectory2 p(6, 2);
  p << 0, 0, 0, 1, 0, 2, 0, 2, 0, 2, 0, 2;  // walks along +y, then stands
  Eigen::VectorXd fb(1);
  fb << 0.25;
  const Eigen::VectorXd h = mocapedit::TangentHeadings(p, {{4, 5}}, fb, 1e-9);
  EXPECT_NEAR(h[0], M_PI / 2, 1e-12);
  EXPECT_NEAR(h[3], M_PI / 2, 1e-12);  // still: keeps the last moving heading
  EXPECT_NEAR(h[4], 0.25, 1e-12);
  EXPECT_NEAR(h[5], 0.25, 1e-12);
}

namespace {

// A walk along the first axis with a sideways sway, standing still over frames [40, 80).
Trajectory2 WalkStandWalk() {
  Trajectory2 p(120, 2);
  double u = 0.0;
  for (int i = 0; i < 120; ++i) {
    p.row(i) << u, 0.02 * std::sin(u * 2.0 * M_PI / 1.2);
    if (i < 39 || i >= 79) u += 0.05;
  }
  return p;
}

Trajectory2 Turned(const Trajectory2& p, double angle, double du, double dv) {
  Trajectory2 out(p.rows(), 2);
  const double c = std::cos(angle), s = std::sin(angle);
  for (Eigen::Index i = 0; i < p.rows(); ++i)
    out.row(i) << c * p(i, 0) - s * p(i, 1) + du, s * p(i, 0) + c * p(i, 1) + dv;
  return out;
}

}  // namespace

TEST(Trajectory, AnUneditedPathTurnsByExactlyZeroAndATurnedOneByItsAngle) {
  const Trajectory2 p = WalkStandWalk();
  EXPECT_TRUE((mocapedit::DeformationTurns(p, p, {}, Eigen::VectorXd(), 2, 0.01).array() == 0.0).all());
  for (double angle : {0.3, -2.5, 3.0}) {
    const Eigen::VectorXd t = mocapedit::DeformationTurns(p, Turned(p, angle, 4.0, 5.0), {}, Eigen::VectorXd(), 3, 0.01);
    EXPECT_LT((t.array() - angle).abs().maxCoeff(), 1e-9) << angle;
  }
}

TEST(Trajectory, AStandTurnsFromTheWalkBeforeItToTheWalkAfterIt) {
  const Trajectory2 p = WalkStandWalk();
  Trajectory2 e = p;
  // The walk after the stand (from its last frame, 79) turned by 0.8 about where it starts.
  e.bottomRows(41) = Turned(p.bottomRows(41).rowwise() - p.row(79), 0.8, p(79, 0), p(79, 1));
  const Eigen::VectorXd t = mocapedit::DeformationTurns(p, e, {}, Eigen::VectorXd(), 2, 0.01);
  EXPECT_LT(t.head(36).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((t.tail(36).array() - 0.8).abs().maxCoeff(), 1e-9);
  const Eigen::VectorXd step = t.tail(119) - t.head(119);
  EXPECT_LT(step.cwiseAbs().maxCoeff(), 0.8 / 30);       // spread over the stand: no jump
  EXPECT_GE(step.minCoeff(), -1e-12);
  // A fixed range turns by its own angle, exactly.
  Eigen::VectorXd turn(1);
  turn << 0.4;
  const Eigen::VectorXd f = mocapedit::DeformationTurns(p, e, {{45, 70}}, turn, 2, 0.01);
  EXPECT_TRUE((f.segment(45, 26).array() == 0.4).all());
}

TEST(Trajectory, ACutInTheSourceCountsForNothing) {
  // A walk along x whose first frame is a rest pose far away (a cut), bent smoothly sideways.
  const int n = 120;
  Trajectory2 p(n, 2), e(n, 2);
  for (int i = 0; i < n; ++i) {
    p.row(i) << 3.3 * i, 0.0;
    e.row(i) << 3.3 * i, 20.0 * (1.0 - std::cos(3.14159265358979 * i / (n - 1)));
  }
  p.row(0) << -40.0, -300.0;
  e.row(0) = p.row(0);
  const int window = 12;
  const Eigen::VectorXd with_cut = mocapedit::DeformationTurns(p, e, {}, Eigen::VectorXd(), window, 1.0);
  const Eigen::VectorXd cut = mocapedit::DeformationTurns(p, e, {}, Eigen::VectorXd(), window, 1.0, 50.0);
  const auto largest_step = [&](const Eigen::VectorXd& t) {
    return (t.tail(n - 2) - t.segment(1, n - 2)).cwiseAbs().maxCoeff();
  };
  // Counted, the cut's 300-unit step outweighs every other step in the windows that hold it,
  // and the turn jumps where it leaves them.
  EXPECT_GT(largest_step(with_cut), 0.05);
  EXPECT_LT(largest_step(cut), 0.01);
  // Without cuts the limit changes nothing.
  Trajectory2 q = p, f = e;
  q.row(0) << -3.3, 0.0;
  f.row(0) = q.row(0);
  EXPECT_TRUE((mocapedit::DeformationTurns(q, f, {}, Eigen::VectorXd(), window, 1.0, 50.0).array() ==
               mocapedit::DeformationTurns(q, f, {}, Eigen::VectorXd(), window, 1.0).array())
                  .all());
}

namespace {

// A root that moves about one spot at 60 frames per second: within 8 cm, at 10 to 30 cm/s.
Trajectory2 Wander(int frames) {
  Trajectory2 p(frames, 2);
  for (int i = 0; i < frames; ++i) {
    const double t = i / 60.0;
    p.row(i) << 0.08 * (0.6 * std::sin(1.3 * t) + 0.4 * std::sin(3.1 * t + 1.0)),
        0.08 * (0.6 * std::sin(1.7 * t + 0.5) + 0.4 * std::sin(2.3 * t + 2.0));
  }
  return p;
}

}  // namespace

TEST(Trajectory, APathAboutOneSpotKeepsItsFacingUnlessItTurnsWithAGroup) {
  const Trajectory2 p = Wander(720);
  // The edit turns its wiggles by 0.7 and moves it 40 cm aside and back.
  Trajectory2 e = Turned(p, -0.7, 0.0, 0.0);
  for (Eigen::Index i = 0; i < e.rows(); ++i) e(i, 0) += 0.4 * std::sin(M_PI * i / (e.rows() - 1.0));
  // 60 fps, metres: windows of 12 frames, 4 cm of travel, cuts beyond 25 cm a frame.
  const Eigen::VectorXd kept = mocapedit::DeformationTurns(p, e, {}, Eigen::VectorXd(), 12, 0.04, 0.25);
  EXPECT_LT(kept.cwiseAbs().maxCoeff(), 10.0 * M_PI / 180.0);
  const Eigen::VectorXd turned = mocapedit::DeformationTurns(p, e, {}, Eigen::VectorXd(), 12, 0.04, 0.25, false);
  EXPECT_LT(turned.mean(), -25.0 * M_PI / 180.0);
  // The same clip placed 2 m away with its first frame left at its rest pose at the origin (a
  // cut): the frames near the cut do not look as if they went somewhere.
  Trajectory2 q = p, f = e;
  q.rowwise() += Eigen::RowVector2d(2.0, 1.0);
  f.rowwise() += Eigen::RowVector2d(2.0, 1.0);
  q.row(0).setZero();
  f.row(0).setZero();
  const Eigen::VectorXd cut = mocapedit::DeformationTurns(q, f, {}, Eigen::VectorXd(), 12, 0.04, 0.25);
  EXPECT_LT(cut.tail(cut.size() - 1).cwiseAbs().maxCoeff(), 10.0 * M_PI / 180.0);
}

TEST(Trajectory, ASpotWeighsAsFarAsThePathStaysAboutOneSpot) {
  // 60 fps, metres: windows of 12 frames, 4 cm of travel, cuts beyond 25 cm a frame.
  const Trajectory2 wander = Wander(720);
  EXPECT_GT(mocapedit::SpotWeight(wander, 12, 0.04, 0.25), 0.95);
  // Its first frame left at the rest pose at the origin, 2 m away (a cut): still about one spot.
  Trajectory2 cut = wander;
  cut.rowwise() += Eigen::RowVector2d(2.0, 1.0);
  cut.row(0).setZero();
  EXPECT_GT(mocapedit::SpotWeight(cut, 12, 0.04, 0.25), 0.95);
  // A walk at 1.4 m/s, even one that sways, goes somewhere.
  Trajectory2 walk(240, 2);
  for (int i = 0; i < 240; ++i) walk.row(i) << 1.4 * i / 60.0, 0.03 * std::sin(2.0 * M_PI * i / 60.0);
  EXPECT_EQ(mocapedit::SpotWeight(walk, 12, 0.04, 0.25), 0.0);
  // The wander drifting 1 m over its 12 s: some frames travel far enough to be sure of their turn.
  Trajectory2 drift = wander;
  for (int i = 0; i < 720; ++i) drift(i, 0) += 1.0 * i / 719.0;
  EXPECT_LT(mocapedit::SpotWeight(drift, 12, 0.04, 0.25), 0.5);
  // No travel threshold: no spot (as DeformationTurns keeps a spot's facing only with one).
  EXPECT_EQ(mocapedit::SpotWeight(wander, 12, 0.0, 0.25), 0.0);
  EXPECT_EQ(mocapedit::SpotWeight(Trajectory2(1, 2), 12, 0.04, 0.25), 0.0);
}
