#include "mocapedit/trajectory.h"
#include "mocapedit/errors.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace mocapedit {

double PathLength(const Eigen::Ref<const Trajectory2>& points) {
  if (points.rows() < 2) return 0.0;
  return (points.bottomRows(points.rows() - 1) - points.topRows(points.rows() - 1))
      .rowwise()
      .norm()
      .sum();
}

Eigen::VectorXd CumulativeArcLength(const Eigen::Ref<const Trajectory2>& points) {
  const Eigen::Index n = points.rows();
  Eigen::VectorXd s = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 1; i < n; ++i) s[i] = s[i - 1] + (points.row(i) - points.row(i - 1)).norm();
  return s;
}

void UnwrapAngles(Eigen::Ref<Eigen::VectorXd> angles) {
  constexpr double kTwoPi = 2.0 * M_PI;
  for (Eigen::Index i = 1; i < angles.size(); ++i) {
    const double turns = (angles[i] - angles[i - 1]) / kTwoPi;
    // std::round is a library call; most steps turn by far less than half a turn.
    if (!(std::abs(turns) < 0.5)) angles[i] -= kTwoPi * std::round(turns);
  }
}

Eigen::VectorXd TangentHeadings(const Eigen::Ref<const Trajectory2>& points,
                                const std::vector<FrameRange>& fixed,
                                const Eigen::Ref<const Eigen::VectorXd>& fallback,
                                double min_step) {
  const Eigen::Index n = points.rows();
  if (static_cast<Eigen::Index>(fixed.size()) != fallback.size())
    throw InvalidInput("TangentHeadings", "one fallback heading is needed per fixed range");
  std::vector<char> is_fixed(static_cast<size_t>(n), 0);
  for (const auto& r : fixed) {
    if (r.first < 0 || r.second >= n || r.first > r.second)
      throw InvalidInput("TangentHeadings", "frame range [" + std::to_string(r.first) + ", " +
                                  std::to_string(r.second) + "] is outside 0.." +
                                  std::to_string(n - 1));
    for (int i = r.first; i <= r.second; ++i) is_fixed[static_cast<size_t>(i)] = 1;
  }

  Eigen::VectorXd heading = Eigen::VectorXd::Zero(n);
  std::vector<char> known(static_cast<size_t>(n), 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (is_fixed[static_cast<size_t>(i)]) continue;
    const Eigen::Index a = i > 0 ? i - 1 : i;
    const Eigen::Index b = i + 1 < n ? i + 1 : i;
    const Eigen::RowVector2d t = points.row(b) - points.row(a);
    if (t.norm() > min_step * static_cast<double>(b - a)) {
      heading[i] = std::atan2(t[1], t[0]);
      known[static_cast<size_t>(i)] = 1;
    }
  }
  // Frames standing still take the heading of the nearest moving frame, earlier first.
  Eigen::Index last = -1;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (known[static_cast<size_t>(i)]) {
      if (last < 0)
        for (Eigen::Index j = 0; j < i; ++j)
          if (!is_fixed[static_cast<size_t>(j)]) heading[j] = heading[i];
      last = i;
    } else if (!is_fixed[static_cast<size_t>(i)] && last >= 0) {
      heading[i] = heading[last];
    }
  }
  UnwrapAngles(heading);
  for (size_t k = 0; k < fixed.size(); ++k)
    for (int i = fixed[k].first; i <= fixed[k].second; ++i) heading[i] = fallback[static_cast<Eigen::Index>(k)];
  return heading;
}

