#include "mocapedit/foot_lock.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "mocapedit/two_threads.h"
#include "view_checks.h"

namespace mocapedit {
namespace {

using detail::Overlap;

using Vec = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;

Vec V(const double* p) { return Vec(p[0], p[1], p[2]); }
Quat Q(const double* p) { return Quat(p[3], p[0], p[1], p[2]); }
void Put(const Vec& v, double* p) { p[0] = v.x(), p[1] = v.y(), p[2] = v.z(); }
void Put(const Quat& q, double* p) { p[0] = q.x(), p[1] = q.y(), p[2] = q.z(), p[3] = q.w(); }

Vec Unit(const Vec& v) { return v / std::max(v.norm(), 1e-12); }

Quat UnitQ(const Quat& q) {
  const double n = std::max(q.coeffs().norm(), 1e-12);
  return Quat(q.w() / n, q.x() / n, q.y() / n, q.z() / n);
}

// Shortest-arc rotation taking unit a to unit b (half a turn about a perpendicular axis when
// they are opposite).
Quat Arc(const Vec& a, const Vec& b) {
  const double d = a.dot(b);
  if (d < -1.0 + 1e-12) {
    const Vec other = std::abs(a.x()) < 0.9 ? Vec(1, 0, 0) : Vec(0, 1, 0);
    const Vec flip = Unit(a.cross(other));
    return UnitQ(Quat(0.0, flip.x(), flip.y(), flip.z()));
  }
  const Vec axis = a.cross(b);
  return UnitQ(Quat(1.0 + d, axis.x(), axis.y(), axis.z()));
}

// The turn about unit `axis` taking a's direction around it onto b's: with (c, s) the cosine
// and sine of that angle, the half-angle quaternion is (s axis, 1 + c), normalised.
Quat Twist(const Vec& axis, const Vec& a, const Vec& b) {
  double c = a.dot(b), s = a.cross(b).dot(axis);
  const double r = std::hypot(c, s);
  if (r < 1e-300) return Quat::Identity();
  c /= r, s /= r;
  if (1.0 + c < 1e-12) return Quat(0.0, axis.x(), axis.y(), axis.z());  // half a turn
  const Vec v = axis * s;
  return UnitQ(Quat(1.0 + c, v.x(), v.y(), v.z()));
}

// The rotation taking the orthonormal pair (u0, n0) to (u1, n1).
Quat FrameDelta(const Vec& u0, const Vec& n0, const Vec& u1, const Vec& n1) {
  const Quat q1 = Arc(u0, u1);
  return UnitQ(Twist(u1, q1 * n0, n1) * q1);
}

// Normalised shortest-arc slerp (trigonometric; linear when the angle is tiny).
Quat SlerpQ(const Quat& a, Quat b, double t) {
  if (t == 0.0) return UnitQ(a);
  double dot = a.coeffs().dot(b.coeffs());
  if (dot < 0) b.coeffs() = -b.coeffs(), dot = -dot;
  const double theta = std::acos(std::min(dot, 1.0));
  const double s = std::sin(theta);
  double w0 = 1 - t, w1 = t;
  if (s >= 1e-6) w0 = std::sin((1 - t) * theta) / s, w1 = std::sin(t * theta) / s;
  Quat out;
  out.coeffs() = w0 * a.coeffs() + w1 * b.coeffs();
  return UnitQ(out);
}

Quat Local(const Quat& parent, const Quat& child) {
  Quat q = UnitQ(parent.conjugate() * child);
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  return q;
}

// How far a hip must go down along `up` for the leg to reach `target` within `reach`.
double RequiredDrop(const Vec& hip, const Vec& target, double reach, const Vec& up) {
  const Vec v = hip - target;
  const double vu = v.dot(up);
  const double disc = vu * vu - v.squaredNorm() + reach * reach;
  return std::max(disc >= 0 ? vu - std::sqrt(disc) : vu, 0.0);
}

bool Sized(Span<const double> s, std::size_t n) { return s.size == n && (n == 0 || s.data); }
bool Sized(Span<double> s, std::size_t n) { return s.size == n && (n == 0 || s.data); }

}  // namespace

void FootLockJob::Validate() const {
  if (offsets.size == 0 || !offsets.data) throw InvalidInput("FootLockJob", "offsets must hold #A + 1 values");
  if (offsets[0] != 0) throw InvalidInput("FootLockJob", "offsets must start at 0");
  for (std::size_t a = 1; a < offsets.size; ++a)
    if (offsets[a] < offsets[a - 1]) throw InvalidInput("FootLockJob", "offsets must not decrease");
  const std::size_t agents = offsets.size - 1, n = static_cast<std::size_t>(offsets[agents]);
  if (smooth.size != agents || (agents && !smooth.data)) throw InvalidInput("FootLockJob", "smooth must hold one value per agent");
  for (std::size_t a = 0; a < agents; ++a)
    if (smooth[a] < 0) throw InvalidInput("FootLockJob", "smooth frames must not be negative");
  if (!Sized(up, 3)) throw InvalidInput("FootLockJob", "up must hold 3 values");
  const double len = std::sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
  if (!std::isfinite(len) || std::abs(len - 1.0) > 1e-6) throw InvalidInput("FootLockJob", "up must be a unit vector");
  const struct { Span<const double> s; std::size_t w; const char* name; } inputs[] = {
      {hip, 3, "hip"}, {knee, 3, "knee"}, {ankle, 3, "ankle"}, {parent_rot, 4, "parent_rot"},
      {hip_rot, 4, "hip_rot"}, {knee_rot, 4, "knee_rot"}, {ankle_rot, 4, "ankle_rot"},
      {target, 3, "target"}, {target_rot, 4, "target_rot"}, {weight, 1, "weight"}, {hinge, 3, "hinge"}};
  for (const auto& in : inputs)
    if (!Sized(in.s, n * 2 * in.w))
      throw InvalidInput("FootLockJob", std::string(in.name) + " must hold " + std::to_string(n * 2 * in.w) + " values");
  for (std::size_t i = 0; i < n * 2; ++i)
    if (!(weight[i] >= 0.0 && weight[i] <= 1.0)) throw InvalidInput("FootLockJob", "weights must be within [0, 1]");
  if (keep.size != 0 && (keep.size != n || !keep.data)) throw InvalidInput("FootLockJob", "keep must be empty or hold #N flags");
  if (!(max_reach > 0.0 && max_reach < 1.0)) throw InvalidInput("FootLockJob", "max_reach must be within (0, 1)");
  if (!(soft_reach > 0.0 && soft_reach <= max_reach)) throw InvalidInput("FootLockJob", "soft_reach must be within (0, max_reach]");
  if (!(bend_noise >= 0.0 && bend_trust > 0.0)) throw InvalidInput("FootLockJob", "bend_noise must be >= 0 and bend_trust > 0");
  const struct { Span<double> s; std::size_t size; const char* name; } outputs[] = {
      {hip_local, n * 8, "hip_local"}, {knee_local, n * 8, "knee_local"}, {ankle_local, n * 8, "ankle_local"},
      {drop, n, "drop"}, {reached, n * 6, "reached"}};
  for (const auto& out : outputs)
    if (!Sized(out.s, out.size))
      throw InvalidInput("FootLockJob", std::string(out.name) + " must hold " + std::to_string(out.size) + " values");
  for (std::size_t i = 0; i < 5; ++i) {
    for (const auto& in : inputs)
      if (Overlap(outputs[i].s.data, outputs[i].s.size, in.s.data, in.s.size))
        throw InvalidInput("FootLockJob", std::string(outputs[i].name) + " overlaps the input " + in.name);
    for (std::size_t j = i + 1; j < 5; ++j)
      if (Overlap(outputs[i].s.data, outputs[i].s.size, outputs[j].s.data, outputs[j].s.size))
        throw InvalidInput("FootLockJob", std::string(outputs[i].name) + " overlaps " + outputs[j].name);
  }
}

namespace {

struct Agent {
  const FootLockJob& job;
  std::size_t lo, hi;
  std::size_t agent_index = 0;
  // Per leg of each pose (2 per pose): blended target, full length, soft and hard reach limits.
  std::vector<Vec> target;
  std::vector<double> full, soft, limit, required, peak;

