#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "job_checks.h"
#include "mocapedit/foot_plant.h"

namespace {

using mocapedit::FootPlantJob;
using mocapedit::Span;

// #A agents of 40 poses at 24 fps, each standing on both feet (contacts at frames 5 to 30);
// the edit drags the body `drag` forwards (+Z) over the contact, the source stays put. Legs
// hang from hips 0.1 apart, thigh 0.45 and shin 0.42 long; every rotation is the identity.
struct Stand {
  static constexpr std::size_t kPoses = 40;
  std::size_t agents;
  std::vector<std::int64_t> offsets, contact_offsets;
  std::vector<std::uint8_t> stationary, stepping;
  std::vector<double> frames, seconds, turn, hip, knee, ankle, ankle_rot, source_hip, source_ankle, source_rot;
  std::vector<double> contacts, blend, stretch, turn_leash, reach_leash, step_leash, up{0, 1, 0};
  std::vector<double> target, target_rot, weight;
  std::vector<std::int64_t> steps;

  Stand(std::size_t a, double drag) : agents(a) {
    offsets.push_back(0);
    contact_offsets.push_back(0);
    for (std::size_t i = 0; i < a; ++i) {
      offsets.push_back(offsets.back() + static_cast<std::int64_t>(kPoses));
      for (int leg = 0; leg < 2; ++leg) {
        contacts.insert(contacts.end(), {5.0, 30.0});
        contact_offsets.push_back(contact_offsets.back() + 1);
      }
      blend.push_back(2.0);
      turn_leash.push_back(1.0);
      reach_leash.push_back(1.0);
      step_leash.push_back(1.0);
      stretch.insert(stretch.end(), {1.0, 1.0});
      for (std::size_t t = 0; t < kPoses; ++t) {
        const double f = static_cast<double>(t);
        frames.push_back(f), seconds.push_back(f / 24.0), turn.push_back(0.0), stationary.push_back(0);
        const double z = drag * std::min(std::max((f - 5.0) / 25.0, 0.0), 1.0);
        for (int leg = 0; leg < 2; ++leg) {
          const double x = leg == 0 ? 0.1 : -0.1;
          hip.insert(hip.end(), {x, 0.9, z}), knee.insert(knee.end(), {x, 0.451, z + 0.02});
          ankle.insert(ankle.end(), {x, 0.032, z});
          source_hip.insert(source_hip.end(), {x, 0.9, 0.0}), source_ankle.insert(source_ankle.end(), {x, 0.032, 0.0});
          ankle_rot.insert(ankle_rot.end(), {0, 0, 0, 1}), source_rot.insert(source_rot.end(), {0, 0, 0, 1});
        }
      }
    }
    const std::size_t n = a * kPoses;
    target.resize(n * 6), target_rot.resize(n * 8), weight.resize(n * 2), stepping.resize(n * 2), steps.resize(a);
  }

