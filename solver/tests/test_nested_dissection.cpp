#include "mocapedit/nested_dissection.h"

#include <cholmod.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <utility>
#include <string>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

using mocapedit::CoordinateDissection;
using mocapedit::Dissection;

namespace {

// An nx x ny x nz grid, each vertex joined to its six neighbours: the lower triangle of
// its pattern (with the diagonal) in compressed columns, and each vertex's coordinates.
struct Grid {
  int nx, ny, nz;
  std::vector<int> ptr{0}, idx;
  std::vector<double> coords;
  int At(int x, int y, int z) const { return (z * ny + y) * nx + x; }
  int Size() const { return nx * ny * nz; }
  Grid(int nx_, int ny_, int nz_, bool edges = true) : nx(nx_), ny(ny_), nz(nz_) {
    for (int z = 0; z < nz; ++z)
      for (int y = 0; y < ny; ++y)
        for (int x = 0; x < nx; ++x) {
          if (edges) {
            idx.push_back(At(x, y, z));
            if (x + 1 < nx) idx.push_back(At(x + 1, y, z));
            if (y + 1 < ny) idx.push_back(At(x, y + 1, z));
            if (z + 1 < nz) idx.push_back(At(x, y, z + 1));
            ptr.push_back(static_cast<int>(idx.size()));
          }
          coords.insert(coords.end(), {static_cast<double>(x), static_cast<double>(y), static_cast<double>(z)});
        }
  }
};

// The graph of a group mesh's step-1 matrix: rows x cols agents in a block, each a path of
// `times` key vertices. Every three consecutive keys of an agent form a clique (its path
// triangles); each agent at each time is placed in the frame of its neighbour's step to
// the next key (a clique of those three vertices), for its four grid neighbours (the mesh,
// path_terms.h). Coordinates are (column, row, time).
Grid Formation(int rows, int cols, int times) {
  Grid g(cols, rows, times, false);
  std::vector<std::vector<int>> lower(g.Size());
  auto clique = [&](std::initializer_list<int> vs) {
    for (int a : vs)
      for (int b : vs)
        if (a >= b) lower[b].push_back(a);
  };
  for (int t = 0; t < times; ++t)
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < cols; ++c) {
        if (t + 2 < times) clique({g.At(c, r, t), g.At(c, r, t + 1), g.At(c, r, t + 2)});
        if (t + 1 == times) continue;
        for (auto [dc, dr] : {std::pair{1, 0}, std::pair{0, 1}}) {
          if (c + dc >= cols || r + dr >= rows) continue;
          const int a = g.At(c, r, t), b = g.At(c + dc, r + dr, t);
          clique({a, b, b + cols * rows});  // a in the frame of b's step (vertex = (t * rows + r) * cols + c)
          clique({b, a, a + cols * rows});
        }
      }
  g.ptr.assign(1, 0);
  g.idx.clear();
  for (auto& col : lower) {
    std::sort(col.begin(), col.end());
    col.erase(std::unique(col.begin(), col.end()), col.end());
    g.idx.insert(g.idx.end(), col.begin(), col.end());
    g.ptr.push_back(static_cast<int>(g.idx.size()));
  }
  return g;
}

bool IsAncestor(const Dissection& d, int above, int below) {
  for (int s = below; s >= 0; s = d.parent[s])
    if (s == above) return true;
  return false;
}

// CHOLMOD's flop count for the Cholesky factor of the grid's Laplacian (plus identity),
// ordered by CAMD within `sets`, or by AMD when `sets` is null.
double CholeskyFlops(const Grid& g, const int* sets) {
  cholmod_common c;
  cholmod_start(&c);
  const int n = g.Size();
  cholmod_sparse a{};
  std::vector<int> ptr = g.ptr, idx = g.idx;
  a.nrow = a.ncol = n;
  a.nzmax = idx.size();
  a.p = ptr.data();
  a.i = idx.data();
  a.stype = -1;
  a.itype = CHOLMOD_INT;
  a.xtype = CHOLMOD_PATTERN;
  a.dtype = CHOLMOD_DOUBLE;
  a.sorted = a.packed = 1;
  c.nmethods = 1;
  cholmod_factor* f;
  if (sets) {
    std::vector<int> perm(n);
    EXPECT_TRUE(cholmod_camd(&a, nullptr, 0, const_cast<int*>(sets), perm.data(), &c));
    c.method[0].ordering = CHOLMOD_GIVEN;
    f = cholmod_analyze_p(&a, perm.data(), nullptr, 0, &c);
  } else {
    c.method[0].ordering = CHOLMOD_AMD;
    f = cholmod_analyze(&a, &c);
  }
  EXPECT_NE(f, nullptr);
  const double flops = c.fl;
  cholmod_free_factor(&f, &c);
  cholmod_finish(&c);
  return flops;
}

}  // namespace

