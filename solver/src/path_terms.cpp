#include "mocapedit/path_terms.h"
#include "mocapedit/errors.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mocapedit/two_threads.h"
#include "union_find.h"

namespace mocapedit {

namespace {

using detail::Require;

void CheckOffsets(const Eigen::Ref<const Eigen::VectorXi>& offsets, Eigen::Index total, const char* what) {
  Require(offsets.size() >= 1 && offsets[0] == 0 && offsets[offsets.size() - 1] == total, what,
                  "offsets must start at 0 and end at " + std::to_string(total));
  for (Eigen::Index a = 1; a < offsets.size(); ++a)
    Require(offsets[a] >= offsets[a - 1], what, "offsets must not decrease");
}

// Distance as numpy's norm computes it (sqrt of the summed squares), so that ties and
// thresholds decide exactly as the reference implementation does.
double Distance(const Eigen::Ref<const Trajectory2>& p, Eigen::Index a, Eigen::Index b) {
  const double dx = p(a, 0) - p(b, 0), dy = p(a, 1) - p(b, 1);
  return std::sqrt(dx * dx + dy * dy);
}

}  // namespace

void ComponentChainTerms(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
                         double min_baseline, IndexTriples& triangles, IndexPairs& edges) {
  CheckOffsets(offsets, rest.rows(), "ComponentChainTerms");
  // Each agent's terms on their own, then one copy: appending to the whole list would
  // reallocate it once per agent.
  const Eigen::Index agents = offsets.size() - 1;
  std::vector<IndexTriples> tri(static_cast<size_t>(agents), IndexTriples(0, 3));
  std::vector<IndexPairs> edg(static_cast<size_t>(agents), IndexPairs(0, 2));
  Eigen::Index t = 0, e = 0;
  for (Eigen::Index a = 0; a < agents; ++a) {
    AppendChainTerms(rest, offsets[a], offsets[a + 1] - offsets[a], min_baseline, tri[a], edg[a]);
    t += tri[a].rows(), e += edg[a].rows();
  }
  triangles.resize(t, 3);
  edges.resize(e, 2);
  t = e = 0;
  for (Eigen::Index a = 0; a < agents; ++a) {
    triangles.middleRows(t, tri[a].rows()) = tri[a];
    edges.middleRows(e, edg[a].rows()) = edg[a];
    t += tri[a].rows(), e += edg[a].rows();
  }
}

void KeyFrames(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
               const Eigen::Ref<const Eigen::VectorXi>& keyed, const Eigen::Ref<const Eigen::VectorXi>& forced,
               double min_baseline, Eigen::VectorXi& keys, Eigen::VectorXi& before) {
  const Eigen::Index n = rest.rows();
  CheckOffsets(offsets, n, "KeyFrames");
  Require(keyed.size() == offsets.size() - 1, "KeyFrames", "one keyed flag per agent is needed");
  std::vector<char> key(static_cast<size_t>(n), 0);
  for (Eigen::Index a = 0; a < keyed.size(); ++a)
    if (!keyed[a]) std::fill(key.begin() + offsets[a], key.begin() + offsets[a + 1], 1);
  for (Eigen::Index i = 0; i < forced.size(); ++i) {
    Require(forced[i] >= 0 && forced[i] < n, "KeyFrames", "forced frame out of range");
    key[forced[i]] = 1;
  }
  // Keys of one agent closer than min_baseline: every frame between them is a key too
  // (decided on the keys given, not on those this adds).
  for (Eigen::Index a = 0; a < keyed.size(); ++a) {
    if (!keyed[a]) continue;
    int last = -1;
    for (int f = offsets[a]; f < offsets[a + 1]; ++f) {
      if (!key[f]) continue;
      if (last >= 0 && f > last + 1 && Distance(rest, last, f) < min_baseline)
        std::fill(key.begin() + last + 1, key.begin() + f, 2);
      last = f;
    }
  }
  before.resize(n);
  int count = 0;
  for (Eigen::Index f = 0; f < n; ++f) {
    before[f] = count;
    count += key[f] != 0;
  }
  keys.resize(count);
  for (Eigen::Index f = 0, k = 0; f < n; ++f)
    if (key[f]) keys[k++] = static_cast<int>(f);
}

void ExpandKeyFrames(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& keys,
                     const Eigen::Ref<const Trajectory2>& positions, Trajectory2& out) {
  const Eigen::Index n = rest.rows(), k = keys.size();
  Require(positions.rows() == k, "ExpandKeyFrames", "one position per key is needed");
  Require(n == 0 || (k >= 1 && keys[0] == 0 && keys[k - 1] == n - 1), "ExpandKeyFrames",
                  "the first and last frames must be keys");
  out.resize(n, 2);
  using Cplx = std::complex<double>;
  const auto z = [&](int f) { return Cplx(rest(f, 0), rest(f, 1)); };
  const auto x = [&](Eigen::Index j) { return Cplx(positions(j, 0), positions(j, 1)); };
  // The multiplier of each interval (keys j-1, j) with frames between its keys.
  std::vector<Cplx> m(static_cast<size_t>(k));
  std::vector<char> smooth(static_cast<size_t>(k), 0);
  for (Eigen::Index j = 0; j < k; ++j) {
    Require(j == 0 || keys[j] > keys[j - 1], "ExpandKeyFrames", "keys must increase");
    out.row(keys[j]) = positions.row(j);
    if (j == 0 || keys[j] == keys[j - 1] + 1) continue;
    const Cplx dz = z(keys[j]) - z(keys[j - 1]);
    if (dz == Cplx(0.0)) continue;
    m[j] = (x(j) - x(j - 1)) / dz;
    smooth[j] = 1;
  }
  for (Eigen::Index j = 1; j < k; ++j) {
    const int f0 = keys[j - 1], f1 = keys[j];
    if (f1 == f0 + 1) continue;
    const Cplx x0 = x(j - 1), x1 = x(j), z0 = z(f0), z1 = z(f1);
    const bool prev = j >= 2 && smooth[j - 1], next = j + 1 < k && smooth[j + 1];
    for (int f = f0 + 1; f < f1; ++f) {
      const double t = static_cast<double>(f - f0) / (f1 - f0);
      Cplx p;
      if (!smooth[j]) {  // keys at one rest position: the frames between move in time
        p = x0 + t * (x1 - x0);
      } else {
        p = x0 + (z(f) - z0) * m[j];
        // S_prev(z) - S(z) = (z - z0)(m_prev - m); S_next(z) - S(z) = (z - z1)(m_next - m).
        if (prev) p += 0.5 * (1 - t) * (1 - t) * (z(f) - z0) * (m[j - 1] - m[j]);
        if (next) p += 0.5 * t * t * (z(f) - z1) * (m[j + 1] - m[j]);
      }
      out(f, 0) = p.real(), out(f, 1) = p.imag();
    }
  }
}

void GroupSampleFrames(const Eigen::Ref<const Eigen::VectorXd>& sample_times,
                       const Eigen::Ref<const Eigen::VectorXi>& offsets, const Eigen::Ref<const Eigen::VectorXd>& times,
                       Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& frames) {
  CheckOffsets(offsets, sample_times.size(), "GroupSampleFrames");
  const Eigen::Index members = offsets.size() - 1;
  frames.resize(members, times.size());
  for (Eigen::Index m = 0; m < members; ++m) {
    const double* first = sample_times.data() + offsets[m];
    const double* last = sample_times.data() + offsets[m + 1];
    Require(last > first, "GroupSampleFrames", "member " + std::to_string(m) + " has no frame");
    const Eigen::Index count = last - first;
    for (Eigen::Index t = 0; t < times.size(); ++t) {
      const Eigen::Index f =
          std::min<Eigen::Index>(std::lower_bound(first, last, times[t] - 1e-9) - first, count - 1);
      frames(m, t) = std::abs(first[f] - times[t]) < 1e-6 ? static_cast<int>(f) : -1;
    }
  }
}

void FramePartners(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
                   double min_baseline, Eigen::VectorXi& partner) {
  CheckOffsets(offsets, rest.rows(), "FramePartners");
  partner.setConstant(rest.rows(), -1);
  for (Eigen::Index a = 0; a + 1 < offsets.size(); ++a) {
    const int lo = offsets[a], count = offsets[a + 1] - offsets[a];
    if (count == 0) continue;
    const auto block = rest.middleRows(lo, count);
    const Eigen::VectorXd arc = CumulativeArcLength(block);
    const double* begin = arc.data();
    const double* end = arc.data() + count;
    for (int i = 0; i < count; ++i) {
      const std::array<Eigen::Index, 2> candidates = {
          std::lower_bound(begin, end, arc[i] + min_baseline) - begin,   // the nearest later frame
          std::upper_bound(begin, end, arc[i] - min_baseline) - begin - 1};  // else an earlier one
      for (const Eigen::Index cand : candidates) {
        if (cand < 0 || cand >= count || cand == i) continue;
        if (Distance(block, cand, i) >= min_baseline) {
          partner[lo + i] = lo + static_cast<int>(cand);
          break;
        }
      }
    }
  }
}

// Groups with at least this many member samples (members x sampled times) find their
// neighbours on two threads.
constexpr Eigen::Index kParallelMemberSamples = 2000;
// Heading sets of at least this many frames are computed on two threads.
constexpr Eigen::Index kParallelHeadingFrames = 20000;

void GroupMeshTerms(const Eigen::Ref<const Trajectory2>& rest,
                    const Eigen::Ref<const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& members,
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

  // Pairs packed as (min << 32 | max): sorting integers is cheaper than sorting pairs. The
  // sampled times are independent: large groups split them between two threads (the pairs
  // are sorted below, so the result does not depend on the split).
  const auto pairs_at = [&](Eigen::Index t_begin, Eigen::Index t_end, std::vector<uint64_t>& pairs) {
    pairs.reserve(static_cast<size_t>(m * (t_end - t_begin) * neighbours));
    std::vector<double> x(static_cast<size_t>(m)), y(static_cast<size_t>(m));
    const auto squared = [&](int a, int b) {  // as Distance, squared
      const double dx = x[a] - x[b], dy = y[a] - y[b];
      return dx * dx + dy * dy;
    };
    // Members bucketed in a grid of about one member per cell (rebuilt at each time).
    std::vector<int> cell_of(static_cast<size_t>(m)), start, items(static_cast<size_t>(m));
    int nx = 0, ny = 0;
    double h = 1.0;
    // visit(b) for the members b != a met ring by ring around a's cell, until the next ring
    // is farther than bound() (a squared distance). Members outside the rings so far are at
    // least (ring - 1) cells away along x or y. (Margins: the cells are found in rounded
    // arithmetic, and every member at the bound itself must be met, for the ties.)
    const auto search = [&](int a, auto&& bound, auto&& visit) {
      const int ax = cell_of[a] % nx, ay = cell_of[a] / nx;
      const auto cell = [&](int cx, int cy) {
        const int c = cy * nx + cx;
        for (int i = start[c]; i < start[c + 1]; ++i)
          if (items[i] != a) visit(items[i]);
      };
      for (int ring = 0;; ++ring) {
        const double reach = (ring - 1) * h * (1 - 1e-9);
        if (ring > 0 && reach > 0 && reach * reach > bound() * (1 + 1e-13)) return;
        if (ax - ring < 0 && ay - ring < 0 && ax + ring >= nx && ay + ring >= ny) return;
        for (int cy = std::max(ay - ring, 0); cy <= std::min(ay + ring, ny - 1); ++cy) {
          if (cy == ay - ring || cy == ay + ring) {
            for (int cx = std::max(ax - ring, 0); cx <= std::min(ax + ring, nx - 1); ++cx) cell(cx, cy);
          } else {
            if (ax - ring >= 0) cell(ax - ring, cy);
            if (ax + ring < nx) cell(ax + ring, cy);
          }
        }
      }
    };
    // The members joined so far at the time being joined.
    detail::UnionFind joined;
    Eigen::Index now = 0;
    const auto join = [&](int a, int b) {
      const uint64_t va = static_cast<uint32_t>(members(a, now)), vb = static_cast<uint32_t>(members(b, now));
      pairs.push_back(std::min(va, vb) << 32 | std::max(va, vb));
      joined.Unite(a, b);
    };
    const int keep = neighbours + 1;
    std::vector<std::pair<double, int>> near(static_cast<size_t>(keep)), close, met;
    // Each member to its `neighbours` nearest.
    const auto join_nearest = [&] {
      for (int a = 0; a < m; ++a) {
        // The k+1 smallest squared distances, ties to the earlier member...
        int count = 0;
        met.clear();
        search(
            a, [&] { return count == keep ? near[keep - 1].first : std::numeric_limits<double>::infinity(); },
            [&](int b) {
              const std::pair<double, int> e{squared(a, b), b};
              met.push_back(e);
              if (count == keep && !(e < near[count - 1])) return;
              int at = count < keep ? count++ : count - 1;
              for (; at > 0 && e < near[at - 1]; --at) near[at] = near[at - 1];
              near[at] = e;
            });
        // ... and the k nearest as a stable sort of the distances themselves would rank them:
        // two squared distances may differ and their square roots not, so when the next one
        // is that close to the k-th, every member whose distance may equal the k-th is
        // ranked by (distance, member).
        const double bound = near[neighbours - 1].first * (1 + 1e-14);
        close.assign(near.begin(), near.begin() + neighbours);
        if (count > neighbours && near[neighbours].first <= bound) {
          close.clear();
          for (const auto& [sq, b] : met)
            if (sq <= bound) close.emplace_back(std::sqrt(sq), b);
          std::partial_sort(close.begin(), close.begin() + neighbours, close.end());
        }
        for (int k = 0; k < neighbours; ++k) join(a, close[k].second);
      }
    };
    // Nearest neighbours can keep to separate clusters (a group walking as two blocks apart),
    // each of which would then be free to move on its own. Each round finds every cluster's
    // nearest other cluster (Boruvka; pairs ranked by squared distance, then member) and
    // joins the two by their `neighbours` nearest pairs, so that each holds the other as
    // firmly as a member holds its neighbours; until one cluster is left. Only groups in
    // pieces pay this search: each member looks, ring by ring, for the nearest member of
    // another cluster, no farther than the best its cluster has found. 1,000 members, 20
    // sampled times: 6 ms in a block (one piece), 19 ms at random, 59 ms in clumps of five
    // far apart.
    std::vector<std::array<double, 3>> best;  // per cluster: squared distance, a, b
    std::vector<int> cluster(static_cast<size_t>(m)), first(static_cast<size_t>(m) + 1), listed(static_cast<size_t>(m));
    const auto join_clusters = [&] {
      for (;;) {
        int clusters = 0;
        std::fill(first.begin(), first.end(), 0);
        for (int a = 0; a < m; ++a) {
          cluster[a] = joined.Find(a);
          clusters += cluster[a] == a;
          ++first[cluster[a] + 1];
        }
        if (clusters <= 1) return;
        // Each cluster's members, listed by cluster.
        for (int r = 0; r < m; ++r) first[r + 1] += first[r];
        {
          std::vector<int> next(first.begin(), first.end() - 1);
          for (int a = 0; a < m; ++a) listed[next[cluster[a]]++] = a;
        }
        best.assign(static_cast<size_t>(m), {std::numeric_limits<double>::infinity(), -1, -1});
        for (int a = 0; a < m; ++a) {
          std::array<double, 3>& mine = best[cluster[a]];
          search(
              a, [&] { return mine[0]; },
              [&](int b) {
                if (cluster[b] == cluster[a]) return;
                const int lo = std::min(a, b), hi = std::max(a, b);
                const std::array<double, 3> e{squared(lo, hi), static_cast<double>(lo), static_cast<double>(hi)};
                if (e < mine) mine = e;
                if (e < best[cluster[b]]) best[cluster[b]] = e;
              });
        }
        // The cluster pairs to join, as (smaller, larger), once each, and the member pairs
        // across each.
        std::vector<std::pair<int, int>> joins;
        for (int r = 0; r < m; ++r)
          if (best[r][1] >= 0) {
            const int ra = cluster[static_cast<int>(best[r][1])], rb = cluster[static_cast<int>(best[r][2])];
            joins.emplace_back(std::min(ra, rb), std::max(ra, rb));
          }
        std::sort(joins.begin(), joins.end());
        joins.erase(std::unique(joins.begin(), joins.end()), joins.end());
        std::vector<std::array<double, 3>> chosen, across;
        for (const auto& [r1, r2] : joins) {
          across.clear();
          for (int i = first[r1]; i < first[r1 + 1]; ++i)
            for (int j = first[r2]; j < first[r2 + 1]; ++j) {
              const int lo = std::min(listed[i], listed[j]), hi = std::max(listed[i], listed[j]);
              across.push_back({squared(lo, hi), static_cast<double>(lo), static_cast<double>(hi)});
            }
          const size_t take = std::min(across.size(), static_cast<size_t>(neighbours));
          std::partial_sort(across.begin(), across.begin() + static_cast<std::ptrdiff_t>(take), across.end());
          chosen.insert(chosen.end(), across.begin(), across.begin() + static_cast<std::ptrdiff_t>(take));
        }
        for (const auto& e : chosen) join(static_cast<int>(e[1]), static_cast<int>(e[2]));
      }
    };
    for (Eigen::Index t = t_begin; t < t_end && neighbours > 0; ++t) {
      now = t;
      joined.Reset(static_cast<int>(m));
      double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
      for (Eigen::Index a = 0; a < m; ++a) {
        x[a] = rest(members(a, t), 0), y[a] = rest(members(a, t), 1);
        Require(std::isfinite(x[a]) && std::isfinite(y[a]), "GroupMeshTerms", "rest positions must be finite");
        x0 = std::min(x0, x[a]), x1 = std::max(x1, x[a]), y0 = std::min(y0, y[a]), y1 = std::max(y1, y[a]);
      }
      const double extent = std::max(x1 - x0, y1 - y0);
      h = extent > 0 ? std::max(extent / std::ceil(std::sqrt(static_cast<double>(m))), extent * 1e-6) : 1.0;
      nx = static_cast<int>((x1 - x0) / h) + 1, ny = static_cast<int>((y1 - y0) / h) + 1;
      start.assign(static_cast<size_t>(nx) * ny + 1, 0);
      for (int a = 0; a < m; ++a) {
        const int cx = std::min(static_cast<int>((x[a] - x0) / h), nx - 1);
        const int cy = std::min(static_cast<int>((y[a] - y0) / h), ny - 1);
        cell_of[a] = cy * nx + cx;
        ++start[cell_of[a] + 1];
      }
      for (size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
      {
        std::vector<int> next(start.begin(), start.end() - 1);
        for (int a = 0; a < m; ++a) items[next[cell_of[a]]++] = a;
      }
      join_nearest();
      join_clusters();
    }
  };
  std::vector<uint64_t> pairs;
  if (times >= 2 && m * times >= kParallelMemberSamples) {
    std::vector<uint64_t> later;
    OnTwoThreads([&] { pairs_at(0, times / 2, pairs); }, [&] { pairs_at(times / 2, times, later); });
    pairs.insert(pairs.end(), later.begin(), later.end());
  } else {
    pairs_at(0, times, pairs);
  }
  // Sorted and unique: bucketed by first vertex (vertex indices are bounded), each bucket
  // (a few pairs) sorted on its own.
  {
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

  edges.resize(static_cast<Eigen::Index>(pairs.size()), 2);
  for (size_t e = 0; e < pairs.size(); ++e)
    edges.row(static_cast<Eigen::Index>(e)) << static_cast<int>(pairs[e] >> 32), static_cast<int>(pairs[e] & 0xffffffffu);
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

void BlockDeformationTurns(const Eigen::Ref<const Trajectory2>& source, const Eigen::Ref<const Trajectory2>& edited,
                           const Eigen::Ref<const IndexPairs>& blocks, const Eigen::Ref<const IndexTriples>& fixed,
                           const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window, double min_travel,
                           Eigen::VectorXd& turns) {
  Require(fixed.rows() == fixed_turn.size(), "BlockDeformationTurns", "one turn is needed per fixed range");
  Require(source.rows() == edited.rows(), "BlockDeformationTurns", "source and edited differ in rows");
  turns.setZero(source.rows());
  // Each block's first fixed range; the blocks are independent.
  const Eigen::Index count = blocks.rows();
  std::vector<Eigen::Index> first_range(static_cast<size_t>(count) + 1);
  Eigen::Index r = 0, frames = 0;
  bool disjoint = true;  // in order, each after the last: the threads below write apart
  for (Eigen::Index b = 0; b < count; ++b) {
    const int begin = blocks(b, 0), end = blocks(b, 1);
    Require(0 <= begin && begin <= end && end <= source.rows(), "BlockDeformationTurns", "block out of range");
    if (b > 0 && begin < blocks(b - 1, 1)) disjoint = false;
    first_range[b] = r;
    while (r < fixed.rows() && fixed(r, 0) == b) ++r;
    frames += end - begin;
  }
  first_range[count] = r;
  Require(r == fixed.rows(), "BlockDeformationTurns", "fixed ranges must be grouped by block, in block order");
  const auto turn = [&](Eigen::Index b0, Eigen::Index b1) {
    std::vector<FrameRange> ranges;
    for (Eigen::Index b = b0; b < b1; ++b) {
      const int begin = blocks(b, 0), end = blocks(b, 1);
      const Eigen::Index lo = first_range[b], hi = first_range[b + 1];
      ranges.clear();
      for (Eigen::Index k = lo; k < hi; ++k) ranges.emplace_back(fixed(k, 1), fixed(k, 2));
      turns.segment(begin, end - begin) =
          DeformationTurns(source.middleRows(begin, end - begin), edited.middleRows(begin, end - begin), ranges,
                           fixed_turn.segment(lo, hi - lo), window, min_travel);
    }
  };
  if (count < 2 || frames < kParallelHeadingFrames || !disjoint) {
    turn(0, count);
    return;
  }
  // Large sets on two threads, split at half of the frames.
  Eigen::Index split = 0;
  for (Eigen::Index seen = 0; split < count && 2 * seen < frames; ++split) seen += blocks(split, 1) - blocks(split, 0);
  OnTwoThreads([&] { turn(0, split); }, [&] { turn(split, count); });
}

namespace {

using Complex = std::complex<double>;
using SparseRow = std::vector<std::pair<int, Complex>>;  // sorted by column

const Complex* Find(const SparseRow& row, int col) {
  const auto it = std::lower_bound(row.begin(), row.end(), col, [](const auto& e, int c) { return e.first < c; });
  return it != row.end() && it->first == col ? &it->second : nullptr;
}

// Unit-magnitude pseudo-random value k of sequence `stream` (splitmix64; deterministic).
Complex Phase(uint64_t stream, uint64_t k) {
  uint64_t z = stream * 0x9E3779B97F4A7C15ull + k + 1;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return std::polar(1.0, 2.0 * M_PI * static_cast<double>(z >> 11) * 0x1.0p-53);
}

}  // namespace

std::vector<char> NullSpaceSupport(const Eigen::Ref<const Eigen::VectorXi>& rows,
                                   const Eigen::Ref<const Eigen::VectorXi>& cols,
                                   const Eigen::Ref<const Eigen::VectorXcd>& values, int num_rows, int num_cols,
                                   double tolerance) {
  Require(num_rows >= 0 && num_cols >= 0, "NullSpaceSupport", "negative size");
  Require(rows.size() == cols.size() && rows.size() == values.size(), "NullSpaceSupport",
                  "rows, cols and values must have one entry each");
  Require(tolerance > 0 && std::isfinite(tolerance), "NullSpaceSupport", "tolerance must be finite and > 0");
  std::vector<char> used(static_cast<size_t>(num_cols), 1);
  if (num_rows == 0) return used;

  // Rows as sorted sparse vectors, repeated positions summed; columns scaled to unit max.
  std::vector<std::array<int, 2>> at(static_cast<size_t>(rows.size()));
  for (Eigen::Index e = 0; e < rows.size(); ++e) {
    Require(rows[e] >= 0 && rows[e] < num_rows && cols[e] >= 0 && cols[e] < num_cols, "NullSpaceSupport",
                    "entry out of range");
    Require(std::isfinite(values[e].real()) && std::isfinite(values[e].imag()), "NullSpaceSupport",
                    "entries must be finite");
    at[static_cast<size_t>(e)] = {rows[e], cols[e]};
  }
  std::vector<int> perm(at.size());
  for (size_t e = 0; e < perm.size(); ++e) perm[e] = static_cast<int>(e);
  std::stable_sort(perm.begin(), perm.end(), [&](int x, int y) { return at[x] < at[y]; });
  std::vector<SparseRow> a(static_cast<size_t>(num_rows));
  for (const int e : perm) {
    SparseRow& row = a[static_cast<size_t>(at[e][0])];
    if (!row.empty() && row.back().first == at[e][1])
      row.back().second += values[e];
    else
      row.emplace_back(at[e][1], values[e]);
  }
  std::vector<double> scale(static_cast<size_t>(num_cols), 0.0);
  for (const auto& row : a)
    for (const auto& [c, v] : row) scale[c] = std::max(scale[c], std::abs(v));
  std::vector<std::vector<int>> holders(static_cast<size_t>(num_cols));  // rows that may hold a column
  for (int r = 0; r < num_rows; ++r)
    for (auto& [c, v] : a[r]) {
      if (scale[c] > 0) v /= scale[c];
      holders[c].push_back(r);
    }

  // Row echelon form, column by column.
  std::vector<char> active(static_cast<size_t>(num_rows), 1);
  std::vector<int> pivot_row(static_cast<size_t>(num_cols), -1);
  std::vector<int> seen(static_cast<size_t>(num_rows), -1);
  SparseRow merged;
  for (int c = 0; c < num_cols; ++c) {
    int best = -1;
    double best_abs = 0;
    std::vector<int> holding;
    for (const int r : holders[c]) {
      if (!active[r] || seen[r] == c) continue;
      seen[r] = c;
      const Complex* v = Find(a[r], c);
      if (!v || *v == Complex(0)) continue;
      holding.push_back(r);
      if (std::abs(*v) > best_abs) best_abs = std::abs(*v), best = r;
    }
    holders[c].clear();
    if (best < 0 || best_abs <= tolerance) continue;  // a free column
    pivot_row[c] = best;
    active[best] = 0;
    const SparseRow& p = a[best];
    const Complex pv = *Find(p, c);
    for (const int r : holding) {
      if (r == best) continue;
      SparseRow& row = a[r];
      const Complex f = *Find(row, c) / pv;
      merged.clear();
      size_t i = 0, j = 0;
      while (i < row.size() || j < p.size()) {
        if (j == p.size() || (i < row.size() && row[i].first < p[j].first)) {
          merged.push_back(row[i++]);
        } else if (i == row.size() || p[j].first < row[i].first) {
          merged.emplace_back(p[j].first, -f * p[j].second);
          holders[p[j].first].push_back(r);
          ++j;
        } else {
          if (row[i].first != c) merged.emplace_back(row[i].first, row[i].second - f * p[j].second);
          ++i, ++j;
        }
      }
      row.swap(merged);
    }
  }

  // Back-substitute two pseudo-random null vectors; pivot rows hold no earlier pivot column.
  std::vector<double> reach(static_cast<size_t>(num_cols), 0.0);
  std::vector<Complex> x(static_cast<size_t>(num_cols));
  for (uint64_t stream = 1; stream <= 2; ++stream) {
    for (int c = 0; c < num_cols; ++c)
      if (pivot_row[c] < 0) x[c] = Phase(stream, static_cast<uint64_t>(c));
    for (int c = num_cols - 1; c >= 0; --c) {
      if (pivot_row[c] < 0) continue;
      Complex sum = 0, pivot = 0;
      for (const auto& [j, v] : a[pivot_row[c]]) {
        if (j == c)
          pivot = v;
        else
          sum += v * x[j];
      }
      x[c] = -sum / pivot;
      reach[c] = std::max(reach[c], std::abs(x[c]));
    }
  }
  for (int c = 0; c < num_cols; ++c) used[c] = pivot_row[c] < 0 || reach[c] > tolerance;
  return used;
}

}  // namespace mocapedit