  FootPlantJob Job() {
    FootPlantJob job;
    job.offsets = offsets, job.frames = frames, job.seconds = seconds, job.stationary = stationary, job.turn = turn;
    job.hip = hip, job.knee = knee, job.ankle = ankle, job.ankle_rot = ankle_rot;
    job.source_hip = source_hip, job.source_ankle = source_ankle;
    job.source_hip_rot = source_rot, job.source_knee_rot = source_rot, job.source_ankle_rot = source_rot;
    job.contact_offsets = contact_offsets, job.contacts = contacts, job.blend = blend, job.stretch = stretch;
    job.turn_leash = turn_leash, job.reach_leash = reach_leash, job.step_leash = step_leash;
    job.up = up;
    job.target = target, job.target_rot = target_rot, job.weight = weight, job.stepping = stepping, job.steps = steps;
    return job;
  }
};

TEST(FootPlantJob, Validate) {
  Stand s(2, 0.1);
  EXPECT_EQ(Rejection(s.Job()), "");
  {
    std::vector<std::int64_t> bad{1, 40, 80};
    auto job = s.Job();
    job.offsets = bad;
    EXPECT_NE(Rejection(job).find("start at 0"), std::string::npos);
  }
  {
    auto job = s.Job();
    job.knee = Span<const double>(s.knee.data(), s.knee.size() - 6);
    EXPECT_NE(Rejection(job).find("knee must hold"), std::string::npos);
  }
  {
    std::vector<double> tilted{0, 0.6, 0.8};
    auto job = s.Job();
    job.up = tilted;
    EXPECT_NE(Rejection(job).find("up must be"), std::string::npos);
  }
  {
    std::vector<std::int64_t> short_contacts{0, 1, 2, 3, 5};
    auto job = s.Job();
    job.contact_offsets = short_contacts;
    EXPECT_NE(Rejection(job).find("contacts must hold"), std::string::npos);
  }
  {
    s.stretch[1] = 0.0;
    EXPECT_NE(Rejection(s.Job()).find("stretch"), std::string::npos);
    s.stretch[1] = 1.0;
  }
  {
    s.turn_leash[0] = -1.0;
    EXPECT_NE(Rejection(s.Job()).find("turn_leash must be finite and positive"), std::string::npos);
    s.turn_leash[0] = 1.0;
    auto job = s.Job();
    job.turn_leash = Span<const double>(s.turn_leash.data(), 1);
    EXPECT_NE(Rejection(job).find("turn_leash must hold 2"), std::string::npos);
    s.reach_leash[1] = 0.5;
    EXPECT_NE(Rejection(s.Job()).find("reach_leash must be finite and at least 1"), std::string::npos);
    s.reach_leash[1] = 1.0;
    s.step_leash[0] = std::nan("");
    EXPECT_NE(Rejection(s.Job()).find("step_leash must be finite and at least 1"), std::string::npos);
    s.step_leash[0] = 1.0;
  }
  {
    auto job = s.Job();
    job.leash_m = 0.2;  // above max_leash_m
    EXPECT_NE(Rejection(job).find("max_leash_m"), std::string::npos);
  }
  {
    auto job = s.Job();
    job.step_foot_speed_ratio = 0.0;
    EXPECT_NE(Rejection(job).find("step_foot_speed_ratio must be positive"), std::string::npos);
    job = s.Job();
    job.step_min_knee_speed = -1.0;
    EXPECT_NE(Rejection(job).find("step_min_knee_speed must not be negative"), std::string::npos);
    job = s.Job();
    job.step_min_foot_speed_m = std::nan("");
    EXPECT_NE(Rejection(job).find("step_min_foot_speed_m"), std::string::npos);
  }
  {
    auto job = s.Job();
    job.target = Span<double>(s.hip.data(), s.hip.size());
    EXPECT_NE(Rejection(job).find("target overlaps the input hip"), std::string::npos);
  }
}

TEST(FootPlantJob, AFootDraggedWithinTheLeashStaysPlanted) {
  Stand s(1, 0.1);
  s.Job().Run();
  EXPECT_EQ(s.steps[0], 0);
  for (std::size_t t = 0; t < Stand::kPoses; ++t)
    for (std::size_t leg = 0; leg < 2; ++leg) {
      const std::size_t i = 2 * t + leg;
      EXPECT_EQ(s.stepping[i], 0);
      if (t >= 5 && t <= 30) {
        // One plant: the source foot shifted to where the edit puts it on average (5 cm on).
        EXPECT_EQ(s.weight[i], 1.0);
        for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(s.target[3 * i + c], s.target[3 * (2 * 5 + leg) + c]);
        EXPECT_NEAR(s.target[3 * i + 2], 0.05, 1e-12);
        EXPECT_LE(std::abs(s.target[3 * i + 2] - s.ankle[3 * i + 2]), 0.08);
      }
      if (t <= 2) {
        EXPECT_EQ(s.weight[i], 0.0);
        EXPECT_EQ(s.target[3 * i + 2], s.ankle[3 * i + 2]);
      }
      EXPECT_NEAR(s.target_rot[4 * i + 3], 1.0, 1e-12);
    }
}

// The plant's turn about up at pose t, leg `leg` (degrees).
double PlantYaw(const Stand& s, std::size_t t, std::size_t leg) {
  const std::size_t i = 2 * t + leg;
  return 2.0 * std::atan2(s.target_rot[4 * i + 1], s.target_rot[4 * i + 3]) * 180.0 / 3.14159265358979323846;
}

TEST(FootPlantJob, APlantLagsTheBodysTurnByItsTurnLeash) {
  // The edit turns the body 40 degrees over the contact: the plant holds its turn within
  // leash_degrees (15) times the agent's turn_leash of the contact's mean turn, and turns along
  // beyond.
  for (double leash : {1.0, 2.0}) {
    Stand s(1, 0.0);
    for (std::size_t t = 0; t < Stand::kPoses; ++t)
      s.turn[t] = 40.0 * 3.14159265358979323846 / 180.0 * std::min(std::max((static_cast<double>(t) - 5.0) / 25.0, 0.0), 1.0);
    s.turn_leash[0] = leash;
    s.Job().Run();
    for (std::size_t leg = 0; leg < 2; ++leg) {
      const double swing = PlantYaw(s, 30, leg) - PlantYaw(s, 5, leg);
      if (leash == 1.0)
        EXPECT_NEAR(swing, 10.0, 0.5) << "both ends of the 40-degree turn lie 20 from its mean: 5 past the leash";
      else
        EXPECT_NEAR(swing, 0.0, 1e-9) << "30 degrees of leash hold the plant through it";
    }
  }
}

TEST(FootPlantJob, APlantLiesAsFarAsItsReachLeashLets) {
  // Bent legs (hips 0.75 up) that reach far; the edit drags the body 0.4 forwards over the
  // contact. The plant lies where the edit puts the foot on average, 0.2 from either end: past
  // max_leash_m (0.15) it is dragged along, within 5/3 of it (0.25) it stays.
  for (double leash : {1.0, 5.0 / 3.0}) {
    Stand s(1, 0.4);
    for (std::size_t i = 0; i < Stand::kPoses * 2; ++i) {
      s.hip[3 * i + 1] = 0.75;
      s.knee[3 * i + 1] = 0.40, s.knee[3 * i + 2] = s.ankle[3 * i + 2] + 0.25;
    }
    s.reach_leash[0] = leash, s.step_leash[0] = leash;
    s.Job().Run();
    for (std::size_t leg = 0; leg < 2; ++leg) {
      const double moved = s.target[3 * (2 * 30 + leg) + 2] - s.target[3 * (2 * 5 + leg) + 2];
      if (leash == 1.0)
        EXPECT_GT(moved, 0.05) << "dragged past the leash";
      else
        EXPECT_NEAR(moved, 0.0, 1e-9) << "held within the longer leash";
    }
  }
}

TEST(FootPlantJob, AgentsAreIndependentOfTheirRunAndThreads) {
  Stand one(1, 0.3), three(3, 0.3);
  one.Job().Run();
  for (int threads : {1, 2, 3}) {
    auto job = three.Job();
    job.threads = threads;
    job.Run();
    for (std::size_t a = 0; a < 3; ++a) {
      const std::size_t at = a * Stand::kPoses * 2;
      for (std::size_t i = 0; i < Stand::kPoses * 2; ++i) {
        EXPECT_EQ(three.weight[at + i], one.weight[i]);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(three.target[3 * (at + i) + c], one.target[3 * i + c]);
      }
      EXPECT_EQ(three.steps[a], one.steps[0]);
    }
  }
}

}  // namespace
