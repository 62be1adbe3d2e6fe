#include "mocapedit/plausibility.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace mocapedit {
namespace {

constexpr double kPi = 3.141592653589793;
constexpr double kDegrees = 180.0 / kPi;  // numpy.degrees' factor
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The edit's turn is measured over spans where the source's chord is at least this fraction of
// its path: a half circle (2 / pi) is a turn, a step away and back is not.
constexpr double kLeastStraightness = 0.5;

// Where a point's ground coordinates sit: (p[0], -p[2]) for Y up, (p[0], p[1]) for Z up.
struct GroundPlane {
  int up;
  double U(const double* p) const { return p[0]; }
  double V(const double* p) const { return up == 1 ? -p[2] : p[1]; }
};

// numpy.remainder (Python's %) for a positive divisor.
double Remainder(double a, double b) {
  double mod = std::fmod(a, b);
  if (mod != 0.0) {
    if ((b < 0) != (mod < 0)) mod += b;
  } else {
    mod = std::copysign(0.0, b);
  }
  return mod;
}

// numpy.unwrap (period 2 pi), in place: each step folded into [-pi, pi) (a step of +pi kept),
// the corrections summed in order.
void Unwrap(double* p, std::size_t n) {
  if (n < 2) return;
  double previous = p[0], sum = 0.0;
  for (std::size_t i = 1; i < n; ++i) {
    const double value = p[i], step = value - previous;
    double correction = 0.0;
    if (!(std::abs(step) < kPi)) {
      double folded = Remainder(step - (-kPi), 2.0 * kPi) + (-kPi);
      if (folded == -kPi && step > 0) folded = kPi;
      correction = folded - step;
    }
    sum = i == 1 ? correction : sum + correction;
    p[i] = value + sum;
    previous = value;
  }
}

// numpy's sum of a contiguous run (pairwise, in blocks of 8), 0 for none.
double PairwiseSum(const double* a, std::size_t n) {
  if (n < 8) {
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) sum += a[i];
    return sum;
  }
  if (n <= 128) {
    double r[8];
    for (int j = 0; j < 8; ++j) r[j] = a[j];
    std::size_t i = 8;
    for (; i < n - n % 8; i += 8)
      for (int j = 0; j < 8; ++j) r[j] += a[i + j];
    double sum = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; ++i) sum += a[i];
    return sum;
  }
  std::size_t half = n / 2;
  half -= half % 8;
  return PairwiseSum(a, half) + PairwiseSum(a + half, n - half);
}

// numpy.interp(x, xp, fp) for #n increasing xp; fp read every `stride` values.
double Interp(double x, const double* xp, const double* fp, std::size_t n, std::size_t stride = 1) {
  if (n == 1) return fp[0];
  if (std::isnan(x)) return x;
  if (x < xp[0]) return fp[0];
  if (x > xp[n - 1]) return fp[(n - 1) * stride];
  const std::size_t j = static_cast<std::size_t>(std::upper_bound(xp, xp + n, x) - xp) - 1;
  const double y0 = fp[j * stride];
  if (j == n - 1 || xp[j] == x) return y0;
  const double y1 = fp[(j + 1) * stride];
  const double slope = (y1 - y0) / (xp[j + 1] - xp[j]);
  double y = slope * (x - xp[j]) + y0;
  if (std::isnan(y)) {
    y = slope * (x - xp[j + 1]) + y1;
    if (std::isnan(y) && y0 == y1) y = y0;
  }
  return y;
}

// #count samples of `width` values each, linearly interpolated at fractional sample
// indices `at` (#m), as numpy.interp over the indices 0 .. count - 1 does.
void Resample(const double* values, std::size_t count, std::size_t width, const double* at, std::size_t m,
              double* out) {
  const double last = static_cast<double>(count) - 1.0;
  for (std::size_t k = 0; k < m; ++k) {
    const double x = at[k];
    for (std::size_t c = 0; c < width; ++c) {
      const double* fp = values + c;
      double y;
      if (count == 1 || !(x > 0.0)) {
        y = std::isnan(x) && count > 1 ? x : fp[0];
      } else if (x >= last) {
        y = fp[(count - 1) * width];
      } else {
        const std::size_t j = static_cast<std::size_t>(x);  // floor: the interval [j, j + 1) holding x
        const double y0 = fp[j * width], y1 = fp[(j + 1) * width];
        if (static_cast<double>(j) == x) {
          y = y0;
        } else {
          const double slope = (y1 - y0) / (static_cast<double>(j + 1) - static_cast<double>(j));
          y = slope * (x - static_cast<double>(j)) + y0;
          if (std::isnan(y)) {
            y = slope * (x - static_cast<double>(j + 1)) + y1;
            if (std::isnan(y) && y0 == y1) y = y0;
          }
        }
      }
      out[k * width + c] = y;
    }
  }
}

