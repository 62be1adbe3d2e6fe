// GroupMeshTerms (path_terms.h): the edges and triangles of a group mesh, each member
// joined at each sampled time to its nearest members, and clusters left apart joined to
// their nearest other cluster.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <utility>
#include <vector>

#include "mocapedit/errors.h"
#include "mocapedit/path_terms.h"
#include "mocapedit/two_threads.h"
#include "union_find.h"

namespace mocapedit {
namespace {

using detail::Require;
using IntGrid = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Groups with at least this many member samples (members x sampled times) find their
// neighbours on two threads.
constexpr Eigen::Index kParallelMemberSamples = 2000;

// Distance as numpy's norm computes it (sqrt of the summed squares), so that ties and
// thresholds decide exactly as the reference implementation does.
double Distance(const Eigen::Ref<const Trajectory2>& p, Eigen::Index a, Eigen::Index b) {
  const double dx = p(a, 0) - p(b, 0), dy = p(a, 1) - p(b, 1);
  return std::sqrt(dx * dx + dy * dy);
}

// Finds the member pairs to join at a run of sampled times, appending each as (min << 32 |
// max): sorting integers is cheaper than sorting pairs.
class MeshJoiner {
 public:
  MeshJoiner(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const IntGrid>& members, int neighbours,
             std::vector<uint64_t>& pairs)
      : rest_(rest),
        members_(members),
        neighbours_(neighbours),
        keep_(neighbours + 1),
        m_(static_cast<int>(members.rows())),
        pairs_(pairs),
        x_(static_cast<size_t>(m_)),
        y_(static_cast<size_t>(m_)),
        cell_of_(static_cast<size_t>(m_)),
        items_(static_cast<size_t>(m_)),
        near_(static_cast<size_t>(keep_)),
        cluster_(static_cast<size_t>(m_)),
        first_(static_cast<size_t>(m_) + 1),
        listed_(static_cast<size_t>(m_)) {}

  void Run(Eigen::Index t_begin, Eigen::Index t_end) {
    pairs_.reserve(static_cast<size_t>(m_ * (t_end - t_begin) * neighbours_));
    for (Eigen::Index t = t_begin; t < t_end && neighbours_ > 0; ++t) {
      now_ = t;
      joined_.Reset(m_);
      Bucket(t);
      JoinNearest();
      JoinClusters();
    }
  }

 private:
  double Squared(int a, int b) const {  // as Distance, squared
    const double dx = x_[a] - x_[b], dy = y_[a] - y_[b];
    return dx * dx + dy * dy;
  }

  // The members' positions at time t, bucketed in a grid of about one member per cell.
  void Bucket(Eigen::Index t) {
    double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    for (int a = 0; a < m_; ++a) {
      x_[a] = rest_(members_(a, t), 0), y_[a] = rest_(members_(a, t), 1);
      Require(std::isfinite(x_[a]) && std::isfinite(y_[a]), "GroupMeshTerms", "rest positions must be finite");
      x0 = std::min(x0, x_[a]), x1 = std::max(x1, x_[a]), y0 = std::min(y0, y_[a]), y1 = std::max(y1, y_[a]);
    }
    const double extent = std::max(x1 - x0, y1 - y0);
    h_ = extent > 0 ? std::max(extent / std::ceil(std::sqrt(static_cast<double>(m_))), extent * 1e-6) : 1.0;
    nx_ = static_cast<int>((x1 - x0) / h_) + 1, ny_ = static_cast<int>((y1 - y0) / h_) + 1;
    start_.assign(static_cast<size_t>(nx_) * ny_ + 1, 0);
    for (int a = 0; a < m_; ++a) {
      const int cx = std::min(static_cast<int>((x_[a] - x0) / h_), nx_ - 1);
      const int cy = std::min(static_cast<int>((y_[a] - y0) / h_), ny_ - 1);
      cell_of_[a] = cy * nx_ + cx;
      ++start_[cell_of_[a] + 1];
    }
    for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    std::vector<int> next(start_.begin(), start_.end() - 1);
    for (int a = 0; a < m_; ++a) items_[next[cell_of_[a]]++] = a;
  }

