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
    EXPECT_THROW(mocapedit::TangentHeadings(p, {{2, 9}}, one, 1e-9), std::invalid_argument);
  }
  {
    EXPECT_THROW(mocapedit::TangentHeadings(p, {{3, 1}}, one, 1e-9), std::invalid_argument);
  }
  {
    EXPECT_THROW(mocapedit::TangentHeadings(p, {}, one, 1e-9), std::invalid_argument);
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