// numpy.linspace(0, count - 1, m): where m samples fall on a clip of #count.
void Fractions(std::size_t count, std::size_t m, std::vector<double>& out) {
  out.assign(m, 0.0);
  if (m < 2) return;
  const double delta = static_cast<double>(count) - 1.0, div = static_cast<double>(m - 1), step = delta / div;
  for (std::size_t i = 0; i < m; ++i)
    out[i] = (step == 0.0 ? static_cast<double>(i) / div * delta : static_cast<double>(i) * step) + 0.0;
  out[m - 1] = delta;
}

// numpy.linalg.norm of a 2-vector.
double Norm(double x, double y) { return std::sqrt(x * x + y * y); }

double PathLength(const double* ground, std::size_t n, std::vector<double>& steps) {
  steps.resize(n > 1 ? n - 1 : 0);
  for (std::size_t i = 0; i + 1 < n; ++i)
    steps[i] = Norm(ground[2 * i + 2] - ground[2 * i], ground[2 * i + 3] - ground[2 * i + 1]);
  return PairwiseSum(steps.data(), steps.size());
}

// numpy.argmax: the first largest value, or the first NaN.
std::size_t ArgMax(const double* a, std::size_t n) {
  std::size_t best = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (std::isnan(a[i])) return i;
    if (a[i] > a[best]) best = i;
  }
  return best;
}

// numpy.max: NaN when any value is.
double Max(const double* a, std::size_t n) {
  double best = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    if (std::isnan(a[i])) return a[i];
    best = std::max(best, a[i]);
  }
  return best;
}

// numpy.min: NaN when any value is.
double Min(const double* a, std::size_t n) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    if (std::isnan(a[i])) return a[i];
    best = std::min(best, a[i]);
  }
  return best;
}

bool Increasing(const double* t, std::size_t n) {
  for (std::size_t i = 0; i + 1 < n; ++i)
    if (!(t[i + 1] - t[i] > 0)) return false;
  return true;
}

void CheckSize(std::size_t size, std::size_t expected, const char* where, const char* name) {
  if (size != expected)
    throw InvalidInput(where, std::string(name) + " must hold " + std::to_string(expected) + " values, not " +
                                  std::to_string(size));
}

void FacingOf(const double* m, std::size_t n, int up, double* facing) {
  double mean[3] = {0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) mean[k] += std::abs(m[16 * i + 4 * k + up]);
  int axis = 0;
  for (int k = 0; k < 3; ++k) {
    mean[k] /= static_cast<double>(n);
    if (std::isnan(mean[k])) {
      axis = k;
      break;
    }
    if (mean[k] < mean[axis]) axis = k;
  }
  const GroundPlane g{up};
  for (std::size_t i = 0; i < n; ++i) {
    const double* row = m + 16 * i + 4 * axis;
    facing[i] = std::atan2(g.V(row), g.U(row));
  }
}

void RatesOf(const double* facing, const double* seconds, std::size_t n, std::vector<double>& scratch,
             double* rates) {
  scratch.assign(facing, facing + n);
  Unwrap(scratch.data(), n);
  for (std::size_t i = 0; i + 1 < n; ++i)
    rates[i] = std::abs(scratch[i + 1] - scratch[i]) * kDegrees / (seconds[i + 1] - seconds[i]);
}

// The chord from sample i to the first at least `chord` seconds later, compared.
void DeviationOf(const double* s, const double* e, const double* t, std::size_t n, double min_speed, double chord,
                 const double* turn, double* out) {
  std::size_t j = 0;  // the chord's end: the first sample not before t[i] + chord (later for each i)
  for (std::size_t i = 0; i < n; ++i) {
    out[i] = kNaN;
    if (n < 2) continue;
    const double end = t[i] + chord - 1e-9;
    while (j < n && t[j] < end) ++j;
    if (j >= n) continue;
    double du = s[2 * j] - s[2 * i], dv = s[2 * j + 1] - s[2 * i + 1];
    const double eu = e[2 * j] - e[2 * i], ev = e[2 * j + 1] - e[2 * i + 1];
    if (!(Norm(du, dv) / (t[j] - t[i]) >= min_speed)) continue;
    if (turn) {
      const double c = std::cos(turn[i]), sn = std::sin(turn[i]);
      const double ru = c * du - sn * dv, rv = sn * du + c * dv;
      du = ru, dv = rv;
    }
    out[i] = std::abs(std::atan2(du * ev - dv * eu, du * eu + dv * ev)) * kDegrees;
  }
}

