#include "mocapedit/collisions.h"
#include "mocapedit/errors.h"
#include "mocapedit/two_threads.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>

namespace mocapedit {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// One (pair, sample) closer than the margin or the watch distance.
struct Record {
  int a, b, sample;
  double clearance;
};

// What one worker finds over its samples.
struct Partial {
  std::vector<Record> records;
  Eigen::VectorXd min_clearance;
  Eigen::VectorXi min_sample;
  int64_t pair_tests = 0;

  explicit Partial(Eigen::Index agents)
      : min_clearance(Eigen::VectorXd::Constant(agents, kInf)),
        min_sample(Eigen::VectorXi::Constant(agents, -1)) {}
};

struct Problem {
  const Eigen::Ref<const Trajectory2>& positions;
  int samples;
  int agents;
  const CapsuleSet& capsules;
  double margin;
  double watch;   // records are kept below max(margin, watch)
  double report;  // clearances up to this are tracked per agent
  double reach;   // horizontal axis distance beyond which no pair matters

  const double* row(int sample, int agent) const {
    return positions.data() + 2 * (static_cast<Eigen::Index>(sample) * agents + agent);
  }
};

// Axis segment of a vertical capsule along up: [lo, hi].
inline void AxisSpan(double radius, double height, double base, double* lo, double* hi) {
  if (height >= 2.0 * radius) {
    *lo = base + radius;
    *hi = base + height - radius;
  } else {
    *lo = *hi = base + 0.5 * height;
  }
}

inline void Keep(Partial* out, int agent, double clearance, int sample) {
  double& best = out->min_clearance[agent];
  int& at = out->min_sample[agent];
  if (clearance < best || (clearance == best && sample < at)) {
    best = clearance;
    at = sample;
  }
}

inline void TestPair(const Problem& p, int sample, int a, int b, Partial* out) {
  if (a > b) std::swap(a, b);
  const double* pa = p.row(sample, a);
  const double* pb = p.row(sample, b);
  ++out->pair_tests;
  const auto& c = p.capsules;
  const double clearance = CapsuleClearance(pb[0] - pa[0], pb[1] - pa[1], c.radius[a], c.height[a],
                                            c.base[a], c.radius[b], c.height[b], c.base[b]);
  if (clearance < p.margin || clearance < p.watch) out->records.push_back({a, b, sample, clearance});
  if (clearance <= p.report) {
    Keep(out, a, clearance, sample);
    Keep(out, b, clearance, sample);
  }
}

bool IsActive(const CapsuleSet& c, int a) { return c.active.empty() || c.active[a] != 0; }

Problem Validate(const Eigen::Ref<const Trajectory2>& positions, int samples,
                 const CapsuleSet& capsules, const CollisionSettings& settings) {
  const Eigen::Index n = capsules.radius.size();
  if (samples < 0) throw InvalidInput("DetectCollisions", "samples must not be negative");
  if (capsules.height.size() != n || capsules.base.size() != n)
    throw InvalidInput("DetectCollisions", "radius, height and base need one value per agent");
  if (!capsules.active.empty() && static_cast<Eigen::Index>(capsules.active.size()) != n)
    throw InvalidInput("DetectCollisions", "active needs one flag per agent (or none)");
  if (positions.rows() != static_cast<Eigen::Index>(samples) * n)
    throw InvalidInput("DetectCollisions", "positions has " + std::to_string(positions.rows()) +
                                " rows, expected samples * agents = " +
                                std::to_string(static_cast<Eigen::Index>(samples) * n));
  if (!(settings.margin >= 0.0) || !std::isfinite(settings.margin))
    throw InvalidInput("DetectCollisions", "margin must be finite and not negative");
  if (std::isnan(settings.report_distance))
    throw InvalidInput("DetectCollisions", "report_distance must not be NaN");
  double max_radius = 0.0;
  for (Eigen::Index a = 0; a < n; ++a) {
    if (!IsActive(capsules, static_cast<int>(a))) continue;
    if (!(capsules.radius[a] > 0.0) || !std::isfinite(capsules.radius[a]))
      throw InvalidInput("DetectCollisions", "agent " + std::to_string(a) +
                                  " has a non-positive radius");
    if (!(capsules.height[a] > 0.0) || !std::isfinite(capsules.height[a]))
      throw InvalidInput("DetectCollisions", "agent " + std::to_string(a) +
                                  " has a non-positive height");
    if (!std::isfinite(capsules.base[a]))
      throw InvalidInput("DetectCollisions", "agent " + std::to_string(a) + " has a non-finite base");
    for (int k = 0; k < samples; ++k) {
      const auto row = positions.row(static_cast<Eigen::Index>(k) * n + a);
      if (!std::isfinite(row[0]) || !std::isfinite(row[1]))
        throw InvalidInput("DetectCollisions", "agent " + std::to_string(a) +
                                    " has a non-finite position at sample " + std::to_string(k));
    }
    max_radius = std::max(max_radius, capsules.radius[a]);
  }
  if (std::isnan(settings.watch_distance) || std::isinf(settings.watch_distance))
    throw InvalidInput("DetectCollisions", "watch_distance must be finite");
  const double watch = settings.watch_distance > settings.margin ? settings.watch_distance : settings.margin;
  const double report = std::max(settings.margin, settings.report_distance);
  return Problem{positions, samples, static_cast<int>(n), capsules, settings.margin, watch, report,
                 std::max(report, watch) + 2.0 * max_radius};
}

// Uniform grid over one sample: agents sorted by cell; each occupied cell is tested
// against itself and the four neighbours that follow it (the other four test it).
// `cells`: empty, or the active agents sorted by cell at the previous sample (any order of
// them would do); left sorted at this sample.
void GridSample(const Problem& p, int sample, std::vector<std::pair<uint64_t, int>>* cells,
                Partial* out) {
  const double inv = p.reach > 0.0 ? 1.0 / p.reach : 1.0;
  constexpr int64_t kLimit = int64_t(1) << 30;
  auto key = [](int64_t cx, int64_t cy) {
    return (static_cast<uint64_t>(cx + (int64_t(1) << 31)) << 32) |
           static_cast<uint64_t>(static_cast<uint32_t>(cy + (int64_t(1) << 31)));
  };
  auto cell_of = [&](int a) {
    const double* x = p.row(sample, a);
    const int64_t cx = static_cast<int64_t>(std::clamp(std::floor(x[0] * inv), -double(kLimit), double(kLimit)));
    const int64_t cy = static_cast<int64_t>(std::clamp(std::floor(x[1] * inv), -double(kLimit), double(kLimit)));
    return key(cx, cy);
  };
  if (cells->empty()) {
    for (int a = 0; a < p.agents; ++a)
      if (IsActive(p.capsules, a)) cells->emplace_back(cell_of(a), a);
    std::sort(cells->begin(), cells->end());
  } else {
    // The same agents as at the caller's previous sample, in that sample's order: agents
    // move a little from one sample to the next, so the order is nearly sorted already and
    // an insertion sort puts it right in a few moves per agent that changed cell (the same
    // order a full sort gives: (cell, agent) pairs are distinct). A sample that moved
    // everyone (a cut) falls back on the full sort.
    for (auto& e : *cells) e.first = cell_of(e.second);
    const size_t n = cells->size();
    size_t moves = 0;
    const size_t budget = 8 * n + 64;
    auto& w = *cells;
    for (size_t i = 1; i < n && moves <= budget; ++i) {
      if (!(w[i] < w[i - 1])) continue;
      const auto item = w[i];
      size_t j = i;
      for (; j > 0 && item < w[j - 1]; --j) w[j] = w[j - 1];
      w[j] = item;
      moves += i - j;
    }
    if (moves > budget) std::sort(cells->begin(), cells->end());
  }
  const auto& v = *cells;
  const size_t n = v.size();
  auto cell_end = [&](size_t i) {
    size_t j = i + 1;
    while (j < n && v[j].first == v[i].first) ++j;
    return j;
  };
  for (size_t i = 0; i < n;) {
    const size_t end = cell_end(i);
    const int64_t cx = static_cast<int64_t>(v[i].first >> 32) - (int64_t(1) << 31);
    const int64_t cy = static_cast<int64_t>(v[i].first & 0xffffffffu) - (int64_t(1) << 31);
    for (size_t s = i; s < end; ++s)
      for (size_t t = s + 1; t < end; ++t) TestPair(p, sample, v[s].second, v[t].second, out);
    // (cx, cy + 1) directly follows this cell when it is occupied.
    if (end < n && v[end].first == key(cx, cy + 1)) {
      const size_t end2 = cell_end(end);
      for (size_t s = i; s < end; ++s)
        for (size_t t = end; t < end2; ++t) TestPair(p, sample, v[s].second, v[t].second, out);
    }
    // (cx + 1, cy - 1 .. cy + 1) are consecutive in the order.
    const uint64_t lo = key(cx + 1, cy - 1), hi = key(cx + 1, cy + 1);
    auto it = std::lower_bound(v.begin() + end, v.end(), std::make_pair(lo, -1));
    for (; it != v.end() && it->first <= hi; ++it)
      for (size_t s = i; s < end; ++s) TestPair(p, sample, v[s].second, it->second, out);
    i = end;
  }
}

void BruteSample(const Problem& p, int sample, Partial* out) {
  for (int a = 0; a < p.agents; ++a) {
    if (!IsActive(p.capsules, a)) continue;
    for (int b = a + 1; b < p.agents; ++b)
      if (IsActive(p.capsules, b)) TestPair(p, sample, a, b, out);
  }
}

// Sorts the records by pair and sample and turns each run of consecutive samples into
// one interval with its deepest sample.
CollisionResult Finish(const Problem& p, std::vector<Partial>& parts) {
  CollisionResult result;
  result.min_clearance = Eigen::VectorXd::Constant(p.agents, kInf);
  result.min_clearance_sample = Eigen::VectorXi::Constant(p.agents, -1);
  size_t total = 0;
  for (const auto& part : parts) total += part.records.size();
  std::vector<Record> records;
  records.reserve(total);
  for (auto& part : parts) {
    records.insert(records.end(), part.records.begin(), part.records.end());
    result.pair_tests += part.pair_tests;
    for (int a = 0; a < p.agents; ++a) {
      const double c = part.min_clearance[a];
      const int k = part.min_sample[a];
      const int at = result.min_clearance_sample[a];
      if (k >= 0 && (c < result.min_clearance[a] || (c == result.min_clearance[a] && k < at))) {
        result.min_clearance[a] = c;
        result.min_clearance_sample[a] = k;
      }
    }
  }
  // By pair and sample: bucketed by first agent (a counting sort), then each bucket sorted.
  {
    std::vector<size_t> start(static_cast<size_t>(p.agents) + 1, 0);
    for (const Record& r : records) ++start[static_cast<size_t>(r.a) + 1];
    for (size_t a = 0; a < static_cast<size_t>(p.agents); ++a) start[a + 1] += start[a];
    std::vector<Record> sorted(records.size());
    std::vector<size_t> fill(start.begin(), start.end() - 1);
    for (const Record& r : records) sorted[fill[static_cast<size_t>(r.a)]++] = r;
    for (size_t a = 0; a < static_cast<size_t>(p.agents); ++a)
      std::sort(sorted.begin() + static_cast<std::ptrdiff_t>(start[a]), sorted.begin() + static_cast<std::ptrdiff_t>(start[a + 1]),
                [](const Record& x, const Record& y) { return x.b != y.b ? x.b < y.b : x.sample < y.sample; });
    records.swap(sorted);
  }
  // Runs of consecutive samples below `limit`, each one interval with its deepest sample.
  auto intervals = [&](double limit, std::vector<Collision>* out) {
    int64_t count = 0;
    for (size_t i = 0; i < records.size();) {
      if (!(records[i].clearance < limit)) {
        ++i;
        continue;
      }
      Collision c{records[i].a, records[i].b, records[i].sample, records[i].sample, records[i].sample,
                  limit - records[i].clearance};
      size_t j = i + 1;
      for (; j < records.size() && records[j].a == c.agent_a && records[j].b == c.agent_b &&
             records[j].sample == c.last + 1 && records[j].clearance < limit;
           ++j) {
        c.last = records[j].sample;
        if (limit - records[j].clearance > c.depth) {
          c.depth = limit - records[j].clearance;
          c.deepest = records[j].sample;
        }
      }
      count += static_cast<int64_t>(j - i);
      out->push_back(c);
      i = j;
    }
    return count;
  };
  result.colliding_samples = intervals(p.margin, &result.collisions);
  if (p.watch > p.margin) intervals(p.watch, &result.near);
  return result;
}

int WorkerCount(const CollisionSettings& settings, int64_t work) {
  int threads = settings.threads;
  if (threads <= 0) threads = DefaultThreads();
  // Below a few thousand agent samples a thread costs more than it saves.
  if (work < 20000) threads = 1;
  return std::max(1, threads);
}

template <typename Fn>
std::vector<Partial> OverSamples(const Problem& p, int threads, Fn fn) {
  threads = std::max(1, std::min(threads, std::max(1, p.samples)));
  std::vector<Partial> parts(static_cast<size_t>(threads), Partial(p.agents));
  auto work = [&](int t) {
    const int first = static_cast<int>(static_cast<int64_t>(p.samples) * t / threads);
    const int last = static_cast<int>(static_cast<int64_t>(p.samples) * (t + 1) / threads);
    fn(first, last, &parts[static_cast<size_t>(t)]);
  };
  OnThreads(threads, work);
  return parts;
}

}  // namespace

