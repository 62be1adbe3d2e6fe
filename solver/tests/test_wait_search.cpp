#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "mocapedit/wait_search.h"

using mocapedit::SmoothDelay;
using mocapedit::Trajectory2;
using mocapedit::WaitDelay;
using mocapedit::WaitQuery;
using mocapedit::WaitSearch;
using mocapedit::WaitSettings;
using mocapedit::WaitWalker;

namespace {

constexpr int kSamples = 240;  // one sample per frame, frames at times 0, 1, ...

// Straight walks at 1.2 m/s (24 fps), each reaching its crossing point at `meet`.
struct Walk {
  double x0, y0, dx, dy;  // position at frame 0 and step per frame
};

Walk Through(double dir_x, double dir_y, int meet) {
  const double v = 0.05;
  return {-dir_x * v * meet, -dir_y * v * meet, dir_x * v, dir_y * v};
}

Trajectory2 Path(const Walk& w) {
  Trajectory2 p(kSamples, 2);
  for (int f = 0; f < kSamples; ++f) p.row(f) << w.x0 + w.dx * f, w.y0 + w.dy * f;
  return p;
}

Trajectory2 Positions(const std::vector<Walk>& walks) {
  const int a = static_cast<int>(walks.size());
  Trajectory2 p(static_cast<Eigen::Index>(kSamples) * a, 2);
  for (int k = 0; k < kSamples; ++k)
    for (int i = 0; i < a; ++i) p.row(static_cast<Eigen::Index>(k) * a + i) = Path(walks[i]).row(k);
  return p;
}

Eigen::VectorXd Frames() { return Eigen::VectorXd::LinSpaced(kSamples, 0.0, kSamples - 1.0); }

// Smallest distance between the walker, played at `times`, and agent `other` over all samples.
double Closest(const Walk& walker, const Eigen::VectorXd& times, const Walk& other) {
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k < kSamples; ++k) {
    // The frame the walker shows at shot time k (its time map is increasing).
    int j = 0;
    while (j + 1 < kSamples && times[j + 1] <= k) ++j;
    const double f = j + 1 < kSamples ? j + (k - times[j]) / (times[j + 1] - times[j]) : j;
    const double x = walker.x0 + walker.dx * f, y = walker.y0 + walker.dy * f;
    best = std::min(best, std::hypot(other.x0 + other.dx * k - x, other.y0 + other.dy * k - y));
  }
  return best;
}

WaitSettings Settings() {
  WaitSettings s;
  s.time_codes_per_second = 24.0;
  s.sample_step = 1.0;
  s.step = 6.0;
  s.margin = 0.05;
  s.block = 24;
  return s;
}

}  // namespace

TEST(WaitSearch, ValidityRejectsBadInput) {
  const Eigen::VectorXd radius = Eigen::VectorXd::Constant(2, 0.3);
  const Trajectory2 p = Positions({Through(1, 0, 100), Through(0, 1, 100)});
  {  // positions not samples x agents
    EXPECT_THROW(WaitSearch(p.topRows(10), Frames(), radius, Settings()), mocapedit::InvalidInput);
  }
  {  // a bad setting
    WaitSettings s = Settings();
    s.slowest_pace = 1.0;
    EXPECT_THROW(WaitSearch(p, Frames(), radius, s), mocapedit::InvalidInput);
  }
  {  // non-finite positions
    Trajectory2 bad = p;
    bad(3, 1) = std::nan("");
    EXPECT_THROW(WaitSearch(bad, Frames(), radius, Settings()), mocapedit::InvalidInput);
  }
  const WaitSearch search(p, Frames(), radius, Settings());
  const Trajectory2 path = Path(Through(0, 1, 100));
  const Eigen::VectorXd times = Frames();
  const WaitWalker walker{path, times, times};
  {  // the same agent twice
    WaitQuery q{1, 1, 90, 110, 72.0, 6.0};
    EXPECT_THROW(search.LeastDelay(q, walker), mocapedit::InvalidInput);
  }
  {  // the encounter past the last sample
    WaitQuery q{1, 0, 90, kSamples, 72.0, 6.0};
    EXPECT_THROW(search.LeastDelay(q, walker), mocapedit::InvalidInput);
  }
  {  // a time map of another length
    const Eigen::VectorXd short_times = times.head(10);
    const WaitWalker bad{path, short_times, times};
    WaitQuery q{1, 0, 90, 110, 72.0, 6.0};
    EXPECT_THROW(search.LeastDelay(q, bad), mocapedit::InvalidInput);
  }
}