namespace {

// Travel, in units of `min_travel`, from which a frame's own turn counts in full.
constexpr double kConfidentTravel = 4.0;
// A path that goes somewhere: over windows of kStraightWindows turn windows each side, the
// chord is at least kStraightFrom of the distance walked for a frame's turn to count at all,
// and kStraightFrom + kStraightRamp of it to count in full. A clip that moves about one spot (a
// boxer's bounce, a dance, an idle's shuffle) has no direction for an edit to turn: its
// wiggles' rotation is not the body's.
constexpr int kStraightWindows = 3;
constexpr double kStraightFrom = 0.4, kStraightRamp = 0.3;

double Straightness(double chord, double walked) {
  if (!(walked > 0.0)) return 0.0;
  return std::clamp((chord / walked - kStraightFrom) / kStraightRamp, 0.0, 1.0);
}

// How far each frame's own turn counts (`weight`): 0 where the source travels less than
// min_travel from `h` frames before to `h` after, 1 from kConfidentTravel times that, in
// proportion between; with `spot`, times the straightness of the path around it. Also the
// distance walked and the displacement from the first frame, cuts left out of both (a clip's
// first frame left at its rest pose at the origin must not make the frames near it look as if
// they go somewhere).
struct Confidence {
  Eigen::VectorXd weight, walked;
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> moved;

  Confidence(const Eigen::Ref<const Trajectory2>& source, Eigen::Index h, double min_travel, double max_step,
             bool spot) {
    const Eigen::Index n = source.rows();
    weight = Eigen::VectorXd::Zero(n);
    walked = Eigen::VectorXd::Zero(n);
    moved = Eigen::MatrixX2d::Zero(n, 2);
    for (Eigen::Index k = 0; k + 1 < n; ++k) {
      const Eigen::RowVector2d s = source.row(k + 1) - source.row(k);
      const bool cut = max_step > 0.0 && s.squaredNorm() > max_step * max_step;
      walked[k + 1] = walked[k] + (cut ? 0.0 : s.norm());
      moved.row(k + 1) = moved.row(k) + (cut ? Eigen::RowVector2d::Zero() : s);
    }
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Index lo = std::max<Eigen::Index>(i - h, 0), hi = std::min<Eigen::Index>(i + h, n - 1);
      const double travel = (source.row(hi) - source.row(lo)).norm();
      if (travel >= min_travel)
        weight[i] = min_travel > 0.0 ? std::min(1.0, (travel - min_travel) / ((kConfidentTravel - 1.0) * min_travel))
                                     : 1.0;
      if (spot && weight[i] > 0.0) weight[i] *= StraightnessAt(i, h);
    }
  }

  // The straightness of the path over kStraightWindows windows of `h` frames each side of frame i.
  double StraightnessAt(Eigen::Index i, Eigen::Index h) const {
    const Eigen::Index n = walked.size(), wide = kStraightWindows * h;
    const Eigen::Index wlo = std::max<Eigen::Index>(i - wide, 0), whi = std::min<Eigen::Index>(i + wide, n - 1);
    return Straightness((moved.row(whi) - moved.row(wlo)).norm(), walked[whi] - walked[wlo]);
  }
};

// The frames that are not keys: each pulled towards its own turn by its weight, and held to
// its neighbours by springs of stiffness window^2 (so a frame sure of itself bends the turn
// over about `window` frames, and a noisy, barely moving one over many more, diluted). Keys
// keep their value; with none, every frame is also held to `turn`, the whole path's, by
// `prior` (weakly for a path that goes somewhere, as strongly as a sure frame for one that
// stays about one spot). `turn` holds the interpolation between the keys on entry and the
// result on return.
void SmoothOwnTurns(const Eigen::VectorXd& own, const Eigen::VectorXd& weight, const std::vector<char>& key,
                    double prior, int window, Eigen::VectorXd& turn) {
  const Eigen::Index n = turn.size();
  if (!(weight.array() > 0.0).any() || n < 2) return;
  const double spring = double(window) * double(window);
  // Tridiagonal system (lower, diagonal, upper, rhs), solved by the Thomas algorithm.
  Eigen::VectorXd lower = Eigen::VectorXd::Zero(n), diag(n), upper = Eigen::VectorXd::Zero(n), rhs(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (key[static_cast<size_t>(i)]) {
      diag[i] = 1.0;
      rhs[i] = turn[i];
      continue;
    }
    const double w = weight[i] < 1.0 ? weight[i] : 1.0;
    const double target = turn[i] + std::remainder(own[i] - turn[i], 2.0 * M_PI);
    diag[i] = w + prior;
    rhs[i] = w * target + prior * turn[i];
    if (i > 0) {
      diag[i] += spring;
      lower[i] = -spring;
    }
    if (i + 1 < n) {
      diag[i] += spring;
      upper[i] = -spring;
    }
  }
  for (Eigen::Index i = 1; i < n; ++i) {
    const double m = lower[i] / diag[i - 1];
    diag[i] -= m * upper[i - 1];
    rhs[i] -= m * rhs[i - 1];
  }
  turn[n - 1] = rhs[n - 1] / diag[n - 1];
  for (Eigen::Index i = n - 2; i >= 0; --i) turn[i] = (rhs[i] - upper[i] * turn[i + 1]) / diag[i];
}

}  // namespace