double CapsuleClearance(double dx, double dy, double radius_a, double height_a, double base_a,
                        double radius_b, double height_b, double base_b) {
  double lo_a, hi_a, lo_b, hi_b;
  AxisSpan(radius_a, height_a, base_a, &lo_a, &hi_a);
  AxisSpan(radius_b, height_b, base_b, &lo_b, &hi_b);
  const double gap = std::max({0.0, lo_b - hi_a, lo_a - hi_b});
  return std::sqrt(dx * dx + dy * dy + gap * gap) - radius_a - radius_b;
}

CollisionResult DetectCollisions(const Eigen::Ref<const Trajectory2>& positions, int samples,
                                 const CapsuleSet& capsules, const CollisionSettings& settings) {
  const Problem p = Validate(positions, samples, capsules, settings);
  const int threads = WorkerCount(settings, static_cast<int64_t>(samples) * p.agents);
  auto parts = OverSamples(p, threads, [&](int first, int last, Partial* out) {
    std::vector<std::pair<uint64_t, int>> cells;  // the last sample's order, the next one's start
    cells.reserve(static_cast<size_t>(p.agents));
    for (int k = first; k < last; ++k) GridSample(p, k, &cells, out);
  });
  return Finish(p, parts);
}

CollisionResult DetectCollisionsBruteForce(const Eigen::Ref<const Trajectory2>& positions,
                                           int samples, const CapsuleSet& capsules,
                                           const CollisionSettings& settings) {
  const Problem p = Validate(positions, samples, capsules, settings);
  auto parts = OverSamples(p, 1, [&](int first, int last, Partial* out) {
    for (int k = first; k < last; ++k) BruteSample(p, k, out);
  });
  return Finish(p, parts);
}

}  // namespace mocapedit
