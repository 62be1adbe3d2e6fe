#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "job_checks.h"
#include "mocapedit/plausibility.h"

namespace {

using mocapedit::PlausibilityJob;
using mocapedit::Span;

constexpr double kPi = 3.141592653589793;

// Y up. The facing joint's world matrix facing `heading` (radians, counter-clockwise about up)
// at ground point (u, v): local axis 0 points along the heading, axis 1 up.
void PushHip(std::vector<double>& m, double heading, double u, double v) {
  const double c = std::cos(heading), s = std::sin(heading);
  const double rows[16] = {c, 0, -s, 0, 0, 1, 0, 0, s, 0, c, 0, u, 0.9, -v, 1};
  m.insert(m.end(), rows, rows + 16);
}

// Agents, each a source and an edited run of samples at 24 per second, and the job's outputs.
struct Crowd {
  std::vector<std::int64_t> source_offsets{0}, edited_offsets{0};
  std::vector<double> source_seconds, source_hip, edited_seconds, edited_hip, edited_frames;
  std::vector<double> max_facing_rate, source_max_facing_rate, max_extra_facing_rate, max_direction_deviation;
  std::vector<double> max_turned_deviation, max_edit_turn, length_ratio, time_warp_min, time_warp_max;
  std::vector<std::int64_t> worst_turn_frame, spin_frames, worst_direction_frame;

  // A source walking along +u at 1.2 units per second facing the way it walks, and its edit: the
  // same walk turned by `turn` radians about the start, facing `extra_facing(i)` more,
  // played at `frames` (or frame by frame when empty).
  template <typename Facing>
  void Add(std::size_t samples, double turn, Facing extra_facing, const std::vector<double>& frames = {}) {
    for (std::size_t i = 0; i < samples; ++i) {
      source_seconds.push_back(static_cast<double>(i) / 24.0);
      PushHip(source_hip, 0.0, 1.2 * static_cast<double>(i) / 24.0, 0.0);
    }
    const std::size_t edited = frames.empty() ? samples : frames.size();
    for (std::size_t i = 0; i < edited; ++i) {
      const double f = frames.empty() ? static_cast<double>(i) : frames[i];
      const double along = 1.2 * f / 24.0;
      edited_seconds.push_back(static_cast<double>(i) / 24.0);
      PushHip(edited_hip, turn + extra_facing(i), along * std::cos(turn), along * std::sin(turn));
      if (!frames.empty()) edited_frames.push_back(f);
    }
    source_offsets.push_back(source_offsets.back() + static_cast<std::int64_t>(samples));
    edited_offsets.push_back(edited_offsets.back() + static_cast<std::int64_t>(edited));
  }