void TurnOf(const double* s, const double* e, const double* t, std::size_t n, double min_speed, double span,
            double least_straightness, std::vector<double>& at, std::vector<double>& angle,
            std::vector<double>& along, double* out) {
  std::fill(out, out + n, 0.0);
  at.clear(), angle.clear();
  if (n < 2) return;
  // The source's path length from its first sample, to tell a walk from a back and forth.
  along.assign(n, 0.0);
  for (std::size_t i = 1; i < n; ++i)
    along[i] = along[i - 1] + Norm(s[2 * i] - s[2 * i - 2], s[2 * i + 1] - s[2 * i - 1]);
  std::size_t a = 0, past = 0;  // the span's first sample, and the first after it (later for each i)
  for (std::size_t i = 0; i < n; ++i) {
    const double from = t[i] - 0.5 * span, to = t[i] + 0.5 * span;
    while (a < n && t[a] < from) ++a;
    while (past < n && !(to < t[past])) ++past;
    const std::size_t b = std::min(past - 1, n - 1);
    const double su = s[2 * b] - s[2 * a], sv = s[2 * b + 1] - s[2 * a + 1];
    const double eu = e[2 * b] - e[2 * a], ev = e[2 * b + 1] - e[2 * a + 1];
    const double dt = std::max(t[b] - t[a], 1e-12);
    // The source walks over the span (and, with least_straightness, goes somewhere: a back and
    // forth has no direction for an edit to turn).
    const double chord = Norm(su, sv);
    if (b > a && chord / dt >= min_speed && chord >= least_straightness * (along[b] - along[a]) && Norm(eu, ev) > 0) {
      at.push_back(static_cast<double>(i));
      angle.push_back(std::atan2(su * ev - sv * eu, su * eu + sv * ev));
    }
  }
  if (at.empty()) return;
  Unwrap(angle.data(), angle.size());
  for (std::size_t i = 0; i < n; ++i) out[i] = Interp(static_cast<double>(i), at.data(), angle.data(), at.size());
}

// Scratch arrays of one agent, kept between agents.
struct Scratch {
  std::vector<double> fs, fe, gs, ge, rate_e, rate_s, rate_src, dt_src, dt_at, warps, extra, unwrapped, fractions, steps;
  std::vector<double> gs_at, ss_at, fs_at, gk, ek, tk, turn, dev, turned, at, angle, along;
  std::vector<std::size_t> kept;
  std::vector<char> measured;
};

}  // namespace

void JointFacing(Span<const double> matrices, int up_axis, Span<double> facing) {
  if (up_axis != 1 && up_axis != 2) throw InvalidInput("JointFacing", "up_axis must be 1 (Y) or 2 (Z)");
  CheckSize(matrices.size, 16 * facing.size, "JointFacing", "matrices");
  if (facing.size) FacingOf(matrices.data, facing.size, up_axis, facing.data);
}

void TurningRates(Span<const double> facing, Span<const double> seconds, Span<double> rates) {
  CheckSize(seconds.size, facing.size, "TurningRates", "seconds");
  CheckSize(rates.size, facing.size > 0 ? facing.size - 1 : 0, "TurningRates", "rates");
  if (!Increasing(seconds.data, seconds.size)) throw InvalidInput("TurningRates", "sample times must increase");
  std::vector<double> scratch;
  if (rates.size) RatesOf(facing.data, seconds.data, facing.size, scratch, rates.data);
}

void DirectionDeviation(Span<const double> source, Span<const double> edited, Span<const double> seconds,
                        double min_speed, double chord, Span<const double> turn, Span<double> deviation) {
  const std::size_t n = seconds.size;
  CheckSize(source.size, 2 * n, "DirectionDeviation", "source");
  CheckSize(edited.size, 2 * n, "DirectionDeviation", "edited");
  CheckSize(deviation.size, n, "DirectionDeviation", "deviation");
  if (turn.size) CheckSize(turn.size, n, "DirectionDeviation", "turn");
  DeviationOf(source.data, edited.data, seconds.data, n, min_speed, chord, turn.size ? turn.data : nullptr,
              deviation.data);
}