TEST(NestedDissection, SeparatorsSplitTheGraphAndComeAfterTheirParts) {
  const Grid g(12, 12, 30);
  const int leaf = 500;
  const Dissection d = CoordinateDissection(g.Size(), g.ptr.data(), g.idx.data(), g.coords.data(), 3, leaf);
  ASSERT_EQ(static_cast<int>(d.set.size()), g.Size());
  const int sets = static_cast<int>(d.parent.size());
  std::vector<int> size(sets, 0);
  for (int s : d.set) {
    ASSERT_GE(s, 0);
    ASSERT_LT(s, sets);
    ++size[s];
  }
  int roots = 0;
  for (int s = 0; s < sets; ++s) {
    EXPECT_GT(size[s], 0);
    if (d.parent[s] < 0) ++roots;
    else EXPECT_GT(d.parent[s], s);  // a separator is numbered after what it separates
  }
  EXPECT_EQ(roots, 1);
  EXPECT_GT(sets, 7);  // 4,320 vertices in parts of at most 500: three levels at least
  // Every edge stays inside a set or joins a set to one of its separators: no edge joins
  // two parts that a separator split.
  for (int j = 0; j < g.Size(); ++j)
    for (int p = g.ptr[j]; p < g.ptr[j + 1]; ++p) {
      const int a = d.set[j], b = d.set[g.idx[p]];
      EXPECT_TRUE(IsAncestor(d, a, b) || IsAncestor(d, b, a)) << "edge " << j << "-" << g.idx[p];
    }
  // Sets that were not split (no set below them) are parts of at most `leaf` vertices.
  std::vector<char> split(sets, 0);
  for (int s = 0; s < sets; ++s)
    if (d.parent[s] >= 0) split[d.parent[s]] = 1;
  for (int s = 0; s < sets; ++s)
    if (!split[s]) EXPECT_LE(size[s], leaf);
  // The first cut is across the longest axis, through one layer: a minimum vertex cover of
  // the 144 edges across it is one side's 144 vertices, not both sides' 288.
  EXPECT_EQ(size[sets - 1], 12 * 12);
}

TEST(NestedDissection, GroupMeshesFillLessThanMinimumDegree) {
  // On plain grids AMD does about as well (12 x 12 x 30: 4.5e7 flops, against 5.8e7 in
  // this order; path_edit.cpp keeps the better of the two). On a group's mesh it does not.
  const Grid g = Formation(10, 10, 43);
  const Dissection d = CoordinateDissection(g.Size(), g.ptr.data(), g.idx.data(), g.coords.data(), 3, 1500);
  const double nd = CholeskyFlops(g, d.set.data()), amd = CholeskyFlops(g, nullptr);
  RecordProperty("flops_ratio", std::to_string(nd / amd));
  EXPECT_LT(nd, 0.75 * amd) << nd << " against " << amd;
}

TEST(NestedDissection, SmallOrUnseparableGraphsStayOneSet) {
  const Grid g(4, 4, 4);
  const Dissection small = CoordinateDissection(g.Size(), g.ptr.data(), g.idx.data(), g.coords.data(), 3, 64);
  EXPECT_EQ(small.parent, std::vector<int>{-1});
  // A clique has no separator smaller than half of it.
  const int n = 40;
  std::vector<int> ptr{0}, idx;
  std::vector<double> coords;
  for (int j = 0; j < n; ++j) {
    for (int i = j; i < n; ++i) idx.push_back(i);
    ptr.push_back(static_cast<int>(idx.size()));
    coords.push_back(j);
  }
  const Dissection clique = CoordinateDissection(n, ptr.data(), idx.data(), coords.data(), 1, 8);
  EXPECT_EQ(clique.parent, std::vector<int>{-1});
  EXPECT_EQ(clique.set, std::vector<int>(n, 0));
}

TEST(NestedDissection, EqualCoordinatesStillSplitEvenly) {
  // Every vertex at the same place: the split falls back to index order, so the parts are
  // still halves (a path of 1,000 vertices needs a separator of one).
  const int n = 1000;
  std::vector<int> ptr{0}, idx;
  for (int j = 0; j < n; ++j) {
    idx.push_back(j);
    if (j + 1 < n) idx.push_back(j + 1);
    ptr.push_back(static_cast<int>(idx.size()));
  }
  const std::vector<double> coords(n, 7.0);
  const Dissection d = CoordinateDissection(n, ptr.data(), idx.data(), coords.data(), 1, 100);
  const int sets = static_cast<int>(d.parent.size());
  std::vector<int> size(sets, 0);
  for (int s : d.set) ++size[s];
  EXPECT_EQ(size[sets - 1], 1);
  EXPECT_EQ(sets, 31);  // 16 parts of about 62 vertices and 15 separators of one
}

TEST(NestedDissection, RejectsBadInput) {
  const Grid g(3, 3, 3);
  std::vector<double> coords = g.coords;
  coords[5] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(CoordinateDissection(g.Size(), g.ptr.data(), g.idx.data(), coords.data(), 3, 4), mocapedit::InvalidInput);
  std::vector<int> idx = g.idx;
  idx[2] = g.Size();
  EXPECT_THROW(CoordinateDissection(g.Size(), g.ptr.data(), idx.data(), g.coords.data(), 3, 4), mocapedit::InvalidInput);
}