  // visit(b) for the members b != a met ring by ring around a's cell, until the next ring
  // is farther than bound() (a squared distance). Members outside the rings so far are at
  // least (ring - 1) cells away along x or y. (Margins: the cells are found in rounded
  // arithmetic, and every member at the bound itself must be met, for the ties.)
  template <typename Bound, typename Visit>
  void Search(int a, Bound&& bound, Visit&& visit) const {
    const int ax = cell_of_[a] % nx_, ay = cell_of_[a] / nx_;
    const auto cell = [&](int cx, int cy) {
      const int c = cy * nx_ + cx;
      for (int i = start_[c]; i < start_[c + 1]; ++i)
        if (items_[i] != a) visit(items_[i]);
    };
    for (int ring = 0;; ++ring) {
      const double reach = (ring - 1) * h_ * (1 - 1e-9);
      if (ring > 0 && reach > 0 && reach * reach > bound() * (1 + 1e-13)) return;
      if (ax - ring < 0 && ay - ring < 0 && ax + ring >= nx_ && ay + ring >= ny_) return;
      for (int cy = std::max(ay - ring, 0); cy <= std::min(ay + ring, ny_ - 1); ++cy) {
        if (cy == ay - ring || cy == ay + ring) {
          for (int cx = std::max(ax - ring, 0); cx <= std::min(ax + ring, nx_ - 1); ++cx) cell(cx, cy);
        } else {
          if (ax - ring >= 0) cell(ax - ring, cy);
          if (ax + ring < nx_) cell(ax + ring, cy);
        }
      }
    }
  }

  void Join(int a, int b) {
    const uint64_t va = static_cast<uint32_t>(members_(a, now_)), vb = static_cast<uint32_t>(members_(b, now_));
    pairs_.push_back(std::min(va, vb) << 32 | std::max(va, vb));
    joined_.Unite(a, b);
  }

  // Each member to its `neighbours` nearest.
  void JoinNearest() {
    for (int a = 0; a < m_; ++a) {
      // The k+1 smallest squared distances, ties to the earlier member...
      int count = 0;
      met_.clear();
      Search(
          a, [&] { return count == keep_ ? near_[keep_ - 1].first : std::numeric_limits<double>::infinity(); },
          [&](int b) {
            const std::pair<double, int> e{Squared(a, b), b};
            met_.push_back(e);
            if (count == keep_ && !(e < near_[count - 1])) return;
            int at = count < keep_ ? count++ : count - 1;
            for (; at > 0 && e < near_[at - 1]; --at) near_[at] = near_[at - 1];
            near_[at] = e;
          });
      // ... and the k nearest as a stable sort of the distances themselves would rank them:
      // two squared distances may differ and their square roots not, so when the next one
      // is that close to the k-th, every member whose distance may equal the k-th is
      // ranked by (distance, member).
      const double bound = near_[neighbours_ - 1].first * (1 + 1e-14);
      close_.assign(near_.begin(), near_.begin() + neighbours_);
      if (count > neighbours_ && near_[neighbours_].first <= bound) {
        close_.clear();
        for (const auto& [sq, b] : met_)
          if (sq <= bound) close_.emplace_back(std::sqrt(sq), b);
        std::partial_sort(close_.begin(), close_.begin() + neighbours_, close_.end());
      }
      for (int k = 0; k < neighbours_; ++k) Join(a, close_[k].second);
    }
  }