  // Blends the targets and measures each leg; the least drop along -up that lets both legs
  // reach, then eased over `smooth` frames.
  void LowerPelvis(const Vec& up) {
    const std::size_t n = hi - lo;
    const auto s = static_cast<std::size_t>(job.smooth[agent_index]);
    target.resize(2 * n), full.resize(2 * n), soft.resize(2 * n), limit.resize(2 * n);
    required.assign(n, 0.0);
    bool any = false;
    for (std::size_t t = 0; t < n; ++t) {
      for (std::size_t leg = 0; leg < 2; ++leg) {
        const std::size_t i = 2 * (lo + t) + leg, k = 2 * t + leg;
        const Vec h = V(&job.hip[3 * i]), kn = V(&job.knee[3 * i]), a = V(&job.ankle[3 * i]);
        const double w = std::clamp(job.weight[i], 0.0, 1.0);
        target[k] = a + w * (V(&job.target[3 * i]) - a);
        full[k] = (kn - h).norm() + (a - kn).norm();
        // A leg already stretched further than the soft limit in its own pose keeps that stretch.
        const double stretch = (a - h).norm();
        soft[k] = std::max(stretch, job.soft_reach * full[k]);
        limit[k] = std::max(stretch, job.max_reach * full[k]);
        required[t] = std::max(required[t], RequiredDrop(h, target[k], soft[k], up));
      }
      any = any || required[t] > 0;
    }
    if (!any || s == 0 || n == 0) {
      std::copy(required.begin(), required.end(), job.drop.data + lo);
      KeepStill(s);
      return;
    }
    peak.assign(n, 0.0);
    for (std::size_t t = 0; t < n; ++t) {
      const std::size_t a = t >= s ? t - s : 0, b = std::min(n - 1, t + s);
      peak[t] = *std::max_element(required.begin() + a, required.begin() + b + 1);
    }
    const double count = static_cast<double>(2 * s + 1);
    for (std::size_t t = 0; t < n; ++t) {
      double sum = 0;
      for (std::ptrdiff_t k = static_cast<std::ptrdiff_t>(t) - static_cast<std::ptrdiff_t>(s);
           k <= static_cast<std::ptrdiff_t>(t + s); ++k)
        sum += peak[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(k, 0, n - 1))];
      job.drop[lo + t] = sum / count;
    }
    KeepStill(s);
  }

