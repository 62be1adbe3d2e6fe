#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "job_checks.h"
#include "mocapedit/placement.h"

namespace {

using mocapedit::PlacementJob;
using mocapedit::Span;

// One pose: the placement moves by (1, 0, 0), the motion turns 90 degrees about +Y then shifts
// by (0, 0, 5); one point (0, 1, 2) and one rotation (the identity).
struct Placed {
  std::vector<double> placement{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1};
  std::vector<double> placement_rotation{0, 0, 0, 1};
  std::vector<double> motion{0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 5, 1};
  std::vector<double> turn{M_PI / 2}, up{0, 1, 0}, points{0, 1, 2}, rotations{0, 0, 0, 1};
  std::vector<double> source_points = std::vector<double>(3), edited_points = std::vector<double>(3);
  std::vector<double> source_rotations = std::vector<double>(4), edited_rotations = std::vector<double>(4);

  PlacementJob Job() {
    PlacementJob job;
    job.placement = placement, job.placement_rotation = placement_rotation, job.motion = motion, job.turn = turn;
    job.up = up, job.points = points, job.rotations = rotations, job.point_count = 1, job.rotation_count = 1;
    job.source_points = source_points, job.edited_points = edited_points;
    job.source_rotations = source_rotations, job.edited_rotations = edited_rotations;
    return job;
  }
};

TEST(PlacementJob, Validate) {
  Placed p;
  EXPECT_EQ(Rejection(p.Job()), "");
  {
    std::vector<double> tilted{0, 2, 0};
    auto job = p.Job();
    job.up = tilted;
    EXPECT_NE(Rejection(job).find("unit"), std::string::npos);
  }
  {
    auto job = p.Job();
    job.point_count = 2;
    EXPECT_NE(Rejection(job).find("points must hold"), std::string::npos);
  }
  {
    auto job = p.Job();
    job.edited_points = Span<double>(p.points.data(), 3);
    EXPECT_NE(Rejection(job).find("overlaps the input points"), std::string::npos);
  }
  {
    auto job = p.Job();
    job.edited_rotations = p.source_rotations;
    EXPECT_NE(Rejection(job).find("overlaps"), std::string::npos);
  }
}

TEST(PlacementJob, PlacesThenMovesByTheEdit) {
  Placed p;
  p.Job().Run();
  EXPECT_EQ(p.source_points, (std::vector<double>{1, 1, 2}));
  // (1, 1, 2) turned about +Y (x -> -z, z -> x), then shifted by 5 along z.
  EXPECT_NEAR(p.edited_points[0], 2.0, 1e-15);
  EXPECT_NEAR(p.edited_points[1], 1.0, 1e-15);
  EXPECT_NEAR(p.edited_points[2], 4.0, 1e-15);
  EXPECT_EQ(p.source_rotations, (std::vector<double>{0, 0, 0, 1}));
  EXPECT_NEAR(p.edited_rotations[1], std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(p.edited_rotations[3], std::sqrt(0.5), 1e-15);
}

}  // namespace
