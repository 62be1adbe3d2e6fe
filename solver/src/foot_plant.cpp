#include "mocapedit/foot_plant.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "mocapedit/two_threads.h"
#include "view_checks.h"

namespace mocapedit {
namespace {

using detail::BytesOverlap;

using Vec = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;

constexpr double kPi = 3.141592653589793;
// Rounds that settle a step's length: the body drifts while the foot is in the air, so the landing
// moves further the longer the step (as footplant.STEP_ROUNDS).
constexpr int kStepRounds = 12;

Vec V(const double* p) { return Vec(p[0], p[1], p[2]); }
Quat Q(const double* p) { return Quat(p[3], p[0], p[1], p[2]); }
void Put(const Vec& v, double* p) { p[0] = v.x(), p[1] = v.y(), p[2] = v.z(); }
void Put(const Quat& q, double* p) { p[0] = q.x(), p[1] = q.y(), p[2] = q.z(), p[3] = q.w(); }

// Lengths summed in index order (as numpy does), so the two jobs round alike.
double Norm(const Vec& v) { return std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()); }
double Norm(double v) { return std::abs(v); }
double Norm4(const Quat& q) { return std::sqrt(q.x() * q.x() + q.y() * q.y() + q.z() * q.z() + q.w() * q.w()); }
double Dot4(const Quat& a, const Quat& b) { return a.x() * b.x() + a.y() * b.y() + a.z() * b.z() + a.w() * b.w(); }

// Hamilton product a * b, term by term as mocapedit.solve.layering.quat_multiply writes it.
Quat Mul(const Quat& a, const Quat& b) {
  return Quat(a.w() * b.w() - a.x() * b.x() - a.y() * b.y() - a.z() * b.z(),
              a.w() * b.x() + a.x() * b.w() + a.y() * b.z() - a.z() * b.y(),
              a.w() * b.y() - a.x() * b.z() + a.y() * b.w() + a.z() * b.x(),
              a.w() * b.z() + a.x() * b.y() - a.y() * b.x() + a.z() * b.w());
}
Quat Conj(const Quat& q) { return Quat(q.w(), -q.x(), -q.y(), -q.z()); }

// An angle wrapped to [-pi, pi) as (a + pi) mod 2 pi - pi, the modulo taking the divisor's sign.
double Wrap(double a) {
  const double period = 2.0 * kPi;
  double m = std::fmod(a + kPi, period);
  if (m != 0.0) {
    if (m < 0.0) m += period;
  } else {
    m = 0.0;
  }
  return m - kPi;
}

double Sign(double v) { return v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0); }
double Clip(double v, double lo, double hi) { return std::min(std::max(v, lo), hi); }
double Smooth(double x) { return x * x * (3.0 - 2.0 * x); }

// 1 inside [first, last], easing to 0 over `in` frames before and `out` after (smoothstep).
double Ramp(double frame, double first, double last, double in, double out) {
  return Smooth(Clip(1.0 - std::max(first - frame, 0.0) / in - std::max(frame - last, 0.0) / out, 0.0, 1.0));
}

bool Sized(Span<const double> s, std::size_t n) { return s.size == n && (n == 0 || s.data); }
template <typename T>
bool SizedOut(Span<T> s, std::size_t n) { return s.size == n && (n == 0 || s.data); }

bool Finite(Span<const double> s) {
  for (double v : s)
    if (!std::isfinite(v)) return false;
  return true;
}

// A plant that starts at `current` and is dragged along, in the order of `run`, wherever
// `offset` lies further than `radius` from it, written to `out`; returns how far it slides from
// the first frame of `run` on.
template <typename T, typename Run>
double Follow(const std::vector<T>& offset, const std::vector<double>& radius, const Run& run, T current,
              std::vector<T>& out) {
  double slide = 0.0;
  bool first = true;
  for (const std::size_t i : run) {
    const T v = offset[i] - current;
    const double d = Norm(v);
    if (d > radius[i]) {
      const T moved = offset[i] - v * (radius[i] / d);
      if (!first) slide += Norm(T(moved - current));
      current = moved;
    }
    out[i] = current;
    first = false;
  }
  return slide;
}

// Plant shifts (or turns) over one contact row (see mocapedit.solve.footplant.leash): `base`
// while the edited foot stays within the leash, followed at the leash's length beyond it, from
// the start that slides least, or outwards from the rigid frames; frames before and after the
// contact take its first and last plant. `inside` and `rigid` are increasing indices;
// `radius_max` is the row's longest leash.
template <typename T>
std::vector<T> Leash(const std::vector<T>& offset, const T& base, const std::vector<std::size_t>& inside,
                     const std::vector<std::size_t>& rigid, const std::vector<double>& radius, double radius_max) {
  std::vector<T> out(offset.size(), base);
  bool far = false;
  for (const std::size_t i : inside) far = far || Norm(T(offset[i] - base)) > radius[i];
  if (!far) return out;
  if (!rigid.empty()) {
    std::vector<std::size_t> before, after;
    for (auto it = inside.rbegin(); it != inside.rend(); ++it)
      if (*it < rigid.front()) before.push_back(*it);
    for (const std::size_t i : inside)
      if (i > rigid.back()) after.push_back(i);
    Follow(offset, radius, before, base, out);
    Follow(offset, radius, after, base, out);
  } else {
    // Followed from `base`, the plant may slide where another start lets it slide less: the
    // plant where that path ends, followed back to the contact's start.
    const double slide = Follow(offset, radius, inside, base, out);
    std::vector<T> back = out;
    std::vector<std::size_t> reversed(inside.rbegin(), inside.rend());
    Follow(offset, radius, reversed, out[inside.back()], back);
    std::vector<T> other = out;
    if (Follow(offset, radius, inside, back[inside.front()], other) < slide - 1e-9 * std::max(radius_max, 1.0))
      out = std::move(other);
  }
  for (std::size_t i = 0; i < inside.front(); ++i) out[i] = out[inside.front()];
  for (std::size_t i = inside.back() + 1; i < out.size(); ++i) out[i] = out[inside.back()];
  return out;
}