  PlausibilityJob Job() {
    const std::size_t agents = source_offsets.size() - 1;
    for (auto* v : {&max_facing_rate, &source_max_facing_rate, &max_extra_facing_rate, &max_direction_deviation,
                    &max_turned_deviation, &max_edit_turn, &length_ratio, &time_warp_min, &time_warp_max})
      v->assign(agents, -7.0);
    for (auto* v : {&worst_turn_frame, &spin_frames, &worst_direction_frame}) v->assign(agents, -7);
    PlausibilityJob job;
    job.source_offsets = source_offsets, job.edited_offsets = edited_offsets;
    job.source_seconds = source_seconds, job.source_hip = source_hip;
    job.edited_seconds = edited_seconds, job.edited_hip = edited_hip, job.edited_frames = edited_frames;
    job.walking_speed = 0.2, job.chord = 0.25, job.edit_turn_span = 2.0, job.spin_rate = 900.0;
    job.max_facing_rate = max_facing_rate, job.source_max_facing_rate = source_max_facing_rate;
    job.max_extra_facing_rate = max_extra_facing_rate, job.worst_turn_frame = worst_turn_frame;
    job.spin_frames = spin_frames, job.max_direction_deviation = max_direction_deviation;
    job.worst_direction_frame = worst_direction_frame, job.max_turned_deviation = max_turned_deviation;
    job.max_edit_turn = max_edit_turn, job.length_ratio = length_ratio;
    job.time_warp_min = time_warp_min, job.time_warp_max = time_warp_max;
    return job;
  }
};

double None(std::size_t) { return 0.0; }

TEST(PlausibilityJob, ValidityRejectsEveryBadSetup) {
  Crowd crowd;
  crowd.Add(48, 0.0, None);
  crowd.Add(30, 0.5, None);
  EXPECT_EQ(Rejection(crowd.Job()), "");
  {
    auto job = crowd.Job();
    job.source_offsets = Span<const std::int64_t>();
    EXPECT_NE(Rejection(job).find("offsets"), std::string::npos);
  }
  {
    std::vector<std::int64_t> late{1, 48, 78};
    auto job = crowd.Job();
    job.edited_offsets = late;
    EXPECT_NE(Rejection(job).find("start at 0"), std::string::npos);
  }
  {
    std::vector<std::int64_t> back{0, 48, 40};
    auto job = crowd.Job();
    job.source_offsets = back;
    EXPECT_NE(Rejection(job), "");
  }
  {
    std::vector<std::int64_t> one{0, 78};
    auto job = crowd.Job();
    job.edited_offsets = one;
    EXPECT_NE(Rejection(job).find("as many agents"), std::string::npos);
  }
  {
    auto job = crowd.Job();
    job.source_hip.size -= 16;
    EXPECT_NE(Rejection(job).find("source_hip"), std::string::npos);
  }
  {
    auto job = crowd.Job();
    job.edited_seconds.size -= 1;
    EXPECT_NE(Rejection(job).find("edited_seconds"), std::string::npos);
  }
  {
    std::vector<double> short_frames(10, 0.0);
    auto job = crowd.Job();
    job.edited_frames = short_frames;
    EXPECT_NE(Rejection(job).find("edited_frames"), std::string::npos);
  }
  {
    auto job = crowd.Job();
    job.spin_frames.size = 1;
    EXPECT_NE(Rejection(job).find("spin_frames"), std::string::npos);
  }
  {
    auto job = crowd.Job();
    job.up_axis = 0;
    EXPECT_NE(Rejection(job).find("up_axis"), std::string::npos);
  }
  for (double bad : {0.0, -1.0, std::nan("")}) {
    auto job = crowd.Job();
    job.chord = bad;
    EXPECT_NE(Rejection(job).find("chord"), std::string::npos);
    job = crowd.Job();
    job.walking_speed = bad;
    EXPECT_NE(Rejection(job).find("walking_speed"), std::string::npos);
  }
  {
    auto job = crowd.Job();  // the thresholds have no defaults
    job.walking_speed = PlausibilityJob().walking_speed, job.spin_rate = PlausibilityJob().spin_rate;
    EXPECT_NE(Rejection(job), "");
  }
  {
    crowd.edited_seconds[50] = crowd.edited_seconds[49];  // the second agent's times stall
    EXPECT_NE(Rejection(crowd.Job()).find("agent 1"), std::string::npos);
  }
}

TEST(PlausibilityJob, InvalidInputLeavesTheOutputsUntouched) {
  Crowd crowd;
  crowd.Add(48, 0.0, None);
  auto job = crowd.Job();
  job.up_axis = 3;
  EXPECT_THROW(job.Run(), mocapedit::InvalidInput);
  EXPECT_EQ(crowd.max_facing_rate[0], -7.0);
}

TEST(PlausibilityJob, AWalkTurnedByTheEditKeepsItsWayAgainstTheTurn) {
  Crowd crowd;
  crowd.Add(72, 0.5 * kPi, None);    // the whole walk turned by a right angle, facing with it
  crowd.Add(72, 0.0, None);          // untouched
  auto job = crowd.Job();
  job.Run();
  for (int a = 0; a < 2; ++a) {
    EXPECT_NEAR(crowd.max_facing_rate[a], 0.0, 1e-9);
    EXPECT_NEAR(crowd.max_extra_facing_rate[a], 0.0, 1e-9);
    EXPECT_EQ(crowd.spin_frames[a], 0);
    EXPECT_NEAR(crowd.max_turned_deviation[a], 0.0, 1e-6);
    EXPECT_NEAR(crowd.length_ratio[a], 1.0, 1e-12);
    EXPECT_DOUBLE_EQ(crowd.time_warp_min[a], 1.0);
    EXPECT_DOUBLE_EQ(crowd.time_warp_max[a], 1.0);
  }
  EXPECT_NEAR(crowd.max_direction_deviation[0], 90.0, 1e-6);
  EXPECT_NEAR(crowd.max_edit_turn[0], 90.0, 1e-6);
  EXPECT_GE(crowd.worst_direction_frame[0], 0);
  EXPECT_NEAR(crowd.max_direction_deviation[1], 0.0, 1e-6);
  EXPECT_NEAR(crowd.max_edit_turn[1], 0.0, 1e-6);
}

TEST(PlausibilityJob, SpinsAreTurnsFasterThanTheSpinRateWhereTheSourceDoesNot) {
  Crowd crowd;
  // 45 degrees a sample at 24 per second (1080 degrees per second) over samples 10 .. 13.
  crowd.Add(48, 0.0, [](std::size_t i) { return i <= 10 ? 0.0 : 0.25 * kPi * static_cast<double>(std::min<std::size_t>(i, 14) - 10); });
  auto job = crowd.Job();
  job.Run();
  EXPECT_EQ(crowd.spin_frames[0], 4);
  EXPECT_NEAR(crowd.max_facing_rate[0], 1080.0, 1e-6);
  EXPECT_NEAR(crowd.max_extra_facing_rate[0], 1080.0, 1e-6);
  EXPECT_GE(crowd.worst_turn_frame[0], 10);   // the first of four equal turns, to rounding
  EXPECT_LE(crowd.worst_turn_frame[0], 13);
  EXPECT_NEAR(crowd.source_max_facing_rate[0], 0.0, 1e-9);
}

TEST(PlausibilityJob, AFacingThatCrossesHalfATurnIsUnwrapped) {
  Crowd crowd;
  // Facing 170 degrees, then -170 after sample 20: a turn of 20 degrees, not 340.
  crowd.Add(48, 0.0, [](std::size_t i) { return i <= 20 ? kPi * 170.0 / 180.0 : -kPi * 170.0 / 180.0; });
  auto job = crowd.Job();
  job.Run();
  EXPECT_NEAR(crowd.max_facing_rate[0], 20.0 * 24.0, 1e-6);
}

TEST(PlausibilityJob, ATimeMapSetsTheWarpAndTheHeldEndsDoNotWalk) {
  Crowd crowd;
  // The source's first 48 frames played at half speed, then held for 12 samples.
  std::vector<double> frames;
  for (int i = 0; i < 96; ++i) frames.push_back(0.5 * i);
  for (int i = 0; i < 12; ++i) frames.push_back(47.5);
  crowd.Add(72, 0.0, None, frames);
  auto job = crowd.Job();
  job.Run();
  EXPECT_NEAR(crowd.time_warp_min[0], 2.0, 1e-9);
  EXPECT_NEAR(crowd.time_warp_max[0], 2.0, 1e-9);
  EXPECT_NEAR(crowd.max_direction_deviation[0], 0.0, 1e-6);
  EXPECT_LT(crowd.worst_direction_frame[0], 96);   // a sample that advances
  EXPECT_NEAR(crowd.max_extra_facing_rate[0], 0.0, 1e-9);
}

TEST(PlausibilityJob, TooFewSamplesGiveTheNeutralFigures) {
  Crowd crowd;
  crowd.Add(1, 0.0, None);
  auto job = crowd.Job();
  job.Run();
  EXPECT_EQ(crowd.worst_turn_frame[0], -1);
  EXPECT_EQ(crowd.worst_direction_frame[0], -1);
  EXPECT_TRUE(std::isnan(crowd.max_direction_deviation[0]));
  EXPECT_EQ(crowd.max_edit_turn[0], 0.0);
  EXPECT_EQ(crowd.time_warp_min[0], 1.0);
}

TEST(PlausibilityMeasures, DirectionDeviationIsNaNWhereTheSourceStands) {
  const std::size_t n = 24;
  std::vector<double> source, edited, seconds, out(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / 24.0;
    seconds.push_back(t);
    source.insert(source.end(), {i < 12 ? t : 0.5, 0.0});   // walks, then stands
    edited.insert(edited.end(), {0.0, i < 12 ? t : 0.5});   // the same, a quarter turn left
  }
  mocapedit::DirectionDeviation(source, edited, seconds, 0.2, 0.25, Span<const double>(), out);
  EXPECT_NEAR(out[0], 90.0, 1e-9);
  EXPECT_TRUE(std::isnan(out[12]));
  EXPECT_TRUE(std::isnan(out[n - 1]));   // no full chord
  std::vector<double> turn(n, 0.5 * kPi), turned(n);
  mocapedit::DirectionDeviation(source, edited, seconds, 0.2, 0.25, turn, turned);
  EXPECT_NEAR(turned[0], 0.0, 1e-9);
  std::vector<double> edit(n);
  mocapedit::EditTurn(source, edited, seconds, 0.2, 2.0, edit);
  for (double a : edit) EXPECT_NEAR(a, 0.5 * kPi, 1e-9);   // held past the walk
  std::vector<double> wrong(n - 1);
  EXPECT_THROW(mocapedit::EditTurn(source, edited, seconds, 0.2, 2.0, wrong), mocapedit::InvalidInput);
}

TEST(PlausibilityMeasures, TurningRatesNeedIncreasingTimes) {
  std::vector<double> facing{0.0, 0.1, 0.2}, seconds{0.0, 0.5, 0.5}, rates(2);
  EXPECT_THROW(mocapedit::TurningRates(facing, seconds, rates), mocapedit::InvalidInput);
  seconds[2] = 1.0;
  mocapedit::TurningRates(facing, seconds, rates);
  EXPECT_NEAR(rates[0], 0.2 * 180.0 / kPi, 1e-9);
}

}  // namespace
