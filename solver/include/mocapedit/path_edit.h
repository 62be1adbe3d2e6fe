// Two-step as-rigid-as-possible path editing on the ground plane (Igarashi et al. 2005,
// sections 5.2 and 5.4 of the deliverable), general enough for one agent, a group mesh
// (Kwon et al. 2008), characters linked by relative constraints (Kim et al. 2009) and the
// separation links of collision avoidance.
//
// The problem is one sparse least-squares system over #V ground-plane vertices (stage
// units): every agent of a connected component concatenated, one vertex per frame.
//
//   Step 1 (shape)  keeps each "triangle" term: vertex i in the local frame of j and k,
//                     P_i = P_j + x (P_k - P_j) + y R90 (P_k - P_j)
//                   with (x, y) taken from the rest positions and R90 the counter-
//                   clockwise quarter turn. These terms do not change under a rotation
//                   and uniform scale, so step 1 bends the path but may scale it.
//   Step 2 (scale)  keeps each "edge" term: P_k - P_j equals the rest vector of the edge
//                   turned to the direction step 1 gave it, at its rest length.
//
// Both steps also carry
//   handles   vertex v at a position p                     (hard, or soft with a weight)
//   links     P_a - P_b = offset, between any two vertices  (hard, or soft with a weight)
//   rigid ranges  sets of vertices that move by one transform in both steps: kRotate (a
//             stationary range: turned and moved rigidly, its rotation taken from step 1;
//             the turn angle is returned so headings turn by exactly the same angle) or
//             kTranslate (moved only, never turned).
//
// Hard handles and links are met exactly: they, and the rigid ranges, are eliminated from
// the unknowns (vertices tied by hard links share one unknown up to a known offset), so
// the factorization is of a smaller positive (semi)definite system. Soft terms are
// weighted relative to the shape terms, whose weights are usually 1.
//
// Use: PathEditPrecompute once for a fixed structure (which vertices are handled, linked,
// rigid, and the weights), then PathEditSolve as often as the handle positions and link
// offsets change (dragging a handle, re-linearised collision links). Solve is const on the
// data and may run from several threads at once.
//
// Factorizations, chosen by measurement (bench/bench_path.py times a single path, a relay
// of agents tied end to start and a group mesh, each next to a scipy peer):
//  - Envelope LDLT (mocapedit/skyline_ldlt.h) in the natural column order, assembled
//    straight from the rows, when its work is at most 64 multiply-adds per column: single
//    paths (a band of 2 to a few columns) and chains of agents tied end to start (the
//    relay: each agent's soft link between its first and last frames makes the bandwidth
//    a whole agent, but the envelope only one extra entry per column, and fills nothing
//    else).
//  - Otherwise CHOLMOD analyses the matrix; when its factor has at least 40 flops per
//    entry (dense fronts: group meshes) CHOLMOD's supernodal Cholesky factors it with BLAS,
//    its OpenMP regions kept on the calling thread (mocapedit/blas_lock.h). Calls into
//    BLAS hold the lock of mocapedit/blas_lock.h. The order of step 1, given vertex times:
//    a nested dissection by position about the centroid at each time and by time
//    (mocapedit/nested_dissection.h) with CAMD within its parts, or AMD's, whichever AMD's
//    and CAMD's own counts say costs fewer flops (AMD wins on long thin and on wide short
//    formations); otherwise, and for step 2, CHOLMOD's AMD. METIS (through CHOLMOD) finds
//    slightly better orders but costs about as much as the factorization; a reverse
//    Cuthill-McKee band or a level-set dissection costs more flops than AMD.
//  - Else Eigen's simplicial LDLT in AMD order (small components with scattered links).
// UMFPACK LU and CHOLMOD on single paths are several times slower than a banded LDLT.
//
// Accuracy. Step 1's normal equations have a condition number growing like L^4 for a
// stretch of L frames between constraints (about 1e15 for 20,000 frames), so a plain
// Cholesky solve of a long clip is wrong in its leading digits. The solve starts from the
// rest path moved by the best similarity to the handles (so it solves for a small
// deformation), then refines with residuals accumulated in extended precision (with the
// shape coefficients themselves kept in extended precision, as a double and its rounding
// error): each pass divides the error by about cond * 1e-16. The first pass, far from the
// solution, uses double residuals (its correction is only good to cond * 1e-16 anyway);
// the extended ones follow, at least one of them. When the estimated condition makes that ratio too large, when
// refinement does not converge, or when the factorization is singular, the step uses sparse
// QR (SPQR) of the rectangular system instead, whose error grows only like L^2, refined the
// same way; PathEditResult says which. A 20,000-frame clip comes out within 1e-14 of its
// extent of the exact answer, as a 200-frame one does.
#pragma once

#include <Eigen/Core>
#include <complex>
#include <memory>
#include <string>
#include <vector>

#include "mocapedit/errors.h"  // ContradictionError
#include "mocapedit/trajectory.h"