// The step profile of mocapedit.solve.footplant.step_profile: (progress, lift) at the n + 1
// frames of a step.
struct Profile {
  std::vector<double> progress, lift;
  explicit Profile(int n) {
    for (int i = 0; i <= n; ++i) {
      const double s = i == n ? 1.0 : static_cast<double>(i) * (1.0 / static_cast<double>(n));
      const double x = Clip((s - 0.25) / (0.75 - 0.25), 0.0, 1.0);
      progress.push_back(Smooth(x));
      const double up = std::sin(kPi * s);
      lift.push_back(up * up);
    }
  }
};

// The ground distance a step moves its foot as the hip sees it at the step's fastest, the body
// drifting by `drift` over the step: mocapedit.solve.footplant.against_hip.
double AgainstHip(const Vec& step, const Vec& drift) {
  const double width = 0.75 - 0.25;
  return Norm(Vec(step - drift * (width / 1.5)));
}

// Frames a step takes: mocapedit.solve.footplant.step_frames.
int StepFrames(double distance, double turn, double height, double bend, double speed, double spin,
               double knee_spin, double seconds, int shortest) {
  const double width = 0.75 - 0.25;
  const double peak = std::hypot(1.5 * distance / width, kPi * height);
  const double need = std::max({peak / std::max(speed, 1e-300), 1.5 * std::abs(turn) / width / std::max(spin, 1e-300),
                                kPi * bend / std::max(knee_spin, 1e-300)});
  return std::max(shortest, static_cast<int>(std::ceil(need / seconds)));
}

// How much more a knee bends to lift its foot by `height`: mocapedit.solve.footplant.lift_bend.
double LiftBend(double thigh, double shin, double reach, double height) {
  auto interior = [&](double d) {
    d = Clip(d, std::abs(thigh - shin) + 1e-9, thigh + shin - 1e-9);
    return std::acos(Clip((thigh * thigh + shin * shin - d * d) / (2.0 * thigh * shin), -1.0, 1.0));
  };
  return std::max(interior(reach) - interior(reach - height), 0.0);
}

// One contact of one foot, over the poses lo .. lo + width - 1 its ramp reaches.
struct Row {
  double first = 0, last = 0;  // source frames
  std::size_t lo = 0, width = 0;
  std::vector<std::uint8_t> inside, rigid;
  std::vector<double> turn, yaw, radius, lift;
  std::vector<Vec> foot, offset, shift;
  std::vector<double> step_radius;  // the leash the foot steps at
  std::vector<Vec> step_shift;      // the plant's shift on that leash
  Vec pivot, base;
  double radius_max = 0, step_radius_max = 0;
  std::vector<std::size_t> inside_at, rigid_at;  // indices of inside (rigid) entries
};

struct Agent {
  const FootPlantJob& job;
  std::size_t lo, hi, index;
  int up_axis;  // 1: Y, 2: Z
  Vec up;
  std::array<std::vector<Row>, 2> rows;

  std::size_t Count() const { return hi - lo; }
  Vec Leg(const Span<const double>& s, std::size_t t, int k) const { return V(&s[3 * (2 * (lo + t) + k)]); }
  Quat LegQ(const Span<const double>& s, std::size_t t, int k) const { return Q(&s[4 * (2 * (lo + t) + k)]); }

  // p turned by `angle` about up (p @ yaw_matrix(angle) of mocapedit.geometry.kinematics).
  Vec Yaw(const Vec& p, double angle) const {
    const double c = std::cos(angle), s = std::sin(angle);
    if (up_axis == 2) return Vec(p.x() * c + p.y() * -s, p.x() * s + p.y() * c, p.z());
    return Vec(p.x() * c + p.z() * s, p.y(), p.x() * -s + p.z() * c);
  }

  Vec Carried(const Row& r, std::size_t w, double yaw) const { return Yaw(Vec(r.foot[w] - r.pivot), yaw) + r.base; }