void EditTurn(Span<const double> source, Span<const double> edited, Span<const double> seconds, double min_speed,
              double span, Span<double> turn) {
  const std::size_t n = seconds.size;
  CheckSize(source.size, 2 * n, "EditTurn", "source");
  CheckSize(edited.size, 2 * n, "EditTurn", "edited");
  CheckSize(turn.size, n, "EditTurn", "turn");
  std::vector<double> at, angle, along;
  TurnOf(source.data, edited.data, seconds.data, n, min_speed, span, kLeastStraightness, at, angle, along, turn.data);
}

void PlausibilityJob::Validate() const {
  const char* where = "PlausibilityJob";
  for (const auto* offsets : {&source_offsets, &edited_offsets}) {
    if (offsets->size == 0 || !offsets->data) throw InvalidInput(where, "offsets must hold #A + 1 values");
    if ((*offsets)[0] != 0) throw InvalidInput(where, "offsets must start at 0");
    for (std::size_t a = 1; a < offsets->size; ++a)
      if ((*offsets)[a] < (*offsets)[a - 1]) throw InvalidInput(where, "offsets must not decrease");
  }
  if (source_offsets.size != edited_offsets.size)
    throw InvalidInput(where, "source_offsets and edited_offsets must hold as many agents");
  const std::size_t agents = source_offsets.size - 1;
  const std::size_t ns = static_cast<std::size_t>(source_offsets[agents]);
  const std::size_t ne = static_cast<std::size_t>(edited_offsets[agents]);
  CheckSize(source_seconds.size, ns, where, "source_seconds");
  CheckSize(source_hip.size, 16 * ns, where, "source_hip");
  CheckSize(edited_seconds.size, ne, where, "edited_seconds");
  CheckSize(edited_hip.size, 16 * ne, where, "edited_hip");
  if (edited_frames.size) CheckSize(edited_frames.size, ne, where, "edited_frames");
  const struct { std::size_t size; const char* name; } outputs[] = {
      {max_facing_rate.size, "max_facing_rate"}, {source_max_facing_rate.size, "source_max_facing_rate"},
      {max_extra_facing_rate.size, "max_extra_facing_rate"}, {worst_turn_frame.size, "worst_turn_frame"},
      {spin_frames.size, "spin_frames"}, {max_direction_deviation.size, "max_direction_deviation"},
      {worst_direction_frame.size, "worst_direction_frame"}, {max_turned_deviation.size, "max_turned_deviation"},
      {max_edit_turn.size, "max_edit_turn"}, {length_ratio.size, "length_ratio"},
      {time_warp_min.size, "time_warp_min"}, {time_warp_max.size, "time_warp_max"}};
  for (const auto& out : outputs) CheckSize(out.size, agents, where, out.name);
  if (up_axis != 1 && up_axis != 2) throw InvalidInput(where, "up_axis must be 1 (Y) or 2 (Z)");
  const struct { double value; const char* name; } positive[] = {
      {walking_speed, "walking_speed"}, {chord, "chord"}, {edit_turn_span, "edit_turn_span"}, {spin_rate, "spin_rate"}};
  for (const auto& p : positive)
    if (!(std::isfinite(p.value) && p.value > 0)) throw InvalidInput(where, std::string(p.name) + " must be positive");
  for (std::size_t a = 0; a < agents; ++a) {
    const std::size_t s0 = source_offsets[a], s = source_offsets[a + 1] - s0;
    const std::size_t e0 = edited_offsets[a], e = edited_offsets[a + 1] - e0;
    if (s < 2 || e < 2) continue;
    if (!Increasing(edited_seconds.data + e0, e))
      throw InvalidInput(where, "agent " + std::to_string(a) + ": edited sample times must increase");
    if (!edited_frames.size && !Increasing(source_seconds.data + s0, s))
      throw InvalidInput(where, "agent " + std::to_string(a) + ": source sample times must increase");
  }
}