  // Each member's cluster (the union-find's name of it) and the members listed by cluster.
  // Returns the number of clusters.
  int ListClusters() {
    int clusters = 0;
    std::fill(first_.begin(), first_.end(), 0);
    for (int a = 0; a < m_; ++a) {
      cluster_[a] = joined_.Find(a);
      clusters += cluster_[a] == a;
      ++first_[cluster_[a] + 1];
    }
    if (clusters <= 1) return clusters;
    for (int r = 0; r < m_; ++r) first_[r + 1] += first_[r];
    std::vector<int> next(first_.begin(), first_.end() - 1);
    for (int a = 0; a < m_; ++a) listed_[next[cluster_[a]]++] = a;
    return clusters;
  }

  // The cluster pairs to join, as (smaller, larger), once each: each cluster with its
  // nearest other cluster. Each member looks, ring by ring, for the nearest member of
  // another cluster, no farther than the best its cluster has found.
  std::vector<std::pair<int, int>> NearestClusters() {
    best_.assign(static_cast<size_t>(m_), {std::numeric_limits<double>::infinity(), -1, -1});
    for (int a = 0; a < m_; ++a) {
      std::array<double, 3>& mine = best_[cluster_[a]];
      Search(
          a, [&] { return mine[0]; },
          [&](int b) {
            if (cluster_[b] == cluster_[a]) return;
            const int lo = std::min(a, b), hi = std::max(a, b);
            const std::array<double, 3> e{Squared(lo, hi), static_cast<double>(lo), static_cast<double>(hi)};
            if (e < mine) mine = e;
            if (e < best_[cluster_[b]]) best_[cluster_[b]] = e;
          });
    }
    std::vector<std::pair<int, int>> joins;
    for (int r = 0; r < m_; ++r)
      if (best_[r][1] >= 0) {
        const int ra = cluster_[static_cast<int>(best_[r][1])], rb = cluster_[static_cast<int>(best_[r][2])];
        joins.emplace_back(std::min(ra, rb), std::max(ra, rb));
      }
    std::sort(joins.begin(), joins.end());
    joins.erase(std::unique(joins.begin(), joins.end()), joins.end());
    return joins;
  }

  // Nearest neighbours can keep to separate clusters (a group walking as two blocks apart),
  // each of which would then be free to move on its own. Each round finds every cluster's
  // nearest other cluster (Boruvka; pairs ranked by squared distance, then member) and
  // joins the two by their `neighbours` nearest pairs, so that each holds the other as
  // firmly as a member holds its neighbours; until one cluster is left. Only groups in
  // pieces pay this search.
  void JoinClusters() {
    std::vector<std::array<double, 3>> chosen, across;
    while (ListClusters() > 1) {
      chosen.clear();
      for (const auto& [r1, r2] : NearestClusters()) {
        across.clear();
        for (int i = first_[r1]; i < first_[r1 + 1]; ++i)
          for (int j = first_[r2]; j < first_[r2 + 1]; ++j) {
            const int lo = std::min(listed_[i], listed_[j]), hi = std::max(listed_[i], listed_[j]);
            across.push_back({Squared(lo, hi), static_cast<double>(lo), static_cast<double>(hi)});
          }
        const size_t take = std::min(across.size(), static_cast<size_t>(neighbours_));
        std::partial_sort(across.begin(), across.begin() + static_cast<std::ptrdiff_t>(take), across.end());
        chosen.insert(chosen.end(), across.begin(), across.begin() + static_cast<std::ptrdiff_t>(take));
      }
      for (const auto& e : chosen) Join(static_cast<int>(e[1]), static_cast<int>(e[2]));
    }
  }