  // The contacts of foot k, one row each, with their leashed plants.
  void Contacts(int k) {
    const FootPlantJob& p = job;
    const std::size_t count = Count();
    const double mpu = p.meters_per_unit;
    const double longest = p.max_leash_m * p.reach_leash[index];
    const double drop = p.max_drop_m / mpu, least = p.leash_m / mpu, most = longest / mpu;
    const double step_most = p.max_leash_m * std::min(p.step_leash[index], p.reach_leash[index]) / mpu;
    const bool step_apart = step_most != most;
    std::vector<double> radius(count), step_radius(count);
    for (std::size_t t = 0; t < count; ++t) {
      // As far as the leg reaches with the pelvis lowered a little.
      const Vec h = Leg(p.hip, t, k), kn = Leg(p.knee, t, k), a = Leg(p.ankle, t, k);
      const double length = Norm(Vec(kn - h)) + Norm(Vec(a - kn));
      const Vec apart = h - a;
      const double along = apart.x() * up.x() + apart.y() * up.y() + apart.z() * up.z();
      const double height = std::max(along - drop, 0.0);
      const double over = Norm(Vec(apart - along * up));
      const double soft = p.soft_reach * length;
      const double reach = std::sqrt(std::max(soft * soft - height * height, 0.0)) - over;
      radius[t] = Clip(reach, least, most);
      step_radius[t] = Clip(reach, least, step_most);
    }
    const double reach_blend = static_cast<double>(p.blend[index]) * longest / p.leash_m;
    const std::size_t c0 = static_cast<std::size_t>(p.contact_offsets[2 * index + k]);
    const std::size_t c1 = static_cast<std::size_t>(p.contact_offsets[2 * index + k + 1]);
    std::vector<Row>& out = rows[k];
    std::size_t width = 0;
    for (std::size_t c = c0; c < c1; ++c) {
      Row r;
      r.first = p.contacts[2 * c], r.last = p.contacts[2 * c + 1];
      bool used = false, any = false;
      for (std::size_t t = 0; t < count; ++t) {
        const double f = p.frames[lo + t];
        used = used || (f >= r.first - 1e-9 && f <= r.last + 1e-9);
        if (Ramp(f, r.first, r.last, reach_blend, reach_blend) > 0) {
          if (!any) r.lo = t;
          any = true;
          ++r.width;
        }
      }
      if (!used) continue;
      width = std::max(width, r.width);
      out.push_back(std::move(r));
    }
    const double leash_turn = p.leash_degrees * p.turn_leash[index] * (kPi / 180.0);
    for (Row& r : out) {
      const std::size_t n = r.width;
      // The longest leash over the leg's widest row from here (numpy's rows share one width).
      r.radius_max = 0.0, r.step_radius_max = 0.0;
      for (std::size_t w = 0; w < width; ++w) {
        r.radius_max = std::max(r.radius_max, radius[std::min(r.lo + w, count - 1)]);
        r.step_radius_max = std::max(r.step_radius_max, step_radius[std::min(r.lo + w, count - 1)]);
      }
      r.inside.assign(n, 0), r.rigid.assign(n, 0);
      r.turn.resize(n), r.radius.resize(n), r.foot.resize(n), r.offset.resize(n), r.lift.assign(n, 0.0);
      r.step_radius.resize(n);
      for (std::size_t w = 0; w < n; ++w) {
        const std::size_t t = r.lo + w;
        const double f = p.frames[lo + t];
        r.inside[w] = f >= r.first - 1e-9 && f <= r.last + 1e-9;
        // Where a contact meets a stationary range, the body moves rigidly: the plant is that motion.
        r.rigid[w] = r.inside[w] && p.stationary[lo + t];
        r.turn[w] = p.turn[lo + t];
        r.radius[w] = radius[t];
        r.step_radius[w] = step_radius[t];
        r.foot[w] = Leg(p.source_ankle, t, k);
        if (r.inside[w]) r.inside_at.push_back(w);
        if (r.rigid[w]) r.rigid_at.push_back(w);
      }
      const std::vector<std::size_t>& chosen = r.rigid_at.empty() ? r.inside_at : r.rigid_at;
      const double n_chosen = static_cast<double>(chosen.size());
      double sin_sum = 0.0, cos_sum = 0.0;
      for (const std::size_t w : chosen) sin_sum += std::sin(r.turn[w]), cos_sum += std::cos(r.turn[w]);
      const double yaw0 = std::atan2(sin_sum, cos_sum);
      // An edit that turns the body far during a contact turns the plant too.
      std::vector<double> apart(n);
      for (std::size_t w = 0; w < n; ++w) {
        const double d = r.turn[w] - yaw0;
        apart[w] = std::atan2(std::sin(d), std::cos(d));
      }
      const std::vector<double> turn_radius(n, leash_turn);
      r.yaw = Leash(apart, 0.0, r.inside_at, r.rigid_at, turn_radius, leash_turn);
      for (double& y : r.yaw) y = yaw0 + y;
      // Turned about the planted foot itself, so a plant that turns along does not slide.
      Vec pivot = Vec::Zero();
      double yaw_sum = 0.0;
      for (const std::size_t w : chosen) pivot += r.foot[w], yaw_sum += r.yaw[w];
      r.pivot = pivot / n_chosen;
      r.base = Yaw(r.pivot, yaw_sum / n_chosen);
      Vec mean = Vec::Zero();
      for (std::size_t w = 0; w < n; ++w) {
        r.offset[w] = Leg(p.ankle, r.lo + w, k) - Carried(r, w, r.yaw[w]);
        r.offset[w][up_axis] = 0.0;  // feet stay at their source height: never below their ground
      }
      for (const std::size_t w : chosen) mean += r.offset[w];
      r.shift = Leash(r.offset, Vec(mean / n_chosen), r.inside_at, r.rigid_at, r.radius, r.radius_max);
      r.step_shift = step_apart ? Leash(r.offset, Vec(mean / n_chosen), r.inside_at, r.rigid_at, r.step_radius,
                                        r.step_radius_max)
                                : r.shift;
    }
  }

