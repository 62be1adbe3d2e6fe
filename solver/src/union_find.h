// Disjoint sets of 0..n-1 with path halving; a set is named by its smallest member
// (internal).
#pragma once

#include <algorithm>
#include <numeric>
#include <vector>

namespace mocapedit::detail {

class UnionFind {
 public:
  UnionFind() = default;
  explicit UnionFind(int n) { Reset(n); }
  // Every element its own set again.
  void Reset(int n) {
    parent_.resize(static_cast<size_t>(n));
    std::iota(parent_.begin(), parent_.end(), 0);
  }
  int Find(int x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  // Joins the sets of a and b; false when they were one already.
  bool Unite(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return false;
    parent_[std::max(a, b)] = std::min(a, b);
    return true;
  }

 private:
  std::vector<int> parent_;
};

}  // namespace mocapedit::detail
