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

// Heading sets of at least this many frames are computed on two threads.
constexpr Eigen::Index kParallelHeadingFrames = 20000;

void BlockDeformationTurns(const Eigen::Ref<const Trajectory2>& source, const Eigen::Ref<const Trajectory2>& edited,
                           const Eigen::Ref<const IndexPairs>& blocks, const Eigen::Ref<const IndexTriples>& fixed,
                           const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window, double min_travel,
                           double max_step, const Eigen::Ref<const Eigen::VectorXi>& keep_spot, Eigen::VectorXd& turns) {
  Require(fixed.rows() == fixed_turn.size(), "BlockDeformationTurns", "one turn is needed per fixed range");
  Require(keep_spot.size() == 0 || keep_spot.size() == blocks.rows(), "BlockDeformationTurns",
          "keep_spot needs one flag per block, or none");
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
                           fixed_turn.segment(lo, hi - lo), window, min_travel, max_step,
                           keep_spot.size() == 0 || keep_spot[b] != 0);
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

// The rows as sorted sparse vectors, repeated positions summed, each column scaled to unit
// largest magnitude; `holders`: per column, the rows that may hold it.
std::vector<SparseRow> ScaledRows(const Eigen::Ref<const Eigen::VectorXi>& rows,
                                  const Eigen::Ref<const Eigen::VectorXi>& cols,
                                  const Eigen::Ref<const Eigen::VectorXcd>& values, int num_rows, int num_cols,
                                  std::vector<std::vector<int>>& holders) {
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
  holders.assign(static_cast<size_t>(num_cols), {});
  for (int r = 0; r < num_rows; ++r)
    for (auto& [c, v] : a[r]) {
      if (scale[c] > 0) v /= scale[c];
      holders[c].push_back(r);
    }
  return a;
}

// Row echelon form of the scaled rows, column by column, with partial pivoting among the
// rows that hold the column; pivots of magnitude <= tolerance leave their column free
// (pivot row -1). Returns each column's pivot row.
std::vector<int> EchelonForm(std::vector<SparseRow>& a, std::vector<std::vector<int>>& holders, int num_cols,
                             double tolerance) {
  const int num_rows = static_cast<int>(a.size());
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
  return pivot_row;
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
  std::vector<std::vector<int>> holders;
  std::vector<SparseRow> a = ScaledRows(rows, cols, values, num_rows, num_cols, holders);
  const std::vector<int> pivot_row = EchelonForm(a, holders, num_cols, tolerance);

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
