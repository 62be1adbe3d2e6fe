// The solve behind collision avoidance: many agents' paths, each kept close to its rest
// path by the two-step Laplacian energy of the deliverable (section 5.2: step 1 keeps the
// local shape of every frame in the frame of the frames around it, step 2 the length of
// every step), coupled by linear equality rows on the ground positions (section 6.2: the
// constraints joining colliding points; also artist pins and links, and the push-out of
// avoid regions). The energy's terms are the path editor's (path_edit.h: an agent's chain
// terms as AppendChainTerms gives them, at min_baseline), built by the same code; every
// frame is also anchored (below).
//
// Each agent's energy is factored once (SeparationPrecompute). The rows change from solve
// to solve (collision avoidance adds, re-linearises and drops them), so they are not part
// of the factorization: each solve forms each agent's block of the Schur complement of its
// rows (S = C K^-1 C^T, one back-substitution per row), finds the row forces and adds each
// agent's response. Rows are equalities or one-sided ("at least"): the forces solve the
// complementarity problem on S by projected Gauss-Seidel (a one-sided row pushes, never
// pulls), then the equality rows are met exactly by a direct solve. The Schur complement
// of a dense crowd fills in badly when factored, so it is never factored whole; the cost
// of a solve grows with the rows per agent, not with the crowd. Repeated solves (with a
// SeparationCache) reuse the entries of K^-1 earlier rows needed and, for an agent whose
// rows are the same as last time, its whole block; the forces of a previous solve, given
// back per step, are warm starts.
//
// Every frame is also pulled weakly towards its rest position (anchor_weight, relative to
// the shape terms): it keeps agents without any pin in place and makes a push a local
// detour rather than a shift of the whole path. A detour spreads over roughly
// anchor_weight^(-1/4) frames on each side.
//
// The weights hold per frame at one sampling rate. An agent sampled k times as often
// (rates[a] = k: a 120 fps clip where the weights are set for 24) has k times the frames for
// the same motion: summed over them, its anchors would weigh k times more, its step-1 shape
// terms (second differences) k^-3 and its step-2 edges (first differences) k^-1, so its
// detours would last 1/k of the seconds and it would give way k^3 times as easily. Its
// anchors weigh 1/k, its shape terms k^3 and its edges k instead: the same motion costs the
// same at any rate.
//
// Stationary ranges move rigidly in both steps (section 5.4.2.5): the range's frames are
// replaced by one similarity in step 1 (translation and a complex scale) and by one
// translation turned by step 1's rotation in step 2. Ranges whose rest positions stand
// within still_extent of each other only translate, and keep their source facing (the
// path editor turns such ranges with the edges around them: a push moves a stand
// sideways, and the edges next to it are too short to carry a direction).
//
// Positions are ground-plane coordinates in stage units; agents' paths are concatenated
// into one #V by 2 list, agent a owning vertices starts[a] .. starts[a+1]-1 (one per frame).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

#include "mocapedit/errors.h"
#include "mocapedit/trajectory.h"

