#include "mocapedit/nested_dissection.h"
#include "mocapedit/errors.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace mocapedit {

namespace {

class Dissector {
 public:
  Dissector(int n, const int* col_ptr, const int* row_index, const double* coords, int dims, int leaf)
      : n_(n), coords_(coords), dims_(dims), leaf_(std::max(leaf, 1)) {
    // Symmetric adjacency without the diagonal, CSR.
    ptr_.assign(n + 1, 0);
    for (int j = 0; j < n; ++j)
      for (int p = col_ptr[j]; p < col_ptr[j + 1]; ++p) {
        const int i = row_index[p];
        if (i < 0 || i >= n)
          throw InvalidInput("CoordinateDissection", "row index " + std::to_string(i) + " out of range");
        if (i != j) ++ptr_[i + 1], ++ptr_[j + 1];
      }
    for (int v = 0; v < n; ++v) ptr_[v + 1] += ptr_[v];
    adj_.resize(ptr_[n]);
    std::vector<int> at(ptr_.begin(), ptr_.end() - 1);
    for (int j = 0; j < n; ++j)
      for (int p = col_ptr[j]; p < col_ptr[j + 1]; ++p) {
        const int i = row_index[p];
        if (i != j) adj_[at[i]++] = j, adj_[at[j]++] = i;
      }
    for (int k = 0; k < n * dims; ++k)
      if (!std::isfinite(coords[k]))
        throw InvalidInput("CoordinateDissection", "coordinate " + std::to_string(k % dims) + " of vertex " +
                                    std::to_string(k / dims) + " is not finite");
    side_.assign(n, kOutside);
    match_.assign(n, -1);
    seen_.assign(n, 0);
    result_.set.assign(n, -1);
  }

  Dissection Run() {
    std::vector<int> all(n_);
    for (int v = 0; v < n_; ++v) all[v] = v;
    if (n_ > 0) Dissect(all);
    return std::move(result_);
  }

 private:
  static constexpr signed char kOutside = -1;

  // Numbers a new set; returns it.
  int NewSet(const std::vector<int>& members) {
    const int s = static_cast<int>(result_.parent.size());
    result_.parent.push_back(-1);
    for (int v : members) result_.set[v] = s;
    return s;
  }

  // Splits `idx` at the median of coordinate d: side_ is 0 for the lower half, 1 for the
  // upper (by coordinate, then index, so equal coordinates still split evenly).
  void Halve(const std::vector<int>& idx, int d) {
    order_ = idx;
    const size_t mid = idx.size() / 2;
    auto less = [&](int a, int b) {
      const double ca = coords_[static_cast<size_t>(a) * dims_ + d], cb = coords_[static_cast<size_t>(b) * dims_ + d];
      return ca < cb || (ca == cb && a < b);
    };
    std::nth_element(order_.begin(), order_.begin() + static_cast<std::ptrdiff_t>(mid), order_.end(), less);
    for (size_t k = 0; k < order_.size(); ++k) side_[order_[k]] = k < mid ? 0 : 1;
  }

