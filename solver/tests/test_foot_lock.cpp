#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mocapedit/foot_lock.h"
#include "job_checks.h"

namespace {

using mocapedit::FootLockJob;
using mocapedit::Span;
using Vec = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;

// One agent of #T poses: two legs hanging from hips 0.1 apart, thigh 0.45 and shin 0.42
// long along -Y, the knee bent a little forwards (+Z), every rotation the identity.
struct Legs {
  std::size_t poses;
  std::vector<std::int64_t> offsets, smooth;
  std::vector<double> up{0, 1, 0};
  std::vector<double> hip, knee, ankle, parent_rot, hip_rot, knee_rot, ankle_rot, target, target_rot, weight, hinge;
  std::vector<double> hip_local, knee_local, ankle_local, drop, reached;

  explicit Legs(std::size_t t) : poses(t), offsets{0, static_cast<std::int64_t>(t)}, smooth{2} {
    for (std::size_t p = 0; p < t; ++p)
      for (int leg = 0; leg < 2; ++leg) {
        const double x = leg == 0 ? 0.1 : -0.1;
        Push(hip, {x, 0.9, 0}), Push(knee, {x, 0.451, 0.02}), Push(ankle, {x, 0.032, 0.0});
        for (auto* r : {&parent_rot, &hip_rot, &knee_rot, &ankle_rot, &target_rot}) Push(*r, {0, 0, 0, 1});
        Push(target, {x, 0.032, 0.0});
        Push(hinge, {1.0, 0.0, 0.0});
        weight.push_back(0.0);
      }
    hip_local.resize(t * 8), knee_local.resize(t * 8), ankle_local.resize(t * 8), drop.resize(t), reached.resize(t * 6);
  }
  static void Push(std::vector<double>& v, std::initializer_list<double> values) { v.insert(v.end(), values); }

  FootLockJob Job() {
    FootLockJob job;
    job.offsets = offsets, job.smooth = smooth, job.up = up;
    job.hip = hip, job.knee = knee, job.ankle = ankle, job.parent_rot = parent_rot, job.hip_rot = hip_rot;
    job.knee_rot = knee_rot, job.ankle_rot = ankle_rot, job.target = target, job.target_rot = target_rot;
    job.weight = weight, job.hinge = hinge;
    job.hip_local = hip_local, job.knee_local = knee_local, job.ankle_local = ankle_local, job.drop = drop;
    job.reached = reached;
    return job;
  }

