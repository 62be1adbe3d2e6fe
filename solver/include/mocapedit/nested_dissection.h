// Nested dissection of a sparse symmetric matrix's graph by the coordinates of its
// unknowns, for ordering its Cholesky factorization.
//
// A group mesh joins its members' paths at sampled times, so its graph is a slab of space
// (the formation) by time. Minimum degree orderings (AMD) leave large dense fronts in such
// graphs; cutting the graph into parts through small separators and ordering each
// separator after its parts keeps the fronts small. Graph partitioners (METIS) find such
// separators from the graph alone but cost as much as the factorization here; the
// unknowns' positions and times give them almost for free.
//
// On a group mesh's step 1 this order needs about half of the CHOLMOD flops of AMD's, close
// to METIS's order at a small part of its cost.
#pragma once

#include <vector>

#include "mocapedit/errors.h"

namespace mocapedit {

struct Dissection {
  // Per vertex: the part or separator it belongs to. Sets are numbered so that a separator
  // comes after every set below it: ordered by set (as CAMD's constraint sets), the
  // factorization never fills between two parts that a separator split.
  std::vector<int> set;
  // Per set: the separator that split it off, or -1 for the root (or a part never split).
  std::vector<int> parent;
};

// Recursive bisection: each part with more than `leaf` vertices is split at the median of
// the coordinate (of `dims`) whose split needs the smallest separator, a minimum vertex
// cover of the edges across it (Koenig). Parts stop splitting at `leaf` vertices or when no
// coordinate separates them with fewer than half their vertices.
//
// The graph is the pattern of a symmetric n x n matrix in compressed columns (one triangle
// or both; the diagonal is ignored). `coords` is n x dims, row-major. Throws
// InvalidInput on an index out of range or a coordinate that is not finite.
Dissection CoordinateDissection(int n, const int* col_ptr, const int* row_index, const double* coords, int dims,
                                int leaf);

}  // namespace mocapedit