  const Eigen::Ref<const Trajectory2>& rest_;
  const Eigen::Ref<const IntGrid>& members_;
  const int neighbours_, keep_, m_;
  std::vector<uint64_t>& pairs_;
  // Positions at the time being joined, and their grid.
  std::vector<double> x_, y_;
  std::vector<int> cell_of_, start_, items_;
  int nx_ = 0, ny_ = 0;
  double h_ = 1.0;
  // The members joined so far at the time being joined.
  detail::UnionFind joined_;
  Eigen::Index now_ = 0;
  std::vector<std::pair<double, int>> near_, close_, met_;
  std::vector<std::array<double, 3>> best_;  // per cluster: squared distance, a, b
  std::vector<int> cluster_, first_, listed_;
};

// Sorted and unique: bucketed by first vertex (vertex indices are below n), each bucket (a
// few pairs) sorted on its own.
void SortUnique(Eigen::Index n, std::vector<uint64_t>& pairs) {
  std::vector<int> first(static_cast<size_t>(n) + 1, 0);
  for (const uint64_t pair : pairs) ++first[(pair >> 32) + 1];
  for (Eigen::Index v = 0; v < n; ++v) first[v + 1] += first[v];
  std::vector<uint64_t> sorted(pairs.size());
  std::vector<int> next(first.begin(), first.end() - 1);
  for (const uint64_t pair : pairs) sorted[next[pair >> 32]++] = pair;
  pairs.clear();
  for (Eigen::Index v = 0; v < n; ++v) {
    const auto begin = sorted.begin() + first[v], end = sorted.begin() + first[v + 1];
    std::sort(begin, end);
    std::unique_copy(begin, end, std::back_inserter(pairs));
  }
}

}  // namespace

void GroupMeshTerms(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const IntGrid>& members,
                    int neighbours, const Eigen::Ref<const Eigen::VectorXi>& partner, IndexTriples& triangles,
                    IndexPairs& edges) {
  const Eigen::Index m = members.rows(), times = members.cols(), n = rest.rows();
  Require(partner.size() == n, "GroupMeshTerms", "one partner per vertex is needed");
  Require(neighbours >= 0 && (m == 0 || neighbours < m), "GroupMeshTerms",
          "neighbours must be at least 0 and less than the member count");
  Require(members.size() == 0 || (members.minCoeff() >= 0 && members.maxCoeff() < n), "GroupMeshTerms",
          "member vertex out of range");
  for (Eigen::Index v = 0; v < n; ++v)
    Require(partner[v] >= -1 && partner[v] < n, "GroupMeshTerms", "partner out of range");

  // The sampled times are independent: large groups split them between two threads (the
  // pairs are sorted below, so the result does not depend on the split).
  std::vector<uint64_t> pairs;
  if (times >= 2 && m * times >= kParallelMemberSamples) {
    std::vector<uint64_t> later;
    OnTwoThreads([&] { MeshJoiner(rest, members, neighbours, pairs).Run(0, times / 2); },
                 [&] { MeshJoiner(rest, members, neighbours, later).Run(times / 2, times); });
    pairs.insert(pairs.end(), later.begin(), later.end());
  } else {
    MeshJoiner(rest, members, neighbours, pairs).Run(0, times);
  }
  SortUnique(n, pairs);

  edges.resize(static_cast<Eigen::Index>(pairs.size()), 2);
  for (size_t e = 0; e < pairs.size(); ++e)
    edges.row(static_cast<Eigen::Index>(e)) << static_cast<int>(pairs[e] >> 32),
        static_cast<int>(pairs[e] & 0xffffffffu);
  std::vector<std::array<int, 3>> tri;
  tri.reserve(2 * pairs.size());
  for (int side = 0; side < 2; ++side)
    for (const uint64_t pair : pairs) {
      const int a = static_cast<int>(pair >> 32), b = static_cast<int>(pair & 0xffffffffu);
      const int v = side == 0 ? a : b, w = side == 0 ? b : a;
      if (partner[w] >= 0 && Distance(rest, v, w) > 0) tri.push_back({v, w, partner[w]});
    }
  triangles.resize(static_cast<Eigen::Index>(tri.size()), 3);
  for (size_t k = 0; k < tri.size(); ++k)
    triangles.row(static_cast<Eigen::Index>(k)) << tri[k][0], tri[k][1], tri[k][2];
}

}  // namespace mocapedit