  // The drop is 0 at kept poses and rises linearly over s + 1 poses away from them.
  void KeepStill(std::size_t s) {
    if (job.keep.empty()) return;
    const std::size_t n = hi - lo;
    const double far = static_cast<double>(n) + static_cast<double>(s) + 2.0;
    std::vector<double> distance(n, far);
    double last = -far;
    for (std::size_t t = 0; t < n; ++t) {
      if (job.keep[lo + t]) last = static_cast<double>(t);
      distance[t] = static_cast<double>(t) - last;
    }
    last = 2.0 * far;
    for (std::size_t t = n; t-- > 0;) {
      if (job.keep[lo + t]) last = static_cast<double>(t);
      distance[t] = std::min(distance[t], last - static_cast<double>(t));
    }
    for (std::size_t t = 0; t < n; ++t)
      job.drop[lo + t] *= std::min(distance[t] / static_cast<double>(s + 1), 1.0);
  }

  void SolveLeg(std::size_t pose, std::size_t leg, const Vec& up) const {
    const std::size_t i = 2 * pose + leg, k = 2 * (pose - lo) + leg;
    const Vec shift = -job.drop[pose] * up;
    const Vec& goal = target[k];
    const Vec hip = V(&job.hip[3 * i]) + shift, knee = V(&job.knee[3 * i]) + shift,
              ankle = V(&job.ankle[3 * i]) + shift;
    const double l1 = (knee - hip).norm(), l2 = (ankle - knee).norm();

    const Vec to_target = goal - hip;
    const double dist = to_target.norm();
    const double room = std::max(limit[k] - soft[k], 1e-12);
    double reach = dist > soft[k] ? soft[k] + room * (1.0 - std::exp(-(dist - soft[k]) / room)) : dist;
    reach = std::max(reach, std::abs(l1 - l2) * 1.0001 + 1e-9);
    const Vec d = Unit(to_target);

    const Quat knee_rot = Q(&job.knee_rot[4 * i]);
    // A nearly straight knee says little about its plane: there the hinge axis takes over.
    const Vec cross = (knee - hip).cross(ankle - hip);
    const double trust =
        std::clamp((cross.norm() / std::max(l1 * l2, 1e-30) - job.bend_noise) / job.bend_trust, 0.0, 1.0);
    const Vec hinge = Unit(V(&job.hinge[3 * i]));
    Vec normal = trust * Unit(cross) + (1.0 - trust) * hinge;
    normal = normal.norm() < 1e-6 ? hinge : Unit(normal);
    const Vec n1 = Unit(normal - normal.dot(d) * d);
    const Vec bend = d.cross(n1);
    const double along = (l1 * l1 - l2 * l2 + reach * reach) / (2.0 * reach);
    const double height = std::sqrt(std::max(l1 * l1 - along * along, 0.0));
    const Vec new_knee = hip + along * d + height * bend;
    const Vec new_ankle = hip + reach * d;

    const Vec u0 = Unit(knee - hip), n0 = Unit(normal - normal.dot(u0) * u0), u1 = Unit(new_knee - hip);
    const Quat hip_rot = FrameDelta(u0, n0, u1, n1) * Q(&job.hip_rot[4 * i]);
    const Vec v0 = Unit(ankle - knee), m0 = Unit(normal - normal.dot(v0) * v0), v1 = Unit(new_ankle - new_knee);
    const Quat new_knee_rot = FrameDelta(v0, m0, v1, n1) * knee_rot;
    const double w = std::clamp(job.weight[i], 0.0, 1.0);
    const Quat ankle_rot = SlerpQ(Q(&job.ankle_rot[4 * i]), Q(&job.target_rot[4 * i]), w);

    Put(Local(Q(&job.parent_rot[4 * i]), hip_rot), &job.hip_local[4 * i]);
    Put(Local(hip_rot, new_knee_rot), &job.knee_local[4 * i]);
    Put(Local(new_knee_rot, ankle_rot), &job.ankle_local[4 * i]);
    Put(new_ankle, &job.reached[3 * i]);
  }
};

}  // namespace

void FootLockJob::Run() const {
  Validate();
  const Vec up_v = V(up.data);
  OnAgentRuns(offsets.data, offsets.size - 1, threads, [&](std::size_t a) {
    Agent agent{*this, static_cast<std::size_t>(offsets[a]), static_cast<std::size_t>(offsets[a + 1]), a};
    agent.LowerPelvis(up_v);
    for (std::size_t p = agent.lo; p < agent.hi; ++p)
      for (std::size_t leg = 0; leg < 2; ++leg) agent.SolveLeg(p, leg, up_v);
  });
}

}  // namespace mocapedit