Eigen::VectorXd DeformationTurns(const Eigen::Ref<const Trajectory2>& source,
                                 const Eigen::Ref<const Trajectory2>& edited,
                                 const std::vector<FrameRange>& fixed,
                                 const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window,
                                 double min_travel, double max_step, bool keep_spot) {
  const Eigen::Index n = source.rows();
  if (edited.rows() != n) throw InvalidInput("DeformationTurns", "source and edited differ in frames");
  if (static_cast<Eigen::Index>(fixed.size()) != fixed_turn.size())
    throw InvalidInput("DeformationTurns", "one turn is needed per fixed range");
  for (const auto& r : fixed)
    if (r.first < 0 || r.second >= n || r.first > r.second)
      throw InvalidInput("DeformationTurns", "frame range [" + std::to_string(r.first) + ", " +
                                  std::to_string(r.second) + "] is outside 0.." + std::to_string(n - 1));
  Eigen::VectorXd turn = Eigen::VectorXd::Zero(n);
  if (n == 0) return turn;
  const Eigen::Index h = std::max(1, window);
  // Prefix sums of conj(s_k) e_k = (s.e, s x e) over the steps k -> k+1.
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> steps = Eigen::MatrixX2d::Zero(n, 2);
  for (Eigen::Index k = 0; k + 1 < n; ++k) {
    const Eigen::RowVector2d s = source.row(k + 1) - source.row(k);
    const Eigen::RowVector2d e = edited.row(k + 1) - edited.row(k);
    const double cut = max_step > 0.0 && s.squaredNorm() > max_step * max_step ? 0.0 : 1.0;
    steps(k + 1, 0) = steps(k, 0) + cut * (s[0] * e[0] + s[1] * e[1]);
    steps(k + 1, 1) = steps(k, 1) + cut * (s[0] * e[1] - s[1] * e[0]);
  }
  // The first window sums the steps from i - h to i + h - 1; the second sums those over the
  // frames from i - h to i + h.
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> once(n + 1, 2);
  once.row(0).setZero();
  std::vector<char> in_range(static_cast<size_t>(n), 0);
  const bool spot = keep_spot && min_travel > 0.0;
  Confidence sure(source, h, min_travel, max_step, spot);
  Eigen::VectorXd& weight = sure.weight;
  const Eigen::VectorXd& walked = sure.walked;
  const auto& moved = sure.moved;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index lo = std::max<Eigen::Index>(i - h, 0), hi = std::min<Eigen::Index>(i + h, n - 1);
    once.row(i + 1) = once.row(i) + (steps.row(hi) - steps.row(lo));
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index lo = std::max<Eigen::Index>(i - h, 0), hi = std::min<Eigen::Index>(i + h, n - 1);
    const Eigen::RowVector2d z = once.row(hi + 1) - once.row(lo);
    turn[i] = std::atan2(z[1], z[0]);
    if (z[0] == 0.0 && z[1] == 0.0) weight[i] = 0.0;
  }
  for (size_t r = 0; r < fixed.size(); ++r) {
    const Eigen::Index a = fixed[r].first, b = fixed[r].second;
    // The frames next to a rigid range blend from its turn into the moving frames'.
    for (Eigen::Index i = std::max<Eigen::Index>(a - h, 0); i <= std::min<Eigen::Index>(b + h, n - 1); ++i)
      weight[i] = 0.0;
  }
  for (size_t r = 0; r < fixed.size(); ++r)
    for (Eigen::Index i = fixed[r].first; i <= fixed[r].second; ++i) {
      in_range[static_cast<size_t>(i)] = 1;
      turn[i] = fixed_turn[static_cast<Eigen::Index>(r)];
    }
  if ((weight.array() == 0.0).all() && fixed.empty()) return Eigen::VectorXd::Zero(n);  // nothing moves: no turn
  const Eigen::VectorXd own = turn;
  std::vector<Eigen::Index> keys;
  for (Eigen::Index i = 0; i < n; ++i)
    if (weight[i] == 1.0 || in_range[static_cast<size_t>(i)]) keys.push_back(i);
  if (keys.empty()) {
    // Nothing travels far enough to be sure of: the whole path's rotation, for every frame, as
    // far as the path goes somewhere (none for a clip that stays about one spot).
    const double whole = std::atan2(steps(n - 1, 1), steps(n - 1, 0));
    const double sure = spot ? Straightness(moved.row(n - 1).norm(), walked[n - 1]) : 1.0;
    turn.setConstant(steps.row(n - 1).isZero(0.0) ? 0.0 : sure * whole);
    SmoothOwnTurns(own, weight, std::vector<char>(static_cast<size_t>(n), 0), 1e-6 + (1.0 - sure),
                   static_cast<int>(h), turn);
    return turn;
  }
  Eigen::VectorXd v(static_cast<Eigen::Index>(keys.size()));
  for (size_t k = 0; k < keys.size(); ++k) v[static_cast<Eigen::Index>(k)] = turn[keys[k]];
  UnwrapAngles(v);
  for (size_t k = 0; k < keys.size(); ++k)
    if (in_range[static_cast<size_t>(keys[k])]) {  // ranges keep their own angle exactly
      v.array() += turn[keys[k]] - v[static_cast<Eigen::Index>(k)];
      break;
    }
  // By frame between the keys, held beyond the first and the last.
  size_t k = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    while (k + 1 < keys.size() && keys[k + 1] <= i) ++k;
    const Eigen::Index x0 = keys[k];
    if (i <= x0 || k + 1 == keys.size()) {
      turn[i] = v[static_cast<Eigen::Index>(k)];
    } else {
      const Eigen::Index x1 = keys[k + 1];
      const double t = static_cast<double>(i - x0) / static_cast<double>(x1 - x0);
      turn[i] = v[static_cast<Eigen::Index>(k)] + t * (v[static_cast<Eigen::Index>(k + 1)] - v[static_cast<Eigen::Index>(k)]);
    }
  }
  std::vector<char> key(static_cast<size_t>(n), 0);
  for (Eigen::Index i : keys) key[static_cast<size_t>(i)] = 1;
  SmoothOwnTurns(own, weight, key, 0.0, static_cast<int>(h), turn);
  return turn;
}

double SpotWeight(const Eigen::Ref<const Trajectory2>& source, int window, double min_travel, double max_step) {
  const Eigen::Index n = source.rows();
  if (n < 2 || !(min_travel > 0.0)) return 0.0;
  const Confidence sure(source, std::max(1, window), min_travel, max_step, true);
  if ((sure.weight.array() == 1.0).any()) return 0.0;
  return 1.0 - Straightness(sure.moved.row(n - 1).norm(), sure.walked[n - 1]);
}

}  // namespace mocapedit