namespace mocapedit {

struct SeparationProblem {
  Trajectory2 rest;            // #V by 2 rest positions, agents concatenated
  Eigen::VectorXi starts;      // #A+1 first vertex of each agent, then #V (non-decreasing)
  std::vector<FrameRange> rigid;  // inclusive global vertex ranges, each inside one agent, disjoint
  double anchor_weight = 1e-3;    // > 0
  Eigen::VectorXd rates;          // #A, each > 0: each agent's samples per unit of time, relative; empty: 1
  // #V, each >= 1, or empty: how many frames' time each vertex's anchor stands for (1; a pose
  // held after its clip ends stands for the frames it is held: as stiff as a stand that long).
  Eigen::VectorXd anchor_frames;
  // #V, or empty: 1 where the rest step into the vertex from the one before is a cut (a rest
  // pose left in a clip's first frame, a teleport): no motion to keep the shape of. No shape
  // term spans a cut (a frame's triangle, a step's edge); the anchors hold each side.
  Eigen::VectorXi cut_into;
  double still_extent = 1e-9;     // stage units, >= 0
  // Stage units, >= 0: each frame's shape term is framed by the nearest frames around it
  // at least this far apart (AppendChainTerms), so a frame that stands still or sways is
  // framed by the walk around it. Frames closer than still_extent never frame a term.
  double min_baseline = 0;
  int threads = 0;                // 0: hardware, at most 2; the result is the same on any number
};

// #R linear rows on ground positions, each sum_t weight_t * dot(direction_r, x[vertex_t])
// = rhs_r. A pin is two rows (directions (1,0) and (0,1)); a separation is one row along
// the normal between two agents' points (weights +1 and -1, or interpolation weights).
struct SeparationRows {
  Trajectory2 direction;       // #R by 2 (unit or not: the row is scaled with it)
  Eigen::VectorXd rhs;         // #R
  Eigen::VectorXd softness;    // #R: 0 = hard, else 1 / weight relative to the shape terms
  Eigen::VectorXi kind;        // #R: 0 equality, 1 at least (value >= rhs); empty: all equalities
  Eigen::VectorXd initial_forces;  // #R step-2 starting forces (a previous solve's `forces`), or empty
  // #R step-1 starting forces (a previous solve's `shape_forces`), or empty. When it is empty,
  // step 1 starts from initial_forces and step 2 from step 1's forces.
  Eigen::VectorXd initial_shape_forces;
  Eigen::VectorXi term_row;    // #T row of each term
  Eigen::VectorXi term_vertex; // #T global vertex of each term
  Eigen::VectorXd term_weight; // #T
};

struct SeparationSettings {
  double tolerance = 1e-6;     // stage units: Gauss-Seidel stops when no row value moves more
                               // (smaller changes are not passed on to the other rows)
  int max_sweeps = 500;        // Gauss-Seidel sweeps per step at most
  double relaxation = 1.0;     // over-relaxation factor of the sweeps, in (0, 2)
  // From this many frames of the agents the rows touch, the rows are swept in two halves of
  // the crowd on two threads (the same forces on any thread count: a big crowd's sweeps wait
  // on memory); below it, or when negative, every row in time order on one thread.
  int64_t split_from = 1000000;
};

struct SeparationResult {
  Trajectory2 positions;        // #V by 2 after step 2 (agents no row touches keep rest)
  Trajectory2 shape;            // #V by 2 after step 1
  Eigen::VectorXd forces;       // #R step-2 row forces: > 0 pushes the row value up
  Eigen::VectorXd shape_forces; // #R step-1 row forces
  Eigen::VectorXd residuals;    // #R row value minus rhs after step 2
  Eigen::VectorXd rigid_angles; // #rigid rotation of each range (radians, CCW) in step 2
  int moved_agents = 0;         // agents some row touched
  int sweeps = 0;               // Gauss-Seidel sweeps, both steps
  int64_t updates = 0;          // row force changes the sweeps passed on, both steps
  int64_t inverse_columns = 0;  // back-substitutions for the agents' blocks (the rest were cached)
  bool converged = true;        // both steps met the tolerance within max_sweeps
  bool regularized = false;     // the hard equality rows were dependent: a tiny softness was added
  // Wall seconds spent forming the agents' blocks (both steps), in the Gauss-Seidel sweeps
  // and exact equality solves (both steps), in the final responses, and in gathering the
  // rows by agent.
  Eigen::Vector4d seconds = Eigen::Vector4d::Zero();
};

namespace detail {
struct SeparationState;  // defined in separation_internal.h
}

// Every agent's factored steps, from SeparationPrecompute.
struct SeparationData {
  SeparationData();
  ~SeparationData();
  SeparationData(SeparationData&&) noexcept;
  SeparationData& operator=(SeparationData&&) noexcept;

  std::unique_ptr<const detail::SeparationState> state;  // opaque
};

// Builds and factors each agent's two steps.
//
// Inputs:
//   problem  as documented on SeparationProblem
// Outputs:
//   data     replaced; reuse it for every SeparationSolve on the same agents
// Throws InvalidInput on bad shapes, starts or ranges, non-finite rest positions, a
// non-positive anchor weight or a negative min_baseline; NumericalError when an agent's energy cannot be factored.
void SeparationPrecompute(const SeparationProblem& problem, SeparationData& data);

// Solves both steps under the rows. Const on data; may run from several threads.
// Throws InvalidInput on bad shapes, vertices out of range, a row without terms, negative
// softness or non-finite values; NumericalError when the equality rows cannot be solved
// even regularized.
void SeparationSolve(const SeparationData& data, const SeparationRows& rows, const SeparationSettings& settings,
                     SeparationResult& result);

// Entries of each agent's inverse energy that earlier solves needed, kept for the next
// solve on the same data (rows that persist from solve to solve then cost no
// back-substitution). Use one cache per SeparationData, from one thread at a time.
struct SeparationCache;
struct SeparationCacheDeleter {
  void operator()(SeparationCache* cache) const;
};
std::unique_ptr<SeparationCache, SeparationCacheDeleter> SeparationNewCache();

// As above, reusing and growing `cache`.
void SeparationSolve(const SeparationData& data, const SeparationRows& rows, const SeparationSettings& settings,
                     SeparationCache& cache, SeparationResult& result);

// Number of agents and vertices of a precomputed problem.
int SeparationAgentCount(const SeparationData& data);
int SeparationVertexCount(const SeparationData& data);

}  // namespace mocapedit
