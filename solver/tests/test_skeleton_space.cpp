#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "job_checks.h"
#include "mocapedit/skeleton_space.h"

namespace {

using mocapedit::SkeletonSpaceJob;
using mocapedit::Span;

// A chain root -> a -> b (b keeps its rest transform) and a joint c off the root, two poses of
// two columns (root, a): the root moved and turned 90 degrees about +Y in pose 1, a scaled by 2.
struct Chain {
  std::vector<std::int64_t> parents{-1, 0, 1, 0}, columns{0, 1, -1, -1}, joints{2, 0};
  std::vector<double> rest;
  std::vector<float> t{0, 0, 0, 0, 1, 0, /* pose 1 */ 1, 2, 3, 0, 1, 0};
  std::vector<float> r{0, 0, 0, 1, 0, 0, 0, 1, /* pose 1 */ 0, static_cast<float>(std::sqrt(0.5)), 0,
                       static_cast<float>(std::sqrt(0.5)), 0, 0, 0, 1};
  std::vector<float> s{1, 1, 1, 2, 2, 2, 1, 1, 1, 2, 2, 2};
  std::vector<double> matrices = std::vector<double>(2 * 2 * 16), rotations = std::vector<double>(2 * 2 * 4);

  Chain() {
    for (int j = 0; j < 4; ++j) {
      const double m[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, j == 2 ? 0.5 : 9.0, 0, 0, 1};
      rest.insert(rest.end(), m, m + 16);
    }
  }
  SkeletonSpaceJob Job() {
    SkeletonSpaceJob job;
    job.parents = parents, job.columns = columns, job.rest = rest, job.joints = joints;
    job.pose = mocapedit::ConstPoseStreamView(t, r, s);
    job.pose_columns = 2;
    job.matrices = matrices, job.rotations = rotations;
    return job;
  }
  double M(std::size_t pose, std::size_t k, int row, int col) const { return matrices[16 * (2 * pose + k) + 4 * row + col]; }
};

TEST(SkeletonSpaceJob, Validate) {
  Chain c;
  EXPECT_EQ(Rejection(c.Job()), "");
  {
    std::vector<std::int64_t> late{-1, 2, 1, 0};
    auto job = c.Job();
    job.parents = late;
    EXPECT_NE(Rejection(job).find("precede"), std::string::npos);
  }
  {
    std::vector<std::int64_t> wide{0, 2, -1, -1};
    auto job = c.Job();
    job.columns = wide;
    EXPECT_NE(Rejection(job).find("column"), std::string::npos);
  }
  {
    std::vector<std::int64_t> missing{4};
    auto job = c.Job();
    job.joints = missing;
    EXPECT_NE(Rejection(job).find("out of range"), std::string::npos);
  }
  {
    auto job = c.Job();
    job.matrices = Span<double>(c.matrices.data(), 16);
    EXPECT_NE(Rejection(job).find("matrices must hold"), std::string::npos);
  }
  {
    auto job = c.Job();
    job.rotations = Span<double>(c.matrices.data(), 16);
    EXPECT_NE(Rejection(job).find("overlaps"), std::string::npos);
  }
  {
    auto job = c.Job();
    job.rotations = Span<double>();  // optional
    EXPECT_EQ(Rejection(job), "");
  }
}

TEST(SkeletonSpaceJob, ChainsLocalsToTheRootAndKeepsRestJoints) {
  Chain c;
  c.Job().Run();
  // Pose 0: b = rest (0.5 along x) * a (scale 2, 1 up) * root (identity): at (1, 1, 0).
  EXPECT_DOUBLE_EQ(c.M(0, 0, 3, 0), 1.0);
  EXPECT_DOUBLE_EQ(c.M(0, 0, 3, 1), 1.0);
  EXPECT_DOUBLE_EQ(c.M(0, 0, 0, 0), 2.0);
  // Pose 1: the root turned 90 degrees about +Y (x -> -z) and moved to (1, 2, 3).
  EXPECT_NEAR(c.M(1, 0, 3, 0), 1.0, 1e-7);
  EXPECT_NEAR(c.M(1, 0, 3, 1), 3.0, 1e-7);
  EXPECT_NEAR(c.M(1, 0, 3, 2), 2.0, 1e-7);
  EXPECT_NEAR(c.M(1, 1, 0, 2), -1.0, 1e-7);
  EXPECT_DOUBLE_EQ(c.M(1, 1, 3, 0), 1.0);
  // Rotations with the scale divided out, w >= 0: b's is the root's.
  const double h = std::sqrt(0.5);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(c.rotations[4 * 2 + i], (i == 1 || i == 3) ? h : 0.0, 1e-7) << i;
  EXPECT_NEAR(c.rotations[3], 1.0, 1e-12);
}

}  // namespace
