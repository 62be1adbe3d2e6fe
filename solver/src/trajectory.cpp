#include "mocapedit/trajectory.h"

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
    throw std::invalid_argument("TangentHeadings: one fallback heading is needed per fixed range");
  std::vector<char> is_fixed(static_cast<size_t>(n), 0);
  for (const auto& r : fixed) {
    if (r.first < 0 || r.second >= n || r.first > r.second)
      throw std::invalid_argument("TangentHeadings: frame range [" + std::to_string(r.first) + ", " +
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

}  // namespace mocapedit
