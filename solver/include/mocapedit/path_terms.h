// Building blocks of a component's path-editing problem (see path_edit.h) that would
// otherwise cost one Python call, or one numpy pass, per agent or per sampled time:
//
//   - the shape terms of every agent of a component at once;
//   - the group mesh (Kwon et al. 2008): which frame of each member falls on each sampled
//     shared time, each vertex's frame partner, and the member-to-nearest-neighbours
//     edges and triangles at each sampled time;
//   - the freedom analysis: which unknowns of a small sparse complex system its null
//     space reaches (which bodies the constraints leave free to move, turn or scale).
//
// Agents are concatenated in one #V by 2 list of rest positions, agent a owning vertices
// offsets[a] .. offsets[a+1]-1 in frame order (stage units).
#pragma once

#include <Eigen/Core>
#include <complex>
#include <vector>

#include "mocapedit/path_edit.h"
#include "mocapedit/trajectory.h"

namespace mocapedit {

// Shape terms of every agent of a component: AppendChainTerms for each agent in order.
//
// Inputs:
//   rest          #V by 2 rest positions of every agent, concatenated
//   offsets       #A+1 first vertex of each agent, then #V (non-decreasing)
//   min_baseline  as in AppendChainTerms (stage units)
// Outputs (replaced):
//   triangles     #T by 3, the agents' triangles in agent order
//   edges         #V-#A by 2, consecutive frames of each agent
// Throws InvalidInput when the offsets do not partition 0..#V-1.
void ComponentChainTerms(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
                         double min_baseline, IndexTriples& triangles, IndexPairs& edges);

// Key frames of a component's agents: group members are solved on key frames only, and
// the frames between two keys follow them (ExpandKeyFrames).
//
// Inputs:
//   rest          #V by 2 rest positions of every frame of every agent, concatenated
//   offsets       #A+1 first frame of each agent, then #V
//   keyed         #A 1 for agents solved on key frames (group members), 0 for agents
//                 that keep every frame
//   forced        #N frames (indices into rest) that must be keys; any order, repeats
//   min_baseline  stage units: two consecutive keys of an agent closer than this keep
//                 every frame between them (a stretch too short to interpolate across)
// Outputs:
//   keys          #K increasing frame indices of the keys (every frame of unkeyed agents)
//   before        #V per frame, how many keys come before it: the solve's vertex of a key,
//                 and of the next key for other frames
// Throws InvalidInput on bad offsets or forced frames out of range.
void KeyFrames(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
               const Eigen::Ref<const Eigen::VectorXi>& keyed, const Eigen::Ref<const Eigen::VectorXi>& forced,
               double min_baseline, Eigen::VectorXi& keys, Eigen::VectorXi& before);

// Every frame's position from the key frames' solved positions. An interval between two
// keys j0, j1 with frames between them has the similarity S that takes the keys' rest
// positions to their solved ones, S(z) = x0 + (z - z0) m with m = (x1 - x0) / (z1 - z0) in
// complex numbers. A frame between them at t = (f - f0) / (f1 - f0) is carried by S,
// blended with the similarities of the neighbouring intervals (those with frames between
// their keys):
//   x = S(z) + (1 - t)^2 / 2 (S_prev(z) - S(z)) + t^2 / 2 (S_next(z) - S(z)).
// Keys stay where they were solved (S_prev and S agree at j0, S and S_next at j1), and the
// path's direction and speed change smoothly through a key, where one similarity per
// interval would turn at each key of a curve (a kink in the root's velocity, which shows as
// foot skate). Where keys turn and scale the path alike, every frame moves by that one
// similarity.
//
// Inputs:
//   rest       #V by 2 rest positions of every frame
//   keys       #K increasing frame indices, the first and last frame among them
//   positions  #K by 2 solved positions of the keys
// Outputs:
//   out        #V by 2
// Throws InvalidInput on bad sizes or keys.
void ExpandKeyFrames(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& keys,
                     const Eigen::Ref<const Trajectory2>& positions, Trajectory2& out);

// The frame of each member at each sampled time of a group.
//
// Inputs:
//   sample_times  #F shot time of every member's frames, concatenated (each member's
//                 increasing)
//   offsets       #M+1 first frame of each member in sample_times, then #F
//   times         #T sampled times
// Outputs:
//   frames        #M by #T: member m's frame (0-based, its own) whose time is within 1e-6
//                 of times[t], found as the first frame at or after times[t] - 1e-9 (the
//                 last frame when there is none); -1 when that frame is not within 1e-6
// Throws InvalidInput when the offsets do not partition sample_times or a
// member has no frame.
void GroupSampleFrames(const Eigen::Ref<const Eigen::VectorXd>& sample_times,
                       const Eigen::Ref<const Eigen::VectorXi>& offsets, const Eigen::Ref<const Eigen::VectorXd>& times,
                       Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& frames);

// Frame partner of each vertex, which frames a group triangle: the nearest later frame
// of the same agent at least min_baseline away along the path and in a straight line
// (searched by arc length), else such an earlier frame, else -1.
//
// Inputs:
//   rest          #V by 2 rest positions, agents concatenated
//   offsets       #A+1 as above
//   min_baseline  stage units
// Outputs:
//   partner       #V vertex index of each vertex's partner, or -1
void FramePartners(const Eigen::Ref<const Trajectory2>& rest, const Eigen::Ref<const Eigen::VectorXi>& offsets,
                   double min_baseline, Eigen::VectorXi& partner);

// Edges and triangles of a group mesh. At each sampled time (a column of `members`) each
// member is joined to its `neighbours` nearest other members there (by rest distance, ties
// to the earlier member). Where those joins leave the members in several clusters (a group
// walking as blocks apart), each cluster is also joined to its nearest other cluster by
// their `neighbours` nearest pairs, round after round until the members are one piece:
// otherwise a cluster would be free to move on its own. Every joined pair becomes one edge
// (a, b), a < b, listed once over all times, sorted. Each edge (v, w) then gives the
// triangles (v; w, partner[w]) and (w; v, partner[v]), the first orientation of every edge
// before the second, where the partner exists and v and w are apart: v in the local frame
// of w's path.
//
// Inputs:
//   rest        #V by 2 rest positions
//   members     #M by #T vertex of each member at each sampled time
//   neighbours  joins per member and time, 0 <= neighbours < #M
//   partner     #V from FramePartners
// Outputs:
//   triangles   #t by 3 (i; j, k): vertex i in the frame of j -> k
//   edges       #e by 2
// Throws InvalidInput on indices out of range or a bad neighbour count.
void GroupMeshTerms(const Eigen::Ref<const Trajectory2>& rest,
                    const Eigen::Ref<const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& members,
                    int neighbours, const Eigen::Ref<const Eigen::VectorXi>& partner, IndexTriples& triangles,
                    IndexPairs& edges);

// Turns of several agents' headings at once: DeformationTurns of each block of rows.
//
// Inputs:
//   source, edited  #V by 2 source and edited paths of every agent, concatenated (stage units)
//   blocks          #B by 2 [begin, end) rows of each agent
//   fixed           #R by 3 (block, first, last): inclusive frame ranges (frames of that block)
//                   that turn rigidly, grouped by block in block order
//   fixed_turn      #R turn of each fixed range
//   window, min_travel, max_step  as in DeformationTurns
//   keep_spot       #B DeformationTurns' keep_spot of each block (nonzero: keep), or empty: every block
// Outputs:
//   turns           #V: each block's rows filled as DeformationTurns fills them, other rows 0
// Throws InvalidInput on blocks or ranges out of range.
void BlockDeformationTurns(const Eigen::Ref<const Trajectory2>& source, const Eigen::Ref<const Trajectory2>& edited,
                           const Eigen::Ref<const IndexPairs>& blocks, const Eigen::Ref<const IndexTriples>& fixed,
                           const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window, double min_travel,
                           double max_step, const Eigen::Ref<const Eigen::VectorXi>& keep_spot, Eigen::VectorXd& turns);

// Columns of a sparse complex #R by #C matrix A that its null space reaches: c such that
// some x with A x = 0 has x_c != 0. Each column is first scaled to unit largest magnitude;
// Gaussian elimination with partial pivoting (column by column, only rows that hold the
// column) treats pivots of magnitude <= tolerance as zero, which leaves their columns
// free; two pseudo-random null vectors (free entries of unit magnitude, deterministic)
// are then back-substituted, and a pivot column is reached where either has an entry
// above the tolerance. Cost: a few operations per entry and fill-in, for the small
// banded systems of the freedom analysis.
//
// Inputs:
//   rows, cols  #N row and column of each entry (repeated positions are summed)
//   values      #N entries
//   num_rows    #R
//   num_cols    #C
//   tolerance   > 0, relative to the scaled columns (1e-9 is typical)
// Returns #C flags (1: reached). With no rows, every column is reached.
// Throws InvalidInput on sizes or indices out of range.
std::vector<char> NullSpaceSupport(const Eigen::Ref<const Eigen::VectorXi>& rows,
                                   const Eigen::Ref<const Eigen::VectorXi>& cols,
                                   const Eigen::Ref<const Eigen::VectorXcd>& values, int num_rows, int num_cols,
                                   double tolerance);

}  // namespace mocapedit