TEST(WaitSearch, SmoothDelayTakesTheDelayUpBetweenStartAndEnd) {
  const Eigen::VectorXd t = Frames();
  const Eigen::VectorXd d = SmoothDelay(t, 40.0, 88.0, 12.0);
  for (int i = 0; i < kSamples; ++i) {
    if (i <= 40) EXPECT_EQ(d[i], t[i]);
    if (i >= 88) EXPECT_DOUBLE_EQ(d[i], t[i] + 12.0);
    if (i > 0) {
      EXPECT_GE(d[i] - d[i - 1], 1.0 - 1e-12);        // no interval shrinks
      EXPECT_LE(d[i] - d[i - 1], 1.0 + 1.5 * 12.0 / 48.0 + 1e-12);  // steepest: 1.5 x the mean
    }
  }
}

TEST(WaitSearch, TheLaterWalkerWaitsUntilTheOtherHasPassed) {
  const std::vector<Walk> walks = {Through(1, 0, 100), Through(0, 1, 100)};
  const Eigen::VectorXd radius = Eigen::VectorXd::Constant(2, 0.3);
  const WaitSettings s = Settings();
  const WaitSearch search(Positions(walks), Frames(), radius, s);
  const Trajectory2 path = Path(walks[1]);
  const Eigen::VectorXd times = Frames();
  const WaitWalker walker{path, times, times};
  const double clearance = 0.6 + s.margin;
  ASSERT_LT(Closest(walks[1], times, walks[0]), clearance);
  const WaitDelay found = search.LeastDelay({1, 0, 91, 109, 72.0, 1.0}, walker);
  ASSERT_TRUE(found.found);
  EXPECT_EQ(std::fmod(found.delay, s.step), 0.0);
  EXPECT_DOUBLE_EQ(found.end, 91.0 - 2.4);
  EXPECT_GE(Closest(walks[1], found.times, walks[0]), clearance);
  for (int i = 0; i < kSamples; ++i) EXPECT_EQ(found.times[i], SmoothDelay(times, found.start, found.end, found.delay)[i]);
  // The least: a step less still meets the other.
  if (found.delay > s.step) {
    const double less = found.delay - s.step;
    const double start = found.end - std::max(1.5 * less, 24.0);
    EXPECT_LT(Closest(walks[1], SmoothDelay(times, start, found.end, less), walks[0]), clearance);
  }
  // No room for it: none.
  EXPECT_FALSE(search.LeastDelay({1, 0, 91, 109, found.delay - 1.0, 1.0}, walker).found);
}

TEST(WaitSearch, AWaitStartsNoEarlierThanTheWalkersEarliest) {
  // The walker's frames up to its earliest keep their times: a wait starts at it or later, and
  // one that would have to start before it is none.
  const std::vector<Walk> walks = {Through(1, 0, 100), Through(0, 1, 100)};
  const WaitSettings s = Settings();
  const WaitSearch search(Positions(walks), Frames(), Eigen::VectorXd::Constant(2, 0.3), s);
  const Trajectory2 path = Path(walks[1]);
  const Eigen::VectorXd times = Frames();
  const WaitQuery query{1, 0, 91, 109, 72.0, 1.0};
  const WaitDelay free = search.LeastDelay(query, WaitWalker{path, times, times});
  ASSERT_TRUE(free.found);
  const WaitDelay at = search.LeastDelay(query, WaitWalker{path, times, times, free.start});
  ASSERT_TRUE(at.found);
  EXPECT_EQ(at.delay, free.delay);
  EXPECT_EQ(at.start, free.start);
  for (const double earliest : {free.start + 1.0, free.end - 1.0, free.end}) {
    const WaitDelay later = search.LeastDelay(query, WaitWalker{path, times, times, earliest});
    if (later.found) {
      EXPECT_GE(later.start, earliest);
      for (int i = 0; i < kSamples && times[i] <= earliest; ++i) EXPECT_EQ(later.times[i], times[i]);
    }
  }
  EXPECT_FALSE(search.LeastDelay(query, WaitWalker{path, times, times, free.end}).found);
}