  // Where a leashed foot would slide and the other bears the weight, it steps instead; writes
  // the steps into the rows (copies) and returns how many.
  int Replant(std::array<std::vector<Row>, 2>& legs, const double* stretch) const {
    const FootPlantJob& p = job;
    const std::size_t count = Count();
    const double mpu = p.meters_per_unit;
    std::array<std::vector<std::uint8_t>, 2> sliding;
    bool any = false;
    for (int k = 0; k < 2; ++k)
      for (const Row& r : legs[k]) {
        double slide = 0.0, turned = 0.0;
        // On the leash the foot steps at.
        for (std::size_t w = 0; w + 1 < r.width; ++w)
          if (r.inside[w] && r.inside[w + 1])
            slide += Norm(Vec(r.step_shift[w + 1] - r.step_shift[w])), turned += std::abs(r.yaw[w + 1] - r.yaw[w]);
        const bool s = slide > p.step_slide_m / mpu || turned > p.step_slide_degrees * (kPi / 180.0);
        sliding[k].push_back(s);
        any = any || s;
      }
    if (!any || count < 3) return 0;
    // Per pose and leg: the contact the foot is in (-1: none), whether it may step, and the
    // rows' values there.
    std::vector<long> contact(2 * count, -1);
    std::vector<std::uint8_t> movable(2 * count, 0);
    std::vector<Vec> offset(2 * count, Vec::Zero()), shift(2 * count, Vec::Zero());
    std::vector<double> radius(2 * count, 0.0), hold(2 * count, 0.0), turn(2 * count, 0.0), yaw(2 * count, 0.0);
    for (int k = 0; k < 2; ++k)
      for (std::size_t c = 0; c < legs[k].size(); ++c) {
        const Row& r = legs[k][c];
        for (const std::size_t w : r.inside_at) {
          const std::size_t i = 2 * (r.lo + w) + static_cast<std::size_t>(k);
          contact[i] = static_cast<long>(c);
          movable[i] = sliding[k][c] && !r.rigid[w];
          offset[i] = r.offset[w], shift[i] = r.shift[w], radius[i] = r.step_radius[w], hold[i] = r.radius[w];
          turn[i] = r.turn[w], yaw[i] = r.yaw[w];
        }
      }
    const double* seconds = &p.seconds[lo];
    // The fastest the source moves each foot against its hip, turns it, and bends its knee.
    std::vector<double> dx(count - 1);
    for (std::size_t t = 0; t + 1 < count; ++t) dx[t] = seconds[t + 1] - seconds[t];
    const bool uniform = std::all_of(dx.begin(), dx.end(), [&](double d) { return d == dx[0]; });
    std::array<double, 2> speed{}, spin{}, knee_spin{};
    auto turn_speed = [&](const auto& rotation) {
      double fastest = -INFINITY;
      for (std::size_t t = 0; t + 1 < count; ++t) {
        const Quat a = rotation(t + 1), b = rotation(t);
        const double dot = std::abs(Dot4(a, b)) / std::max(Norm4(a) * Norm4(b), 1e-300);
        fastest = std::max(fastest, 2.0 * std::acos(Clip(dot, 0.0, 1.0)) / std::max(dx[t], 1e-300));
      }
      return fastest;
    };
    for (int k = 0; k < 2; ++k) {
      auto f = [&](std::size_t t) { return Vec(Leg(p.source_ankle, t, k) - Leg(p.source_hip, t, k)); };
      double fastest = -INFINITY;
      for (std::size_t t = 0; t < count; ++t) {
        Vec g;
        if (t == 0) {
          g = (f(1) - f(0)) / dx[0];
        } else if (t + 1 == count) {
          g = (f(t) - f(t - 1)) / dx[t - 1];
        } else if (uniform) {
          g = (f(t + 1) - f(t - 1)) / (2. * dx[0]);
        } else {
          const double d1 = dx[t - 1], d2 = dx[t];
          const double a = -(d2) / (d1 * (d1 + d2)), b = (d2 - d1) / (d1 * d2), c = d1 / (d2 * (d1 + d2));
          g = a * f(t - 1) + b * f(t) + c * f(t + 1);
        }
        fastest = std::max(fastest, Norm(g));
      }
      speed[k] = std::max(p.step_foot_speed_ratio * fastest, p.step_min_foot_speed_m / mpu);
      spin[k] = std::max(turn_speed([&](std::size_t t) { return LegQ(p.source_ankle_rot, t, k); }),
                         p.step_min_turn_speed);
      knee_spin[k] = std::max(
          turn_speed([&](std::size_t t) { return Mul(Conj(LegQ(p.source_hip_rot, t, k)), LegQ(p.source_knee_rot, t, k)); }),
          p.step_min_knee_speed);
    }
    const double height = p.step_height_m / mpu;
    std::vector<double> bend(2 * count);
    for (std::size_t t = 0; t < count; ++t)
      for (int k = 0; k < 2; ++k) {
        const Vec h = Leg(p.hip, t, k), kn = Leg(p.knee, t, k), a = Leg(p.ankle, t, k);
        bend[2 * t + k] = LiftBend(Norm(Vec(kn - h)), Norm(Vec(a - kn)), Norm(Vec(a - h)), height);
      }
    std::vector<double> sorted = dx;
    std::sort(sorted.begin(), sorted.end());
    const std::size_t m = sorted.size();
    const double frame = m % 2 ? sorted[m / 2] : (sorted[m / 2 - 1] + sorted[m / 2]) / 2.0;
    const int shortest = std::max(2, static_cast<int>(std::nearbyint(p.step_seconds / frame)));
    const int longest = std::max(2, static_cast<int>(std::nearbyint(p.step_longest_seconds / frame)));
    const double turn_radius = job.leash_degrees * job.turn_leash[index] * (kPi / 180.0);

    std::vector<double> lift;
    const int steps = Steps(contact, movable, offset, radius, hold, turn, shift, yaw, lift, bend, turn_radius, frame,
                            shortest, longest, height, speed, spin, knee_spin, stretch);
    if (!steps) return 0;
    for (int k = 0; k < 2; ++k)
      for (std::size_t c = 0; c < legs[k].size(); ++c) {
        if (!sliding[k][c]) continue;
        Row& r = legs[k][c];
        for (const std::size_t w : r.inside_at) {
          const std::size_t i = 2 * (r.lo + w) + static_cast<std::size_t>(k);
          r.shift[w] = shift[i], r.yaw[w] = yaw[i], r.lift[w] = lift[i];
        }
        const std::size_t a = r.inside_at.front(), b = r.inside_at.back();
        for (std::size_t w = 0; w < a; ++w) r.shift[w] = r.shift[a], r.yaw[w] = r.yaw[a], r.lift[w] = 0.0;
        for (std::size_t w = b + 1; w < r.width; ++w) r.shift[w] = r.shift[b], r.yaw[w] = r.yaw[b], r.lift[w] = 0.0;
      }
    return steps;
  }

