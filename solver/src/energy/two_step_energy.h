// The two-step as-rigid-as-possible energy of ground-plane paths (section 5.2 of the
// deliverable; Igarashi et al. 2005), written once for path editing (path_edit_*.cpp) and
// for the separation solve of collision avoidance (separation*.cpp). The two solvers take
// their terms from here and differ only in their unknowns (the path editor eliminates hard
// constraints and rigid ranges over a whole component; the separation solver factors each
// agent on its own, its rigid ranges replaced by a few unknowns) and in how they solve.
//
// Positions are complex numbers x + iy, stage units: z the rest (source) positions, x the
// edited ones. One vertex per frame of an agent (per key frame of a group member).
//
//   Step 1 (shape)  a shape term keeps vertex i in the local frame of j -> k,
//                     x_i + (c - 1) x_j - c x_k = 0,   c = (z_i - z_j) / (z_k - z_j),
//                   the deliverable's P_i = P_j + a (P_k - P_j) + b R90 (P_k - P_j) with
//                   c = a + ib. It holds under any rotation and uniform scale, so step 1
//                   bends a path and may scale it. Along an agent's path (a chain) frame i
//                   is framed by the nearest frames around it that are at least a baseline
//                   apart (ChainFrames), so a frame that stands still, or a sway of a few
//                   millimetres, is never the frame of a term.
//   Step 2 (scale)  an edge term keeps x_k - x_j at the edge's rest length along the
//                   direction step 1 gave it (EdgeTarget).
//   Anchors         x_v = z_v, weighted: the separation solver's pull of every frame to its
//                   source (the path editor has handles instead, the same rows).
//   Rigid ranges    (stationary ranges, section 5.4.2.5) move as one: terms whose vertices
//                   all lie in one range are dropped (InOneRange); the range is one
//                   similarity in step 1 and one translation of its rest shape turned by
//                   step 1's rotation in step 2 (RangeTurn). A range whose rest positions
//                   lie within a small extent of each other (RangeMasters) is too small to
//                   carry a rotation: it moves as a point in step 1 and, in path editing,
//                   turns with the step-1 edges entering and leaving it (BoundaryTurn); in
//                   avoidance it keeps its source facing (separation.h says why).
//
// Shape terms are built in the caller's precision: extended for the path editor (it refines
// its solve with residuals in extended precision), double for the separation solver.
#pragma once

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cmath>
#include <complex>
#include <initializer_list>
#include <utility>

#include "mocapedit/trajectory.h"