namespace mocapedit {

enum class RigidMode {
  kRotate,     // one rotation + translation; the rotation comes from step 1
  kTranslate,  // one translation, no rotation
};

struct RigidRange {
  std::vector<int> vertices;  // vertex indices (any order, no repeats)
  RigidMode mode = RigidMode::kRotate;
};

using IndexTriples = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using IndexPairs = Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>;

// The structure of a path-editing problem. Weights of handles and links are +infinity for
// hard constraints, a finite value >= 0 for soft ones.
struct PathEditProblem {
  Trajectory2 rest;                 // #V by 2 rest (source) positions, stage units
  IndexTriples triangles;           // #T by 3 (i, j, k): vertex i in the frame of j -> k
  Eigen::VectorXd triangle_weights; // #T weights >= 0 (empty: all 1)
  IndexPairs edges;                 // #E by 2 (j, k): step-2 edge from j to k
  Eigen::VectorXd edge_weights;     // #E weights >= 0 (empty: all 1)
  std::vector<RigidRange> rigid;    // #R disjoint rigid vertex sets
  Eigen::VectorXi handles;          // #H handled vertex per handle
  Eigen::VectorXd handle_weights;   // #H: +inf hard, else soft weight >= 0
  IndexPairs links;                 // #L by 2 (a, b): P_a - P_b = offset
  Eigen::VectorXd link_weights;     // #L: +inf hard, else soft weight >= 0
  // kRotate ranges whose rest positions all lie within this distance (stage units) of
  // each other are too small to carry a rotation of their own: they move as a point in
  // step 1 and turn with the step-1 edges entering and leaving them.
  double rigid_min_extent = 0;
  // #V time of each vertex (any unit; shot times for group members), or empty. Large
  // systems use them to order their factorization (below).
  Eigen::VectorXd vertex_times;
  // Also precompute step 1's response to each handle position and link offset (one solve
  // each): PathEditSolve then needs only step 2's solve. For interactive dragging.
  bool precompute_responses = false;
  // Solve both steps by sparse QR even when the normal equations are well conditioned
  // (for comparisons).
  bool force_qr = false;
};

// How one step was solved, for the report.
struct StepInfo {
  std::string solver;      // "LDLT", "LDLT (AMD)", "CHOLMOD supernodal", "SPQR", "SPQR (singular)",
                           // "SPQR (ill-conditioned)", "rigid" (one rigid motion met every
                           // constraint), "none" (no unknowns)
  int unknowns = 0;        // free vertices after elimination
  int refinements = 0;     // extended-precision refinement passes used by the last solve
  double correction = 0;   // size of the last refinement correction (stage units)
};

struct PathEditResult {
  Trajectory2 positions;         // #V by 2 edited positions (after step 2)
  Trajectory2 shape;             // #V by 2 step-1 positions (shape step, possibly scaled)
  Eigen::VectorXd rigid_angles;  // #R rotation (radians, CCW) applied to each rigid range
  bool rigid_motion = false;     // true when every constraint was met by one rigid motion
  double rigid_angle = 0;        // that motion's rotation, when rigid_motion
  StepInfo step1, step2;
};

namespace detail {
struct PathEditState;  // defined in path_edit_internal.h
}

// Precomputed structure and factorizations, from PathEditPrecompute.
struct PathEditData {
  PathEditData();
  ~PathEditData();
  PathEditData(PathEditData&&) noexcept;
  PathEditData& operator=(PathEditData&&) noexcept;

  int handle_count = 0;  // #H of the problem
  int link_count = 0;    // #L of the problem
  std::unique_ptr<const detail::PathEditState> state;  // opaque
};

// Validates the problem, eliminates hard constraints and rigid ranges, builds and factors
// both steps.
//
// Inputs:
//   problem  as documented on PathEditProblem
// Outputs:
//   data     replaced; reuse it for every PathEditSolve with the same structure
// Throws InvalidInput for bad shapes, indices out of range, negative or non-finite
// weights, overlapping rigid ranges, a triangle whose frame vertices j and k share a rest
// position; ContradictionError (an InvalidInput) for a rigid range that holds more hard
// constraints than it can (two for kRotate, one for kTranslate), naming them;
// NumericalError when a factorization fails.
void PathEditPrecompute(const PathEditProblem& problem, PathEditData& data);

// Solves both steps for the given handle positions and link offsets.
//
// Inputs:
//   data              from PathEditPrecompute
//   handle_positions  #H by 2 positions, stage units
//   link_offsets      #L by 2 offsets P_a - P_b, stage units
// Outputs:
//   result            positions, step-1 positions, rigid angles and solver notes
// Throws ContradictionError when hard constraints disagree by more than
// 1e-7 + 1e-12 * (largest coordinate), naming every constraint in the cycle;
// InvalidInput for wrong shapes or non-finite values; NumericalError when a solve fails.
void PathEditSolve(const PathEditData& data, const Eigen::Ref<const Trajectory2>& handle_positions,
                   const Eigen::Ref<const Trajectory2>& link_offsets, PathEditResult& result);

// Estimated 2-norm condition number of each step's factorized normal matrix (largest
// eigenvalue from Gershgorin's bound, smallest from inverse iteration with the factor).
// Costs a few solves; for reports and benchmarks. Returns {step 1, step 2}; 0 when a
// step has no unknowns, infinity when it is singular.
std::pair<double, double> PathEditConditionEstimate(const PathEditData& data);

// Shape terms of one agent's path: vertices first .. first+count-1 of `rest` in frame
// order. Each inner vertex i gets the triangle (i; a, b) with a < i < b the nearest frames
// whose rest positions are at least `min_baseline` apart (the frame widens around frames
// that stand still); a vertex that cannot be framed that way gets none. Consecutive
// frames get an edge. Terms that fall inside one rigid range are dropped by
// PathEditPrecompute, so stationary ranges need no special care here.
//
// Outputs are appended:
//   triangles  (#T+t) by 3
//   edges      (#E+count-1) by 2
void AppendChainTerms(const Eigen::Ref<const Trajectory2>& rest, int first, int count, double min_baseline,
                      IndexTriples& triangles, IndexPairs& edges);

}  // namespace mocapedit