  // Minimum vertex cover of the edges between the two sides (Koenig: from a maximum
  // matching, the lower side's vertices not reachable by alternating paths from an
  // unmatched lower vertex, and the upper side's vertices that are).
  std::vector<int> Cover(const std::vector<int>& idx) {
    lower_.clear();
    for (int v : idx) {
      if (side_[v] != 0) continue;
      for (int p = ptr_[v]; p < ptr_[v + 1]; ++p)
        if (side_[adj_[p]] == 1) {
          lower_.push_back(v);
          break;
        }
    }
    for (int v : idx) match_[v] = -1;
    // Greedy matching, then augmenting paths (depth first, iterative).
    for (int v : lower_)
      for (int p = ptr_[v]; p < ptr_[v + 1]; ++p) {
        const int w = adj_[p];
        if (side_[w] == 1 && match_[w] < 0) {
          match_[v] = w;
          match_[w] = v;
          break;
        }
      }
    // A search that finds no augmenting path leaves its vertices unable to reach a free one
    // until the matching changes: they stay marked until an augmentation.
    ++stamp_;
    for (int root : lower_) {
      if (match_[root] >= 0) continue;
      // Stack of (lower vertex, next adjacency position).
      stack_.clear();
      stack_.emplace_back(root, ptr_[root]);
      seen_[root] = stamp_;
      bool found = false;
      while (!stack_.empty() && !found) {
        auto& [v, p] = stack_.back();
        if (p == ptr_[v + 1]) {
          stack_.pop_back();
          continue;
        }
        const int w = adj_[p++];
        if (side_[w] != 1 || seen_[w] == stamp_) continue;
        seen_[w] = stamp_;
        if (match_[w] < 0) {
          // Augment along the stack: each lower vertex takes the upper vertex it went to.
          int take = w;
          for (size_t k = stack_.size(); k-- > 0;) {
            const int u = stack_[k].first, previous = match_[u];
            match_[u] = take;
            match_[take] = u;
            take = previous;
          }
          found = true;
          ++stamp_;
        } else {
          const int u = match_[w];
          if (seen_[u] != stamp_) {
            seen_[u] = stamp_;
            stack_.emplace_back(u, ptr_[u]);
          }
        }
      }
    }
    // Alternating reach from the unmatched lower vertices.
    ++stamp_;
    queue_.clear();
    for (int v : lower_)
      if (match_[v] < 0) {
        seen_[v] = stamp_;
        queue_.push_back(v);
      }
    for (size_t head = 0; head < queue_.size(); ++head) {
      const int v = queue_[head];
      for (int p = ptr_[v]; p < ptr_[v + 1]; ++p) {
        const int w = adj_[p];
        if (side_[w] != 1 || seen_[w] == stamp_) continue;
        seen_[w] = stamp_;
        const int u = match_[w];  // matched: w is reached only through non-matching edges
        if (u >= 0 && seen_[u] != stamp_) {
          seen_[u] = stamp_;
          queue_.push_back(u);
        }
      }
    }
    std::vector<int> cover;
    for (int v : lower_) {
      if (seen_[v] != stamp_) cover.push_back(v);
      for (int p = ptr_[v]; p < ptr_[v + 1]; ++p) {
        const int w = adj_[p];
        // Each reached upper vertex once: from its partner, or from any reached neighbour.
        if (side_[w] == 1 && seen_[w] == stamp_ && match_[w] != -2) {
          cover.push_back(w);
          match_[w] = -2;
        }
      }
    }
    return cover;
  }

  // Returns the set at the top of idx's subtree.
  int Dissect(std::vector<int>& idx) {
    if (static_cast<int>(idx.size()) <= leaf_) return NewSet(idx);
    std::vector<int> best;
    int best_dim = -1;
    for (int d = 0; d < dims_; ++d) {
      Halve(idx, d);
      std::vector<int> cover = Cover(idx);
      if (best_dim < 0 || cover.size() < best.size()) {
        best = std::move(cover);
        best_dim = d;
      }
    }
    if (2 * best.size() >= idx.size()) {
      for (int v : idx) side_[v] = kOutside;
      return NewSet(idx);
    }
    Halve(idx, best_dim);
    for (int v : best) side_[v] = 2;  // separator
    std::vector<int> parts[2];
    for (int v : idx) {
      if (side_[v] < 2) parts[side_[v]].push_back(v);
      side_[v] = kOutside;
    }
    idx.clear();
    idx.shrink_to_fit();
    int top[2] = {-1, -1};
    // Every vertex is outside again: a part's dissection sides only its own vertices (and
    // leaves them outside when it returns).
    for (int k = 0; k < 2; ++k)
      if (!parts[k].empty()) top[k] = Dissect(parts[k]);
    const int s = NewSet(best);
    for (int t : top)
      if (t >= 0) result_.parent[t] = s;
    return s;
  }

  int n_;
  const double* coords_;
  int dims_, leaf_;
  std::vector<int> ptr_, adj_;
  std::vector<signed char> side_;
  std::vector<int> match_, seen_, order_, lower_, queue_;
  std::vector<std::pair<int, int>> stack_;
  int stamp_ = 0;
  Dissection result_;
};

}  // namespace

Dissection CoordinateDissection(int n, const int* col_ptr, const int* row_index, const double* coords, int dims,
                                int leaf) {
  if (n < 0 || dims < 1) throw InvalidInput("CoordinateDissection", "bad size");
  return Dissector(n, col_ptr, row_index, coords, dims, leaf).Run();
}

}  // namespace mocapedit
