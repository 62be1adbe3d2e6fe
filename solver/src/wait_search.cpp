#include "mocapedit/wait_search.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace mocapedit {
namespace {

constexpr char kWhere[] = "WaitSearch";

// Fractional frames at the increasing shot times `at`, for frames played at the increasing
// times `map` (numpy.interp of the frame numbers: ends held, a time on a frame gives it exactly).
void FramesAt(const double* map, int count, const double* at, int n, double* out) {
  int j = 0;
  for (int i = 0; i < n; ++i) {
    const double x = at[i];
    if (x > map[count - 1]) {
      out[i] = count - 1;
      continue;
    }
    if (x < map[0]) {
      out[i] = 0.0;
      continue;
    }
    while (j + 1 < count && map[j + 1] <= x) ++j;
    while (j > 0 && map[j] > x) --j;
    if (j == count - 1 || map[j] == x) {
      out[i] = j;
      continue;
    }
    const double slope = 1.0 / (map[j + 1] - map[j]);
    out[i] = slope * (x - map[j]) + j;
  }
}

// The path's position at a fractional frame (clamped to its ends), blended linearly.
inline void PositionAt(const Eigen::Ref<const Trajectory2>& path, double frame, double* x, double* y) {
  const int last = static_cast<int>(path.rows()) - 1;
  const double f = std::min(std::max(frame, 0.0), static_cast<double>(last));
  const int i0 = static_cast<int>(std::floor(f));
  const int i1 = std::min(i0 + 1, last);
  const double a = f - i0;
  *x = path(i0, 0) * (1.0 - a) + path(i1, 0) * a;
  *y = path(i0, 1) * (1.0 - a) + path(i1, 1) * a;
}

// Python's int(numpy.ceil(x)).
inline int Ceil(double x) { return static_cast<int>(std::ceil(x)); }

}  // namespace

Eigen::VectorXd SmoothDelay(const Eigen::Ref<const Eigen::VectorXd>& times, double start, double end,
                            double delay) {
  const double span = std::max(end - start, 1e-12);
  Eigen::VectorXd out(times.size());
  for (Eigen::Index i = 0; i < times.size(); ++i) {
    const double u = std::min(std::max((times[i] - start) / span, 0.0), 1.0);
    out[i] = times[i] + delay * u * u * (3.0 - 2.0 * u);
  }
  return out;
}

void WaitSearch::BlockGrid::Cells(double lx, double ly, double hx, double hy, int c0[2], int c1[2]) const {
  auto index = [&](double v, double origin, int n) {
    return static_cast<int>(std::min(std::max(std::floor((v - origin) / cell), 0.0), static_cast<double>(n - 1)));
  };
  c0[0] = index(lx, x0, nx), c1[0] = index(hx, x0, nx);
  c0[1] = index(ly, y0, ny), c1[1] = index(hy, y0, ny);
}