  // The step planner of mocapedit.solve.footplant.replant, on (pose, leg) arrays; writes shift,
  // yaw and lift (0 to 1 of the step height) and returns the steps taken.
  int Steps(const std::vector<long>& contact, std::vector<std::uint8_t> movable, const std::vector<Vec>& offset,
            const std::vector<double>& radius, const std::vector<double>& hold, const std::vector<double>& turn,
            std::vector<Vec>& shift,
            std::vector<double>& yaw, std::vector<double>& lift, const std::vector<double>& bend, double turn_radius, double seconds,
            int shortest, int longest, double height, const std::array<double, 2>& speed,
            const std::array<double, 2>& spin, const std::array<double, 2>& knee_spin, const double* stretch) const {
    const double trigger = job.trigger, lead = job.lead;
    const long count = static_cast<long>(Count());
    auto at = [](long t, int k) { return static_cast<std::size_t>(2 * t + k); };
    // A foot steps only through contacts during which the other foot is planted for at least
    // shortest + 3 frames in a row somewhere.
    {
      std::vector<std::uint8_t> standing(2 * static_cast<std::size_t>(count), 0);
      for (int k = 0; k < 2; ++k) {
        std::vector<long> seen;
        for (long t = 0; t < count; ++t)
          if (movable[at(t, k)]) seen.push_back(contact[at(t, k)]);
        std::sort(seen.begin(), seen.end());
        seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
        for (const long c : seen) {
          long run = 0, best = 0;
          for (long t = 0; t < count; ++t) {
            const bool v = contact[at(t, k)] >= 0 && contact[at(t, 1 - k)] >= 0 && contact[at(t, k)] == c;
            run = v ? run + 1 : 0;
            best = std::max(best, run);
          }
          if (best >= shortest + 3)
            for (long t = 0; t < count; ++t)
              if (contact[at(t, k)] == c) standing[at(t, k)] = 1;
        }
      }
      for (std::size_t i = 0; i < movable.size(); ++i) movable[i] = movable[i] && standing[i];
    }
    lift.assign(2 * static_cast<std::size_t>(count), 0.0);
    std::vector<std::uint8_t> stepping(2 * static_cast<std::size_t>(count), 0);
    std::vector<std::optional<Profile>> profiles;
    auto profile = [&](int n) -> const Profile& {
      if (static_cast<std::size_t>(n) >= profiles.size()) profiles.resize(static_cast<std::size_t>(n) + 1);
      if (!profiles[static_cast<std::size_t>(n)]) profiles[static_cast<std::size_t>(n)].emplace(n);
      return *profiles[static_cast<std::size_t>(n)];
    };
    struct Step {
      long t0;
      Vec from, to;
      double y0, y1;
      int n;
    };
    struct State {
      long contact;
      Vec plant;
      double yaw;
      std::optional<Step> step;
    };
    std::array<std::optional<State>, 2> state;
    int steps = 0;

    auto may_step = [&](int k, long c, long t, long t1) {
      if (!(t1 + 1 < count)) return false;
      for (long i = t; i <= t1 + 1; ++i)
        if (contact[at(i, k)] != c || !movable[at(i, k)]) return false;
      for (long i = std::max(t - 1, 0L); i < std::min(t1 + 2, count); ++i)
        if (contact[at(i, 1 - k)] < 0 || stepping[at(i, 1 - k)]) return false;
      return true;
    };
    auto landing = [&](int k, long t, long t1, double ahead, Vec& to, double& y1) {
      const Vec drift = offset[at(t1, k)] - offset[at(t, k)];
      const double norm = Norm(drift);
      to = offset[at(t1, k)];
      if (norm > 1e-3 * radius[at(t, k)]) to = to + drift * (ahead * radius[at(t1, k)] / norm);
      const double spun = Wrap(turn[at(t1, k)] - turn[at(t, k)]);
      y1 = turn[at(t1, k)] + (std::abs(spun) > 1e-3 * turn_radius ? Sign(spun) * ahead * turn_radius : 0.0);
    };

    for (long t = 0; t < count; ++t) {
      for (int k = 0; k < 2; ++k) {
        const std::size_t i = at(t, k);
        const long c = contact[i];
        if (c < 0 || !movable[i]) {
          state[k].reset();
          continue;
        }
        if (!state[k] || state[k]->contact != c) {
          const Vec& o = offset[i];
          const double r = radius[i];
          Vec ahead = shift[i] - o;
          ahead *= std::min(1.0, lead * r / std::max(Norm(ahead), 1e-300));
          const double turned = Clip(Wrap(yaw[i] - turn[i]), -lead * turn_radius, lead * turn_radius);
          state[k] = State{c, Vec(o + ahead), turn[i] + turned, std::nullopt};
        }
        State& s = *state[k];
        if (s.step) {
          const Step& st = *s.step;
          const Profile& prof = profile(st.n);
          const std::size_t j = static_cast<std::size_t>(t - st.t0);
          shift[i] = st.from + prof.progress[j] * Vec(st.to - st.from);
          yaw[i] = st.y0 + prof.progress[j] * Wrap(st.y1 - st.y0);
          lift[i] = prof.lift[j];
          if (static_cast<int>(j) == st.n) {
            s.plant = st.to, s.yaw = st.y1;
            s.step.reset();
          }
          continue;
        }
        const Vec& o = offset[i];
        const double r = radius[i];
        const bool far = Norm(Vec(o - s.plant)) > trigger * r;
        const bool turned = std::abs(Wrap(turn[i] - s.yaw)) > trigger * turn_radius;
        if (far || turned) {
          std::optional<Step> plan;
          // Landing `lead` ahead of the drift; where the foot cannot get there in time, landing
          // where the foot is then (as footplant.replant).
          const double aheads[2] = {lead, 0.0};
          for (int a = lead > 0 ? 0 : 1; a < 2 && !plan; ++a) {
            int n = shortest;
            for (int round = 0; round < kStepRounds; ++round) {  // the landing depends on the step's length, and the length on the landing
              if (n > longest || !may_step(k, c, t, t + n)) break;
              Vec to;
              double y1;
              landing(k, t, t + n, aheads[a], to, y1);
              int need = StepFrames(AgainstHip(Vec(to - s.plant), Vec(offset[at(t + n, k)] - o)), Wrap(y1 - s.yaw),
                                    height, bend[i], speed[k], spin[k],
                                    knee_spin[k], seconds, shortest);
              need = std::max(shortest, static_cast<int>(std::ceil(need * stretch[k])));
              if (need <= n) {
                plan = Step{t, s.plant, to, s.yaw, y1, n};
                break;
              }
              n = need;
            }
          }
          if (plan) {
            for (long j = t; j <= t + plan->n; ++j) stepping[at(j, k)] = 1;
            ++steps;
            shift[i] = s.plant, yaw[i] = s.yaw;
            s.step = plan;
            continue;
          }
        }
        // No step here: the plant follows at the leash's length (hold's).
        const double d = Norm(Vec(o - s.plant));
        const double held = hold[i];
        if (d > held) s.plant = o - Vec(o - s.plant) * (held / d);
        const double a = Wrap(turn[i] - s.yaw);
        if (std::abs(a) > turn_radius) s.yaw += a - Sign(a) * turn_radius;
        shift[i] = s.plant, yaw[i] = s.yaw;
      }
    }
    return steps;
  }