void PlausibilityJob::Run() const {
  Validate();
  const std::size_t agents = source_offsets.size - 1;
  const GroundPlane plane{up_axis};
  Scratch w;
  for (std::size_t a = 0; a < agents; ++a) {
    const std::size_t s0 = source_offsets[a], ns = source_offsets[a + 1] - s0;
    const std::size_t e0 = edited_offsets[a], ne = edited_offsets[a + 1] - e0;
    const double* ss = source_seconds.data + s0;
    const double* se = edited_seconds.data + e0;
    const double* ms = source_hip.data + 16 * s0;
    const double* me = edited_hip.data + 16 * e0;
    // Facing: the same as metrics.body_facing (unwrapped).
    w.fs.resize(ns), w.fe.resize(ne), w.gs.resize(2 * ns), w.ge.resize(2 * ne);
    if (ns) FacingOf(ms, ns, up_axis, w.fs.data());
    if (ne) FacingOf(me, ne, up_axis, w.fe.data());
    Unwrap(w.fs.data(), ns), Unwrap(w.fe.data(), ne);
    for (std::size_t i = 0; i < ns; ++i) w.gs[2 * i] = plane.U(ms + 16 * i + 12), w.gs[2 * i + 1] = plane.V(ms + 16 * i + 12);
    for (std::size_t i = 0; i < ne; ++i) w.ge[2 * i] = plane.U(me + 16 * i + 12), w.ge[2 * i + 1] = plane.V(me + 16 * i + 12);
    const double le = PathLength(w.ge.data(), ne, w.steps), ls = PathLength(w.gs.data(), ns, w.steps);
    length_ratio[a] = ls == 0.0 ? (le == 0.0 ? 1.0 : std::numeric_limits<double>::infinity()) : le / ls;
    if (ne < 2 || ns < 2) {
      max_facing_rate[a] = source_max_facing_rate[a] = max_extra_facing_rate[a] = 0.0;
      worst_turn_frame[a] = worst_direction_frame[a] = -1;
      spin_frames[a] = 0;
      max_direction_deviation[a] = max_turned_deviation[a] = kNaN;
      max_edit_turn[a] = 0.0;
      time_warp_min[a] = time_warp_max[a] = 1.0;
      continue;
    }
    // TurningRates, and the source AtEditedSamples.
    w.rate_e.resize(ne - 1), w.rate_s.resize(ne - 1), w.gs_at.resize(2 * ne), w.ss_at.resize(ne);
    RatesOf(w.fe.data(), se, ne, w.unwrapped, w.rate_e.data());
    w.warps.clear();
    if (!edited_frames.size) {
      // Paired by sample, resampled by fraction of the clip when the counts differ.
      auto pair = [&](const double* values, std::size_t count, std::size_t width, std::size_t m, double* out) {
        if (count == m) {
          std::copy(values, values + count * width, out);
        } else {
          Fractions(count, m, w.fractions);
          Resample(values, count, width, w.fractions.data(), m, out);
        }
      };
      w.rate_src.resize(ns - 1), w.dt_src.resize(ns - 1), w.dt_at.resize(ne - 1);
      RatesOf(w.fs.data(), ss, ns, w.unwrapped, w.rate_src.data());
      pair(w.rate_src.data(), ns - 1, 1, ne - 1, w.rate_s.data());
      for (std::size_t i = 0; i + 1 < ns; ++i) w.dt_src[i] = ss[i + 1] - ss[i];
      pair(w.dt_src.data(), ns - 1, 1, ne - 1, w.dt_at.data());
      for (std::size_t i = 0; i + 1 < ne; ++i) w.warps.push_back((se[i + 1] - se[i]) / w.dt_at[i]);
      pair(w.gs.data(), ns, 2, ne, w.gs_at.data());
      pair(ss, ns, 1, ne, w.ss_at.data());
    } else {
      // The source's turn over each edited interval, per second of the source.
      const double* f = edited_frames.data + e0;
      w.fs_at.resize(ne);
      Resample(w.fs.data(), ns, 1, f, ne, w.fs_at.data());
      Resample(ss, ns, 1, f, ne, w.ss_at.data());
      Resample(w.gs.data(), ns, 2, f, ne, w.gs_at.data());
      for (std::size_t i = 0; i + 1 < ne; ++i) {
        const double src_dt = w.ss_at[i + 1] - w.ss_at[i];
        const bool moving = f[i + 1] - f[i] > 1e-9;
        w.rate_s[i] = moving ? std::abs(w.fs_at[i + 1] - w.fs_at[i]) * kDegrees / src_dt : 0.0;
        if (moving) w.warps.push_back((se[i + 1] - se[i]) / src_dt);
      }
    }
    // The time warp over the intervals that play the source (1 when none does).
    double warp_min = 1.0, warp_max = 1.0;
    if (!w.warps.empty()) warp_min = Min(w.warps.data(), w.warps.size()), warp_max = Max(w.warps.data(), w.warps.size());
    time_warp_min[a] = warp_min, time_warp_max[a] = warp_max;
    // Rates: the largest extra turn (first where it is) and the spins.
    std::vector<double>& extra = w.extra;
    extra.resize(ne - 1);
    std::int64_t spins = 0;
    for (std::size_t i = 0; i + 1 < ne; ++i) {
      extra[i] = w.rate_e[i] - w.rate_s[i];
      spins += w.rate_e[i] > spin_rate && w.rate_s[i] <= spin_rate;
    }
    const std::size_t turn_frame = ArgMax(extra.data(), ne - 1);
    worst_turn_frame[a] = static_cast<std::int64_t>(turn_frame);
    max_extra_facing_rate[a] = extra[turn_frame];
    spin_frames[a] = spins;
    max_facing_rate[a] = Max(w.rate_e.data(), ne - 1);
    source_max_facing_rate[a] = Max(w.rate_s.data(), ne - 1);
    // HeldSamplesOut: the held ends of a warped clip do not walk; measure on the samples that advance.
    w.kept.clear();
    for (std::size_t i = 0; i < ne; ++i)
      if (i == 0 || w.ss_at[i] - w.ss_at[i - 1] > 0) w.kept.push_back(i);
    const std::size_t nk = w.kept.size();
    w.gk.resize(2 * nk), w.ek.resize(2 * nk), w.tk.resize(nk), w.turn.resize(nk), w.dev.resize(nk), w.turned.resize(nk);
    for (std::size_t k = 0; k < nk; ++k) {
      const std::size_t i = w.kept[k];
      w.gk[2 * k] = w.gs_at[2 * i], w.gk[2 * k + 1] = w.gs_at[2 * i + 1];
      w.ek[2 * k] = w.ge[2 * i], w.ek[2 * k + 1] = w.ge[2 * i + 1];
      w.tk[k] = w.ss_at[i];
    }
    // EditTurn, DirectionDeviation, Extremes. The largest turn the edit gives the walk counts
    // every span where the source walks, a step away and back included: an edit that sends a
    // take round a loop where it wanders turns it past 180 degrees there.
    TurnOf(w.gk.data(), w.ek.data(), w.tk.data(), nk, walking_speed, edit_turn_span, 0.0, w.at, w.angle, w.along,
           w.turn.data());
    double max_turn = 0.0;
    for (std::size_t k = 0; k < nk; ++k) {
      if (std::isnan(w.turn[k]) || std::isnan(max_turn)) max_turn = kNaN;
      else max_turn = std::max(max_turn, std::abs(w.turn[k]));
    }
    // The turn a walking direction is compared with is measured only where the source goes
    // somewhere over the span (the chord of a step away and back points anywhere), and is a
    // guess elsewhere (from the frames around; held from the first or last before the source
    // walks or after it stops). Where it is a guess, a chord walks back only if it also does
    // against the source as it is: a take that stands, then steps away and back where the edit
    // bends it, had its standing frames' small steps compared with a turn of 108 degrees that
    // only the step away gets (tests/inspect/test_metrics.py).
    TurnOf(w.gk.data(), w.ek.data(), w.tk.data(), nk, walking_speed, edit_turn_span, kLeastStraightness, w.at,
           w.angle, w.along, w.turn.data());
    DeviationOf(w.gk.data(), w.ek.data(), w.tk.data(), nk, walking_speed, chord, nullptr, w.dev.data());
    DeviationOf(w.gk.data(), w.ek.data(), w.tk.data(), nk, walking_speed, chord, w.turn.data(), w.turned.data());
    w.measured.assign(nk, 0);
    for (const double k : w.at) w.measured[static_cast<std::size_t>(k)] = 1;
    std::int64_t dev_frame = -1;
    double max_dev = kNaN, max_turned = kNaN;
    for (std::size_t k = 0; k < nk; ++k) {
      if (!std::isnan(w.dev[k]) && (dev_frame < 0 || w.dev[k] > max_dev))
        max_dev = w.dev[k], dev_frame = static_cast<std::int64_t>(w.kept[k]);
      const double turned = w.measured[k] ? w.turned[k] : std::min(w.turned[k], w.dev[k]);
      if (!std::isnan(turned) && (std::isnan(max_turned) || turned > max_turned)) max_turned = turned;
    }
    worst_direction_frame[a] = dev_frame;
    max_direction_deviation[a] = max_dev;
    max_turned_deviation[a] = max_turned;
    max_edit_turn[a] = max_turn * kDegrees;
  }
}

}  // namespace mocapedit