WaitSearch::WaitSearch(const Eigen::Ref<const Trajectory2>& positions, const Eigen::Ref<const Eigen::VectorXd>& times,
                       const Eigen::Ref<const Eigen::VectorXd>& radius, const WaitSettings& settings)
    : positions_(positions), times_(times), radius_(radius), settings_(settings) {
  samples_ = static_cast<int>(times.size());
  agents_ = static_cast<int>(radius.size());
  if (positions.rows() != static_cast<Eigen::Index>(samples_) * agents_)
    throw InvalidInput(kWhere, "positions has " + std::to_string(positions.rows()) +
                                   " rows, expected samples * agents = " +
                                   std::to_string(static_cast<Eigen::Index>(samples_) * agents_));
  if (!(settings.time_codes_per_second > 0.0) || !(settings.sample_step > 0.0) || !(settings.step > 0.0) ||
      !(settings.margin >= 0.0) || !(settings.slowest_pace > 0.0 && settings.slowest_pace < 1.0) ||
      settings.block < 1)
    throw InvalidInput(kWhere, "time codes per second, sample step and step must be positive, the margin "
                               "not negative, the slowest pace in (0, 1) and the block at least 1");
  if (!positions.allFinite() || !times.allFinite() || !radius.allFinite())
    throw InvalidInput(kWhere, "positions, times and radii must be finite");
  const int block = settings.block;
  blocks_ = (samples_ + block - 1) / block;
  boxes_.assign(static_cast<size_t>(agents_) * blocks_ * 4, 0.0);
  const double inf = std::numeric_limits<double>::infinity();
  for (int a = 0; a < agents_; ++a)
    for (int b = 0; b < blocks_; ++b) {
      double* box = &boxes_[(static_cast<size_t>(a) * blocks_ + b) * 4];
      box[0] = box[1] = inf;
      box[2] = box[3] = -inf;
      for (int k = b * block; k < std::min((b + 1) * block, samples_); ++k) {
        const double* p = positions_.row(static_cast<Eigen::Index>(k) * agents_ + a).data();
        box[0] = std::min(box[0], p[0]);
        box[1] = std::min(box[1], p[1]);
        box[2] = std::max(box[2], p[0]);
        box[3] = std::max(box[3], p[1]);
      }
    }
  // The broad phase's grid: every agent's box of a block in the cells it covers. An agent
  // moves at most `speed_` (either axis) from one sample to the next, so over a run of
  // blocks it stays within its first block's box grown by that times the run's samples.
  double largest = 0.0;
  for (int a = 0; a < agents_; ++a) {
    largest = std::max(largest, radius_[a]);
    for (int k = 1; k < samples_; ++k) {
      const double* p0 = positions_.row(static_cast<Eigen::Index>(k - 1) * agents_ + a).data();
      const double* p1 = positions_.row(static_cast<Eigen::Index>(k) * agents_ + a).data();
      speed_ = std::max({speed_, std::abs(p1[0] - p0[0]), std::abs(p1[1] - p0[1])});
    }
  }
  largest_radius_ = largest;
  grids_.resize(static_cast<size_t>(blocks_));
  for (int b = 0; b < blocks_; ++b) {
    BlockGrid& g = grids_[static_cast<size_t>(b)];
    double lo[2] = {inf, inf}, hi[2] = {-inf, -inf}, extent = 0.0;
    for (int a = 0; a < agents_; ++a) {
      const double* box = &boxes_[(static_cast<size_t>(a) * blocks_ + b) * 4];
      for (int c = 0; c < 2; ++c) {
        lo[c] = std::min(lo[c], box[c]);
        hi[c] = std::max(hi[c], box[2 + c]);
      }
      extent = std::max({extent, box[2] - box[0], box[3] - box[1]});
    }
    if (agents_ == 0) continue;
    constexpr int kMaxCells = 512;  // per axis
    g.cell = std::max({extent, 2.0 * largest + settings.margin, (hi[0] - lo[0]) / kMaxCells,
                       (hi[1] - lo[1]) / kMaxCells, 1e-300});
    g.x0 = lo[0], g.y0 = lo[1];
    g.nx = std::min(kMaxCells, static_cast<int>((hi[0] - lo[0]) / g.cell) + 1);
    g.ny = std::min(kMaxCells, static_cast<int>((hi[1] - lo[1]) / g.cell) + 1);
    std::vector<std::pair<int, int>> entries;  // (cell, agent)
    for (int a = 0; a < agents_; ++a) {
      const double* box = &boxes_[(static_cast<size_t>(a) * blocks_ + b) * 4];
      int c0[2], c1[2];
      g.Cells(box[0], box[1], box[2], box[3], c0, c1);
      for (int y = c0[1]; y <= c1[1]; ++y)
        for (int x = c0[0]; x <= c1[0]; ++x) entries.emplace_back(y * g.nx + x, a);
    }
    std::sort(entries.begin(), entries.end());
    g.start.assign(static_cast<size_t>(g.nx) * g.ny + 1, 0);
    g.agents.resize(entries.size());
    for (size_t i = 0; i < entries.size(); ++i) {
      ++g.start[static_cast<size_t>(entries[i].first) + 1];
      g.agents[i] = entries[i].second;
    }
    for (size_t c = 1; c < g.start.size(); ++c) g.start[c] += g.start[c - 1];
  }
}