  // The targets, turns and weights of both legs from the rows' plants, with the agent's steps.
  void Plan() {
    const FootPlantJob& p = job;
    const std::size_t count = Count();
    const double mpu = p.meters_per_unit;
    std::array<std::vector<Row>, 2> legs = rows;
    const int steps = !legs[0].empty() && !legs[1].empty() ? Replant(legs, &p.stretch[2 * index]) : 0;
    p.steps[index] = steps;
    const double blend = p.blend[index], least = p.leash_m / mpu;
    const double ratio = p.max_leash_m * p.reach_leash[index] / p.leash_m;
    const double lifted = p.step_height_m / mpu;
    std::vector<Vec> pos_sum(2 * count, Vec::Zero());
    std::vector<Quat> rot_sum(2 * count, Quat(0, 0, 0, 0));
    std::vector<double> w_sum(2 * count, 0.0), weight(2 * count, 0.0);
    std::vector<std::uint8_t> stepping(2 * count, 0);
    for (int k = 0; k < 2; ++k)
      for (const Row& r : legs[k]) {
        for (std::size_t w = 0; w < r.width; ++w)
          if (r.lift[w] > 0) stepping[2 * (r.lo + w) + k] = 1;
        // The lock eases in and out over longer where the plant lies far from the edited foot.
        auto far = [&](std::size_t w) { return Norm(Vec(r.shift[w] - r.offset[w])) / least; };
        const double blend_in = blend * Clip(far(r.inside_at.front()), 1.0, ratio);
        const double blend_out = blend * Clip(far(r.inside_at.back()), 1.0, ratio);
        for (std::size_t w = 0; w < r.width; ++w) {
          const std::size_t t = r.lo + w, i = 2 * t + k;
          const double wt = Ramp(p.frames[lo + t], r.first, r.last, blend_in, blend_out);
          if (!(wt > 0)) continue;
          const double half = 0.5 * r.yaw[w], sine = std::sin(half);
          Quat plant_rot = Mul(Quat(std::cos(half), sine * up.x(), sine * up.y(), sine * up.z()),
                               LegQ(p.source_ankle_rot, t, k));
          if (Dot4(plant_rot, LegQ(p.ankle_rot, t, k)) < 0) plant_rot.coeffs() *= -1.0;
          const Vec plant = Carried(r, w, r.yaw[w]) + r.shift[w] + (r.lift[w] * lifted) * up;
          // Where the ramps of two contacts meet, their plants blend by weight: no jump.
          pos_sum[i] += wt * plant;
          rot_sum[i].coeffs() += wt * plant_rot.coeffs();
          w_sum[i] += wt;
          weight[i] = std::max(weight[i], wt);
        }
      }
    for (std::size_t t = 0; t < count; ++t)
      for (int k = 0; k < 2; ++k) {
        const std::size_t i = 2 * t + k, out = 2 * (lo + t) + k;
        if (w_sum[i] > 0) {
          Put(Vec(pos_sum[i] / w_sum[i]), &p.target[3 * out]);
          Put(Quat(rot_sum[i].coeffs() / std::max(Norm4(rot_sum[i]), 1e-12)), &p.target_rot[4 * out]);
        } else {
          Put(Leg(p.ankle, t, k), &p.target[3 * out]);
          Put(LegQ(p.ankle_rot, t, k), &p.target_rot[4 * out]);
        }
        p.weight[out] = weight[i];
        p.stepping[out] = stepping[i];
      }
  }
};

}  // namespace