TEST(WaitSearch, AWaitMeetsNobodyNew) {
  // A third walker crosses the same point a little after the first: the least delay that
  // parts the walker from the first would run it into the third, so it waits longer.
  const std::vector<Walk> two = {Through(1, 0, 100), Through(0, 1, 100)};
  const std::vector<Walk> three = {two[0], two[1], Through(1, 0, 120)};
  const Eigen::VectorXd times = Frames();
  const Trajectory2 path = Path(two[1]);
  const WaitWalker walker{path, times, times};
  const WaitSettings s = Settings();
  const double clearance = 0.6 + s.margin;
  const WaitDelay alone =
      WaitSearch(Positions(two), times, Eigen::VectorXd::Constant(2, 0.3), s).LeastDelay({1, 0, 91, 109, 72.0, 30.0}, walker);
  ASSERT_TRUE(alone.found);
  ASSERT_LT(Closest(two[1], alone.times, three[2]), clearance);
  ASSERT_GE(Closest(two[1], times, three[2]), clearance);
  const WaitDelay found =
      WaitSearch(Positions(three), times, Eigen::VectorXd::Constant(3, 0.3), s).LeastDelay({1, 0, 91, 109, 72.0, 30.0}, walker);
  ASSERT_TRUE(found.found);
  EXPECT_GT(found.delay, alone.delay);
  EXPECT_GE(Closest(two[1], found.times, three[0]), clearance);
  EXPECT_GE(Closest(two[1], found.times, three[2]), clearance);
}

TEST(WaitSearch, ARoundTakesEachWalkersFirstDelayAndRemembersWhatItTried) {
  // Walker 1 crosses walker 0, and walker 2 crosses walker 0 later: each of 1 and 2 waits once,
  // for its first encounter in the order given.
  const std::vector<Walk> walks = {Through(1, 0, 100), Through(0, 1, 100), Through(0, -1, 100)};
  const Eigen::VectorXd radius = Eigen::VectorXd::Constant(3, 0.3);
  const WaitSearch search(Positions(walks), Frames(), radius, Settings());
  const Eigen::VectorXd times = Frames();
  const std::vector<Trajectory2> paths = {Path(walks[0]), Path(walks[1]), Path(walks[2])};
  std::vector<WaitWalker> walkers;
  for (const auto& p : paths) walkers.push_back({p, times, times});
  const std::vector<mocapedit::WaitEncounter> encounters = {
      {1, 0, 91, 109, 1.0}, {1, 0, 91, 109, 1.0}, {2, 0, 91, 109, 1.0}};
  std::vector<double> delay(3, 0.0);
  mocapedit::WaitTried tried;
  const auto found = mocapedit::WaitRound(search, encounters, walkers, 72.0, 6.0, delay, tried);
  ASSERT_EQ(found.size(), 2u);
  EXPECT_EQ(found[0].first, 1);
  EXPECT_EQ(found[1].first, 2);
  const WaitDelay alone = search.LeastDelay({1, 0, 91, 109, 72.0, 1.0}, walkers[1]);
  EXPECT_EQ(found[0].second.delay, alone.delay);
  for (int i = 0; i < kSamples; ++i) EXPECT_EQ(found[0].second.times[i], alone.times[i]);
  EXPECT_EQ(delay[1], alone.delay);
  EXPECT_EQ(delay[2], found[1].second.delay);
  EXPECT_EQ(tried.size(), 2u);
  EXPECT_EQ(tried.at({1, 0}), std::make_pair(0.0, 0.0));
  // The same pairs with the same delays again: passed over. A walker with less than a step of
  // its budget left: passed over.
  std::vector<double> again(3, 0.0);
  EXPECT_TRUE(mocapedit::WaitRound(search, encounters, walkers, 72.0, 6.0, again, tried).empty());
  mocapedit::WaitTried fresh;
  std::vector<double> spent = {0.0, 70.0, 0.0};
  const auto left = mocapedit::WaitRound(search, encounters, walkers, 72.0, 6.0, spent, fresh);
  ASSERT_EQ(left.size(), 1u);
  EXPECT_EQ(left[0].first, 2);
  // An agent out of range is an error.
  std::vector<double> none(3, 0.0);
  EXPECT_THROW(mocapedit::WaitRound(search, {{3, 0, 91, 109, 1.0}}, walkers, 72.0, 6.0, none, fresh),
               mocapedit::InvalidInput);
}