WaitDelay WaitSearch::LeastDelay(const WaitQuery& q, const WaitWalker& walker) const {
  const WaitSettings& s = settings_;
  const int w = q.walker, o = q.other;
  if (w < 0 || w >= agents_ || o < 0 || o >= agents_ || w == o)
    throw InvalidInput(kWhere, "walker and other must be two agents in range");
  if (q.first < 0 || q.last < q.first || q.last >= samples_)
    throw InvalidInput(kWhere, "the encounter's samples are out of range");
  const int frames = static_cast<int>(walker.times.size());
  if (frames < 1 || walker.path.rows() != frames || walker.source_times.size() != frames)
    throw InvalidInput(kWhere, "the walker's path, time map and source time map need one entry per frame");
  WaitDelay out;
  const double fps = s.time_codes_per_second;
  // The encounter: from a second before the overlap to a second past it, plus the room.
  const int lo = std::max(q.first - Ceil(fps / s.sample_step), 0);
  const int hi = std::min(q.last + Ceil((q.room + fps) / s.sample_step), samples_ - 1);
  const int n = hi - lo + 1;
  auto at = [&](int k, int a) { return positions_.row(static_cast<Eigen::Index>(k) * agents_ + a).data(); };
  // Whatever the delay, the walker walks the part of its path it walked from `room` before
  // the window to its end: only the agents whose boxes come near that part can meet it.
  double r_lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  double r_hi[2] = {-r_lo[0], -r_lo[1]};
  for (int k = std::max(lo - Ceil(q.room / s.sample_step), 0); k <= hi; ++k) {
    const double* p = at(k, w);
    for (int c = 0; c < 2; ++c) {
      r_lo[c] = std::min(r_lo[c], p[c]);
      r_hi[c] = std::max(r_hi[c], p[c]);
    }
  }
  const int b0 = lo / s.block, b1 = hi / s.block + 1;
  // The agents whose boxes over the window's blocks, grown by both radii and the margin,
  // meet that part; the grid of block b0 gives a superset of them.
  std::vector<int> cand, found;
  std::vector<double> need2, grows;
  {
    const BlockGrid& g = grids_[static_cast<size_t>(b0)];
    const double reach = (radius_[w] + largest_radius_ + s.margin + speed_ * (b1 - b0) * s.block) * (1.0 + 1e-9);
    int c0[2], c1[2];
    g.Cells(r_lo[0] - reach, r_lo[1] - reach, r_hi[0] + reach, r_hi[1] + reach, c0, c1);
    for (int y = c0[1]; y <= c1[1]; ++y)
      for (int x = c0[0]; x <= c1[0]; ++x) {
        const int cell = y * g.nx + x;
        found.insert(found.end(), g.agents.begin() + g.start[static_cast<size_t>(cell)],
                     g.agents.begin() + g.start[static_cast<size_t>(cell) + 1]);
      }
    found.push_back(o);
    std::sort(found.begin(), found.end());
    found.erase(std::unique(found.begin(), found.end()), found.end());
  }
  int at_o = -1;
  for (int a : found) {
    const double grow = radius_[w] + radius_[a] + s.margin;
    bool near = a == o;
    if (a != w && a != o) {
      const double* box = &boxes_[(static_cast<size_t>(a) * blocks_ + b0) * 4];
      double low[2] = {box[0], box[1]}, high[2] = {box[2], box[3]};
      for (int b = b0 + 1; b < b1; ++b) {
        box += 4;
        low[0] = std::min(low[0], box[0]);
        low[1] = std::min(low[1], box[1]);
        high[0] = std::max(high[0], box[2]);
        high[1] = std::max(high[1], box[3]);
      }
      near = low[0] - grow <= r_hi[0] && low[1] - grow <= r_hi[1] && high[0] + grow >= r_lo[0] &&
             high[1] + grow >= r_lo[1];
    }
    if (!near) continue;
    if (a == o) at_o = static_cast<int>(cand.size());
    cand.push_back(a);
    need2.push_back(grow * grow);
    grows.push_back(grow);
  }
  const int nc = static_cast<int>(cand.size());
  const double* window = times_.data() + lo;
  // The walker's positions in the window under a time map, and their box in each block.
  std::vector<double> fr(static_cast<size_t>(n)), px(static_cast<size_t>(n)), py(static_cast<size_t>(n));
  std::vector<double> wbox(static_cast<size_t>(b1 - b0) * 4);
  auto place = [&](const double* map) {
    FramesAt(map, frames, window, n, fr.data());
    for (int b = b0; b < b1; ++b) {
      double* box = &wbox[static_cast<size_t>(b - b0) * 4];
      box[0] = box[1] = std::numeric_limits<double>::infinity();
      box[2] = box[3] = -box[0];
      for (int k = std::max(lo, b * s.block); k <= std::min(hi, (b + 1) * s.block - 1); ++k) {
        const size_t i = static_cast<size_t>(k - lo);
        PositionAt(walker.path, fr[i], &px[i], &py[i]);
        box[0] = std::min(box[0], px[i]), box[1] = std::min(box[1], py[i]);
        box[2] = std::max(box[2], px[i]), box[3] = std::max(box[3], py[i]);
      }
    }
  };
  // Whether the walker so placed overlaps candidate c somewhere in the window. A block where
  // their boxes stand `grow` apart along an axis has no sample closer than that.
  auto overlaps = [&](int c) {
    const int a = cand[static_cast<size_t>(c)];
    const double need = need2[static_cast<size_t>(c)], grow = grows[static_cast<size_t>(c)];
    for (int b = b0; b < b1; ++b) {
      const double* wb = &wbox[static_cast<size_t>(b - b0) * 4];
      const double* box = &boxes_[(static_cast<size_t>(a) * blocks_ + b) * 4];
      if (box[0] - wb[2] >= grow || wb[0] - box[2] >= grow || box[1] - wb[3] >= grow || wb[1] - box[3] >= grow)
        continue;
      for (int k = std::max(lo, b * s.block); k <= std::min(hi, (b + 1) * s.block - 1); ++k) {
        const double* p = at(k, a);
        const size_t i = static_cast<size_t>(k - lo);
        const double dx = p[0] - px[i], dy = p[1] - py[i];
        if (dx * dx + dy * dy - need < 0.0) return true;
      }
    }
    return false;
  };
  // Walkers going the same way may be caught up with: they wait in their turn (the next
  // round), as a queue does. A new encounter with anyone else is not worth a wait: the
  // candidates a delay must not meet are those neither met already nor going its way.
  const double* w_lo = at(lo, w);
  const double* w_hi = at(hi, w);
  const double mine[2] = {w_hi[0] - w_lo[0], w_hi[1] - w_lo[1]};
  const double mine_norm = std::sqrt(mine[0] * mine[0] + mine[1] * mine[1]);
  std::vector<int> avoid;
  place(walker.times.data());
  for (int c = 0; c < nc; ++c) {
    const double* c_lo = at(lo, cand[static_cast<size_t>(c)]);
    const double* c_hi = at(hi, cand[static_cast<size_t>(c)]);
    const double motion[2] = {c_hi[0] - c_lo[0], c_hi[1] - c_lo[1]};
    const double norm = std::sqrt(motion[0] * motion[0] + motion[1] * motion[1]);
    const double cos = (motion[0] * mine[0] + motion[1] * mine[1]) / std::max(norm * mine_norm, 1e-300);
    if (!(cos >= s.passing_cos) && !overlaps(c)) avoid.push_back(c);
  }
  // A smoothstep's steepest slope is 1.5 times its mean: the pace stays at or above
  // slowest_pace. It starts after the clip does: a walker never stands frozen in its first
  // pose waiting for its clip to begin; and after the walker's earliest (its pinned frames play
  // when they did).
  const double t_end = times_[q.first] - 0.1 * fps;
  const double step = s.step;
  const double lowest = std::isfinite(q.guess) ? std::max(step, step * (std::ceil(q.guess / step) - 1.0)) : step;
  // numpy.arange(lowest, min(room, lowest + 4 step) + 1e-9, step), value by value.
  const double stop = std::min(q.room, lowest + 4.0 * step) + 1e-9;
  const int count = std::max(0, Ceil((stop - lowest) / step));
  const double delta = (lowest + step) - lowest;
  for (int i = 0; i < count; ++i) {
    const double d = i == 0 ? lowest : i == 1 ? lowest + step : lowest + i * delta;
    const double t_start = t_end - std::max(1.5 * d / (1.0 / s.slowest_pace - 1.0), fps);
    if (!(t_start >= walker.times[0] && t_start >= walker.earliest)) continue;
    Eigen::VectorXd trial = SmoothDelay(walker.times, t_start, t_end, d);
    // Delays taken up over overlapping spans add their slowing: the pace stays at or above
    // slowest_pace of the source's all the same.
    bool paced = true;
    for (int f = 0; f + 1 < frames && paced; ++f)
      paced = (trial[f + 1] - trial[f]) * s.slowest_pace <=
              (walker.source_times[f + 1] - walker.source_times[f]) * (1.0 + 1e-9);
    if (!paced) continue;
    place(trial.data());
    if (overlaps(at_o)) continue;
    bool fresh = false;
    for (size_t i = 0; i < avoid.size() && !fresh; ++i) fresh = overlaps(avoid[i]);
    if (fresh) continue;
    out.found = true;
    out.delay = d;
    out.start = t_start;
    out.end = t_end;
    out.times = std::move(trial);
    return out;
  }
  return out;
}