void FootPlantJob::Validate() const {
  const char* job = "FootPlantJob";
  if (offsets.size == 0 || !offsets.data) throw InvalidInput(job, "offsets must hold #A + 1 values");
  if (offsets[0] != 0) throw InvalidInput(job, "offsets must start at 0");
  for (std::size_t a = 1; a < offsets.size; ++a)
    if (offsets[a] < offsets[a - 1]) throw InvalidInput(job, "offsets must not decrease");
  const std::size_t agents = offsets.size - 1, n = static_cast<std::size_t>(offsets[agents]);
  const struct { Span<const double> s; std::size_t size; const char* name; } inputs[] = {
      {frames, n, "frames"}, {seconds, n, "seconds"}, {turn, n, "turn"},
      {hip, n * 6, "hip"}, {knee, n * 6, "knee"}, {ankle, n * 6, "ankle"}, {ankle_rot, n * 8, "ankle_rot"},
      {source_hip, n * 6, "source_hip"}, {source_ankle, n * 6, "source_ankle"},
      {source_hip_rot, n * 8, "source_hip_rot"}, {source_knee_rot, n * 8, "source_knee_rot"},
      {source_ankle_rot, n * 8, "source_ankle_rot"}, {blend, agents, "blend"}, {stretch, agents * 2, "stretch"},
      {turn_leash, agents, "turn_leash"}, {reach_leash, agents, "reach_leash"}, {step_leash, agents, "step_leash"},
      {up, 3, "up"}};
  for (const auto& in : inputs)
    if (!Sized(in.s, in.size)) throw InvalidInput(job, std::string(in.name) + " must hold " + std::to_string(in.size) + " values");
  if (stationary.size != n || (n && !stationary.data)) throw InvalidInput(job, "stationary must hold #N flags");
  for (const auto& s : {frames, seconds, turn})
    if (!Finite(s)) throw InvalidInput(job, "frames, seconds and turns must be finite");
  if (contact_offsets.size != 2 * agents + 1 || !contact_offsets.data)
    throw InvalidInput(job, "contact_offsets must hold #2A + 1 values");
  if (contact_offsets[0] != 0) throw InvalidInput(job, "contact_offsets must start at 0");
  for (std::size_t i = 1; i < contact_offsets.size; ++i)
    if (contact_offsets[i] < contact_offsets[i - 1]) throw InvalidInput(job, "contact_offsets must not decrease");
  const auto contact_count = static_cast<std::size_t>(contact_offsets[2 * agents]);
  if (!Sized(contacts, 2 * contact_count))
    throw InvalidInput(job, "contacts must hold 2 frames for each of the " + std::to_string(contact_count) + " contacts");
  if (!Finite(contacts)) throw InvalidInput(job, "contact frames must be finite");
  for (double b : blend)
    if (!(std::isfinite(b) && b > 0)) throw InvalidInput(job, "blend frames must be finite and positive");
  for (double s : stretch)
    if (!(std::isfinite(s) && s > 0)) throw InvalidInput(job, "stretch must be finite and positive");
  for (double s : turn_leash)
    if (!(std::isfinite(s) && s > 0)) throw InvalidInput(job, "turn_leash must be finite and positive");
  for (double s : reach_leash)
    if (!(std::isfinite(s) && s >= 1)) throw InvalidInput(job, "reach_leash must be finite and at least 1");
  for (double s : step_leash)
    if (!(std::isfinite(s) && s >= 1)) throw InvalidInput(job, "step_leash must be finite and at least 1");
  const bool y_up = up[0] == 0 && up[1] == 1 && up[2] == 0, z_up = up[0] == 0 && up[1] == 0 && up[2] == 1;
  if (!y_up && !z_up) throw InvalidInput(job, "up must be +Y (0, 1, 0) or +Z (0, 0, 1)");
  const struct { double v; bool ok; const char* what; } settings[] = {
      {meters_per_unit, meters_per_unit > 0, "meters_per_unit must be positive"},
      {leash_m, leash_m > 0, "leash_m must be positive"},
      {max_leash_m, max_leash_m >= leash_m, "max_leash_m must not be below leash_m"},
      {max_drop_m, max_drop_m >= 0, "max_drop_m must not be negative"},
      {leash_degrees, leash_degrees > 0, "leash_degrees must be positive"},
      {soft_reach, soft_reach > 0 && soft_reach <= 1, "soft_reach must be within (0, 1]"},
      {step_slide_m, step_slide_m >= 0, "step_slide_m must not be negative"},
      {step_slide_degrees, step_slide_degrees >= 0, "step_slide_degrees must not be negative"},
      {step_seconds, step_seconds > 0, "step_seconds must be positive"},
      {step_longest_seconds, step_longest_seconds >= step_seconds, "step_longest_seconds must not be below step_seconds"},
      {step_height_m, step_height_m >= 0, "step_height_m must not be negative"},
      {step_foot_speed_ratio, step_foot_speed_ratio > 0, "step_foot_speed_ratio must be positive"},
      {step_min_foot_speed_m, step_min_foot_speed_m >= 0, "step_min_foot_speed_m must not be negative"},
      {step_min_turn_speed, step_min_turn_speed >= 0, "step_min_turn_speed must not be negative"},
      {step_min_knee_speed, step_min_knee_speed >= 0, "step_min_knee_speed must not be negative"},
      {trigger, trigger > 0, "trigger must be positive"},
      {lead, lead > 0, "lead must be positive"}};
  for (const auto& s : settings)
    if (!(std::isfinite(s.v) && s.ok)) throw InvalidInput(job, std::string(s.what) + " and finite");
  if (!SizedOut(target, n * 6)) throw InvalidInput(job, "target must hold " + std::to_string(n * 6) + " values");
  if (!SizedOut(target_rot, n * 8)) throw InvalidInput(job, "target_rot must hold " + std::to_string(n * 8) + " values");
  if (!SizedOut(weight, n * 2)) throw InvalidInput(job, "weight must hold " + std::to_string(n * 2) + " values");
  if (!SizedOut(stepping, n * 2)) throw InvalidInput(job, "stepping must hold " + std::to_string(n * 2) + " values");
  if (!SizedOut(steps, agents)) throw InvalidInput(job, "steps must hold " + std::to_string(agents) + " values");
  const struct { const void* data; std::size_t bytes; const char* name; } outputs[] = {
      {target.data, target.size * sizeof(double), "target"},
      {target_rot.data, target_rot.size * sizeof(double), "target_rot"},
      {weight.data, weight.size * sizeof(double), "weight"},
      {stepping.data, stepping.size, "stepping"},
      {steps.data, steps.size * sizeof(std::int64_t), "steps"}};
  for (std::size_t i = 0; i < 5; ++i) {
    for (const auto& in : inputs)
      if (BytesOverlap(outputs[i].data, outputs[i].bytes, in.s.data, in.s.size * sizeof(double)))
        throw InvalidInput(job, std::string(outputs[i].name) + " overlaps the input " + in.name);
    const struct { const void* data; std::size_t bytes; const char* name; } others[] = {
        {stationary.data, stationary.size, "stationary"},
        {contacts.data, contacts.size * sizeof(double), "contacts"},
        {contact_offsets.data, contact_offsets.size * sizeof(std::int64_t), "contact_offsets"},
        {offsets.data, offsets.size * sizeof(std::int64_t), "offsets"}};
    for (const auto& in : others)
      if (BytesOverlap(outputs[i].data, outputs[i].bytes, in.data, in.bytes))
        throw InvalidInput(job, std::string(outputs[i].name) + " overlaps the input " + in.name);
    for (std::size_t j = i + 1; j < 5; ++j)
      if (BytesOverlap(outputs[i].data, outputs[i].bytes, outputs[j].data, outputs[j].bytes))
        throw InvalidInput(job, std::string(outputs[i].name) + " overlaps " + outputs[j].name);
  }
}

void FootPlantJob::Run() const {
  Validate();
  const int up_axis = up[2] == 1 ? 2 : 1;
  OnAgentRuns(offsets.data, offsets.size - 1, threads, [&](std::size_t a) {
    Agent agent{*this, static_cast<std::size_t>(offsets[a]), static_cast<std::size_t>(offsets[a + 1]), a, up_axis,
                up_axis == 2 ? Vec(0, 0, 1) : Vec(0, 1, 0), {}};
    agent.Contacts(0);
    agent.Contacts(1);
    agent.Plan();
  });
}

}  // namespace mocapedit