  Vec At(const std::vector<double>& v, std::size_t i) const { return Vec(v[3 * i], v[3 * i + 1], v[3 * i + 2]); }
};

TEST(FootLockJob, Validate) {
  Legs legs(4);
  std::string why;
  EXPECT_EQ(Rejection(legs.Job()), "");
  {
    auto job = legs.Job();
    job.offsets = Span<const std::int64_t>();
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    std::vector<std::int64_t> bad{1, 4};
    auto job = legs.Job();
    job.offsets = bad;
    EXPECT_NE(why = Rejection(job), "");
    EXPECT_NE(why.find("start at 0"), std::string::npos);
  }
  {
    std::vector<std::int64_t> negative{-1};
    auto job = legs.Job();
    job.smooth = negative;
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    std::vector<double> tilted{0, 2, 0};
    auto job = legs.Job();
    job.up = tilted;
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    auto job = legs.Job();
    job.knee.size -= 1;
    EXPECT_NE(why = Rejection(job), "");
    EXPECT_NE(why.find("knee"), std::string::npos);
  }
  {
    legs.weight[3] = 1.5;
    EXPECT_NE(why = Rejection(legs.Job()), "");
    legs.weight[3] = std::nan("");
    EXPECT_NE(why = Rejection(legs.Job()), "");
    legs.weight[3] = 0.0;
  }
  {
    auto job = legs.Job();
    job.soft_reach = 0.9999;
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    auto job = legs.Job();
    job.reached = Span<double>(legs.weight.data(), legs.reached.size());  // an output over an input
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    auto job = legs.Job();
    job.drop = Span<double>(legs.hip_local.data(), legs.drop.size());  // two outputs at once
    EXPECT_NE(why = Rejection(job), "");
  }
  {
    auto job = legs.Job();
    job.weight.size = 3;
    EXPECT_THROW(job.Run(), mocapedit::InvalidInput);
  }
}

TEST(FootLockJob, WeightZeroLeavesTheLegs) {
  Legs legs(3);
  ASSERT_NO_THROW(legs.Job().Run());
  for (std::size_t i = 0; i < legs.poses * 2; ++i) {
    EXPECT_NEAR(legs.hip_local[4 * i + 3], 1.0, 1e-12);
    EXPECT_NEAR(legs.knee_local[4 * i + 3], 1.0, 1e-12);
    EXPECT_NEAR(legs.ankle_local[4 * i + 3], 1.0, 1e-12);
    EXPECT_LT((legs.At(legs.reached, i) - legs.At(legs.ankle, i)).norm(), 1e-12);
  }
  for (double d : legs.drop) EXPECT_EQ(d, 0.0);
}

TEST(FootLockJob, ReachesATargetKeepingBonesAndKneeSide) {
  Legs legs(1);
  legs.target[0] = 0.16, legs.target[1] = 0.1, legs.target[2] = 0.12;  // left ankle: up, forwards and out
  legs.weight[0] = 1.0;
  const Quat turn(Eigen::AngleAxisd(0.3, Vec::UnitY()));
  legs.target_rot[0] = turn.x(), legs.target_rot[1] = turn.y(), legs.target_rot[2] = turn.z(),
  legs.target_rot[3] = turn.w();
  ASSERT_NO_THROW(legs.Job().Run());
  EXPECT_EQ(legs.drop[0], 0.0);
  EXPECT_LT((legs.At(legs.reached, 0) - Vec(0.16, 0.1, 0.12)).norm(), 1e-12);
  // Forward kinematics of the new locals from the unchanged hip gives the same ankle.
  const Quat hip(legs.hip_local[3], legs.hip_local[0], legs.hip_local[1], legs.hip_local[2]);
  const Quat knee(legs.knee_local[3], legs.knee_local[0], legs.knee_local[1], legs.knee_local[2]);
  const Quat ankle(legs.ankle_local[3], legs.ankle_local[0], legs.ankle_local[1], legs.ankle_local[2]);
  const Vec h = legs.At(legs.hip, 0);
  const Vec k = h + hip * (legs.At(legs.knee, 0) - h);
  const Vec a = k + (hip * knee) * (legs.At(legs.ankle, 0) - legs.At(legs.knee, 0));
  EXPECT_LT((a - Vec(0.16, 0.1, 0.12)).norm(), 1e-9);
  EXPECT_NEAR((k - h).norm(), (legs.At(legs.knee, 0) - h).norm(), 1e-12);
  // The knee still bends forwards, and the foot takes the target's turn in the world.
  const Vec line = (a - h).normalized();
  const Vec off = (k - h) - (k - h).dot(line) * line;
  EXPECT_GT(off.z(), 0.0);
  EXPECT_LT((hip * knee * ankle).angularDistance(turn), 1e-9);
  // The right leg was not asked to move.
  EXPECT_LT((legs.At(legs.reached, 1) - legs.At(legs.ankle, 1)).norm(), 1e-12);
}

TEST(FootLockJob, LowersThePelvisOnlyWhereALegCannotReach) {
  Legs legs(21);
  legs.smooth[0] = 3;
  for (std::size_t p = 0; p < legs.poses; ++p) {
    legs.target[6 * p + 1] = p == 10 ? -0.1 : 0.032;  // one pose asks the left foot 13 cm lower
    legs.weight[2 * p] = 1.0;
  }
  ASSERT_NO_THROW(legs.Job().Run());
  EXPECT_GT(legs.drop[10], 0.1);
  EXPECT_EQ(legs.drop[0], 0.0);
  EXPECT_EQ(legs.drop[20], 0.0);
  for (std::size_t p = 1; p < legs.poses; ++p)  // eased: no jump between poses
    EXPECT_LT(std::abs(legs.drop[p] - legs.drop[p - 1]), 0.6 * legs.drop[10]);
  EXPECT_LT((legs.At(legs.reached, 20) - Vec(0.1, -0.1, 0.0)).norm(), 2e-3);
  // Never fully straight.
  const Vec h = legs.At(legs.hip, 20) - legs.drop[10] * Vec::UnitY();
  EXPECT_LT((legs.At(legs.reached, 20) - h).norm(), 0.9995 * (0.87 + 1e-3));
}

}  // namespace
