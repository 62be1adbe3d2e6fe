#include <gtest/gtest.h>

#include <cmath>

#include "mocapedit/regions.h"

using mocapedit::GroundRegion;
using mocapedit::Trajectory2;

TEST(Regions, ValidityRejectsEmptyRegions) {
  {
    EXPECT_THROW(mocapedit::CircleRegion(Eigen::Vector2d(0, 0), 0.0), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::CircleRegion(Eigen::Vector2d(0, NAN), 1.0), mocapedit::InvalidInput);
  }
  {
    Trajectory2 line(3, 2);
    line << 0, 0, 1, 1, 2, 2;
    EXPECT_THROW(mocapedit::HullRegion(line), mocapedit::InvalidInput);
  }
  {
    const GroundRegion r = mocapedit::CircleRegion(Eigen::Vector2d(0, 0), 1.0);
    Trajectory2 p = Trajectory2::Zero(2, 2);
    EXPECT_THROW(mocapedit::PushOutOfRegion(r, p, Eigen::VectorXd::Constant(3, 0.1)), mocapedit::InvalidInput);
    EXPECT_THROW(mocapedit::PushOutOfRegion(r, p, Eigen::VectorXd::Constant(1, -0.1)), mocapedit::InvalidInput);
  }
}

TEST(Regions, HullDropsInnerCollinearAndRepeatedPoints) {
  Trajectory2 p(9, 2);
  p << 0, 0, 2, 0, 1, 0, 2, 2, 0, 2, 1, 1, 0, 0, 2, 2, 0, 1;
  const Trajectory2 h = mocapedit::ConvexHull(p);
  ASSERT_EQ(h.rows(), 4);
  double area = 0.0;
  for (int i = 0; i < 4; ++i) area += h(i, 0) * h((i + 1) % 4, 1) - h((i + 1) % 4, 0) * h(i, 1);
  EXPECT_NEAR(area / 2, 4.0, 1e-12);  // positive: counter-clockwise
}

TEST(Regions, SignedDistanceToABoxAndACircle) {
  Trajectory2 corners(4, 2);
  corners << -1, -2, 1, -2, 1, 2, -1, 2;
  const GroundRegion box = mocapedit::HullRegion(corners);
  Trajectory2 p(4, 2);
  p << 0, 0, 3, 0, 4, 6, 0.5, 1.9;
  const Eigen::VectorXd d = mocapedit::RegionSignedDistance(box, p);
  EXPECT_NEAR(d[0], -1.0, 1e-12);
  EXPECT_NEAR(d[1], 2.0, 1e-12);
  EXPECT_NEAR(d[2], 5.0, 1e-12);  // nearest the corner (1, 2)
  EXPECT_NEAR(d[3], -0.1, 1e-12);
  const GroundRegion circle = mocapedit::CircleRegion(Eigen::Vector2d(1, 1), 2.0);
  EXPECT_NEAR(mocapedit::RegionSignedDistance(circle, p)[1], std::sqrt(5.0) - 2.0, 1e-12);
}

TEST(Regions, PushOutGoesToTheNearestPointAtTheClearance) {
  Trajectory2 corners(4, 2);
  corners << -1, -2, 1, -2, 1, 2, -1, 2;
  const GroundRegion box = mocapedit::HullRegion(corners);
  Trajectory2 p(5, 2);
  p << 0.8, 0.0,  // inside, nearest the +x side
      1.2, 0.0,   // outside but within the clearance
      1.3, 2.3,   // near the corner, outside
      5.0, 0.0,   // far away: untouched
      1.0, 0.5;   // on the boundary
  const auto push = mocapedit::PushOutOfRegion(box, p, Eigen::VectorXd::Constant(1, 0.5));
  ASSERT_EQ(push.index.size(), 4);
  EXPECT_EQ(push.index[3], 4);
  EXPECT_NEAR(push.target(0, 0), 1.5, 1e-12);
  EXPECT_NEAR(push.target(0, 1), 0.0, 1e-12);
  EXPECT_NEAR(push.depth[0], 0.7, 1e-12);
  EXPECT_NEAR(push.target(1, 0), 1.5, 1e-12);
  const Eigen::Vector2d n(std::sqrt(0.5), std::sqrt(0.5));
  EXPECT_NEAR(push.normal.row(2).dot(n.transpose()), 1.0, 1e-12);
  EXPECT_NEAR((push.target.row(2) - Eigen::RowVector2d(1, 2)).norm(), 0.5, 1e-12);
  EXPECT_NEAR(push.target(3, 0), 1.5, 1e-12);
  // Every target is exactly at the clearance.
  const Eigen::VectorXd d = mocapedit::RegionSignedDistance(box, push.target);
  for (Eigen::Index i = 0; i < d.size(); ++i) EXPECT_NEAR(d[i], 0.5, 1e-12);

  const GroundRegion circle = mocapedit::CircleRegion(Eigen::Vector2d(0, 0), 1.0);
  Trajectory2 q(2, 2);
  q << 0.0, 0.5, 0.0, 0.0;
  Eigen::VectorXd c(2);
  c << 0.25, 0.5;
  const auto cp = mocapedit::PushOutOfRegion(circle, q, c);
  ASSERT_EQ(cp.index.size(), 2);
  EXPECT_NEAR(cp.target(0, 1), 1.25, 1e-12);
  EXPECT_NEAR(cp.target.row(1).norm(), 1.5, 1e-12);  // the centre itself goes some fixed way
}

TEST(Regions, NearestOnRegionGivesBoundaryPointsAndNormals) {
  Trajectory2 corners(4, 2);
  corners << -1, -2, 1, -2, 1, 2, -1, 2;
  const GroundRegion box = mocapedit::HullRegion(corners);
  Trajectory2 p(3, 2);
  p << 0.5, 0.0, 3.0, 0.0, 2.0, 3.0;
  const auto near = mocapedit::NearestOnRegion(box, p);
  EXPECT_NEAR(near.distance[0], -0.5, 1e-12);
  EXPECT_NEAR(near.boundary(0, 0), 1.0, 1e-12);
  EXPECT_NEAR(near.normal(0, 0), 1.0, 1e-12);
  EXPECT_NEAR(near.distance[1], 2.0, 1e-12);
  EXPECT_NEAR(near.normal(1, 0), 1.0, 1e-12);
  EXPECT_NEAR(near.distance[2], std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(near.normal(2, 0), std::sqrt(0.5), 1e-12);
  const GroundRegion circle = mocapedit::CircleRegion(Eigen::Vector2d(1, 0), 2.0);
  const auto c = mocapedit::NearestOnRegion(circle, p);
  EXPECT_NEAR(c.distance[0], -1.5, 1e-12);
  EXPECT_NEAR(c.normal(0, 0), -1.0, 1e-12);
}