std::vector<std::pair<int, WaitDelay>> WaitRound(const WaitSearch& search, const std::vector<WaitEncounter>& encounters,
                                                 const std::vector<WaitWalker>& walkers, double budget, double step,
                                                 std::vector<double>& delay, WaitTried& tried) {
  if (delay.size() != static_cast<size_t>(search.agents()) || walkers.size() != delay.size())
    throw InvalidInput("WaitRound", "delay and walkers need one entry per agent");
  std::vector<std::pair<int, WaitDelay>> out;
  std::vector<char> taken(delay.size(), 0);
  for (const WaitEncounter& e : encounters) {
    if (e.walker < 0 || e.other < 0 || e.walker >= search.agents() || e.other >= search.agents())
      throw InvalidInput("WaitRound", "an encounter names an agent out of range");
    const size_t w = static_cast<size_t>(e.walker), o = static_cast<size_t>(e.other);
    if (taken[w] || budget - delay[w] < step) continue;
    const std::pair<double, double> now{delay[w], delay[o]};
    auto [at, fresh] = tried.try_emplace({e.walker, e.other}, now);
    if (!fresh) {
      if (at->second == now) continue;
      at->second = now;
    }
    WaitQuery q;
    q.walker = e.walker, q.other = e.other, q.first = e.first, q.last = e.last;
    q.room = budget - delay[w], q.guess = e.guess;
    WaitDelay found = search.LeastDelay(q, walkers[w]);
    if (!found.found) continue;
    delay[w] += found.delay;
    taken[w] = 1;
    out.emplace_back(e.walker, std::move(found));
  }
  return out;
}

}  // namespace mocapedit