namespace mocapedit::detail {

using LCplx = std::complex<long double>;

// A row of a term: (vertex, coefficient) pairs, sum coeff * x_vertex = target.
template <typename T, size_t N>
using TermRow = std::array<std::pair<int, std::complex<T>>, N>;

// ---------------------------------------------------------------------------------------
// Step 1.

// Vertex i in the local frame of j -> k (vertex indices of the caller's numbering), its
// coefficient in precision T (double or long double).
template <typename T>
struct ShapeTerm {
  int i, j, k;
  std::complex<T> c;  // (z_i - z_j) / (z_k - z_j)
};

template <typename T>
ShapeTerm<T> MakeShapeTerm(int i, int j, int k, const std::complex<T>& zi, const std::complex<T>& zj,
                           const std::complex<T>& zk) {
  return {i, j, k, (zi - zj) / (zk - zj)};
}

// Its row, of zero target: x_i + (c - 1) x_j - c x_k.
template <typename T>
TermRow<T, 3> Row(const ShapeTerm<T>& t) {
  return {{{t.i, T(1)}, {t.j, t.c - T(1)}, {t.k, -t.c}}};
}

// The frames of one agent's shape terms. Calls frame(i, a, b) for each inner frame i of
// the chain rest[first .. first+count-1] (indices local to the chain, a < i < b) with a, b
// the nearest frames around i whose rest positions are at least `min_baseline` (stage
// units) apart and apart at all, the frame widened symmetrically around i; a frame that
// cannot be framed so gets no term.
template <typename Frame>
void ChainFrames(const Eigen::Ref<const Trajectory2>& rest, int first, int count, double min_baseline, Frame frame) {
  const auto gap = [&](int a, int b) { return (rest.row(first + b) - rest.row(first + a)).norm(); };
  for (int i = 1; i + 1 < count; ++i) {
    int a = i - 1, b = i + 1;
    double g = gap(a, b);
    while (g < min_baseline || g == 0.0) {
      if (a > 0 && (b + 1 >= count || i - a <= b - i))
        --a;
      else if (b + 1 < count)
        ++b;
      else
        break;
      g = gap(a, b);
    }
    if (g >= min_baseline && g > 0.0) frame(i, a, b);
  }
}

// ---------------------------------------------------------------------------------------
// Step 2.

// x_k - x_j = target.
struct EdgeTerm {
  int j, k;
};

inline TermRow<double, 2> Row(const EdgeTerm& e) { return {{{e.k, 1.0}, {e.j, -1.0}}}; }

// The target of an edge: its rest length along its step-1 vector, or its rest vector when
// step 1 collapsed it.
inline std::complex<double> EdgeTarget(const std::complex<double>& step1, double rest_length,
                                       const std::complex<double>& rest) {
  const double length = std::sqrt(std::norm(step1));
  return length > 0 ? step1 * (rest_length / length) : rest;
}

// The edges of one agent's chain of `count` frames: edge(j, j + 1) for each step, local
// indices.
template <typename Edge>
void ChainEdges(int count, Edge edge) {
  for (int j = 0; j + 1 < count; ++j) edge(j, j + 1);
}

// ---------------------------------------------------------------------------------------
// Anchors: x_v = z_v.

inline TermRow<double, 1> AnchorRow(int v) { return {{{v, 1.0}}}; }

// ---------------------------------------------------------------------------------------
// Rigid ranges.

// True when every vertex lies in one rigid range: its terms are dropped. range_of(v) is
// v's range, or < 0.
template <typename RangeOf>
bool InOneRange(const RangeOf& range_of, std::initializer_list<int> vertices) {
  const int r = range_of(*vertices.begin());
  if (r < 0) return false;
  for (int v : vertices)
    if (range_of(v) != r) return false;
  return true;
}

// Two vertices of a range far apart, whose rest vector carries the range's rotation in
// step 1: the vertex farthest from `from`, and the one farthest from it (the first of the
// range when `from` < 0). `vertices` is the range's vertices in order, z(v) a vertex's rest
// position. Their distance is the range's extent: at most a small extent, the range is
// too small to carry a rotation.
template <typename Vertices, typename Z>
std::pair<int, int> RangeMasters(const Vertices& vertices, const Z& z, int from = -1) {
  const auto farthest = [&](int start) {
    int best = start;
    double distance = -1;
    for (int v : vertices) {
      const double d = std::abs(z(v) - z(start));
      if (d > distance) distance = d, best = v;
    }
    return best;
  };
  const int m1 = from >= 0 ? from : farthest(*std::begin(vertices));
  return {m1, farthest(m1)};
}

// The unit rotation of a step-1 similarity factor (or summed edge turn), 1 when it is 0.
template <typename T>
std::complex<T> RangeTurn(const std::complex<T>& q) {
  const T length = std::sqrt(std::norm(q));
  return length > 0 ? q / length : std::complex<T>(1);
}

// The turn a step-1 edge adds to a small range's rotation: its step-1 vector against its
// rest vector. Summed over the edges entering and leaving the range, then RangeTurn.
template <typename T>
std::complex<T> BoundaryTurn(const std::complex<T>& step1, const std::complex<T>& rest) {
  return step1 * std::conj(rest);
}

}  // namespace mocapedit::detail
