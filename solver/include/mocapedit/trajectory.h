// Ground-plane trajectory utilities shared by every solve.
//
// A trajectory is a #N by 2 list of root positions on the ground plane, one row per
// source frame, in stage units. Headings are angles in radians, counter-clockwise about
// the up axis, measured from the ground plane's first axis.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "mocapedit/errors.h"

namespace mocapedit {

using Trajectory2 = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using FrameRange = std::pair<int, int>;  // inclusive [first, last]

// Total polyline length of a #N by 2 trajectory.
double PathLength(const Eigen::Ref<const Trajectory2>& points);

// #N cumulative arc length, starting at 0.
Eigen::VectorXd CumulativeArcLength(const Eigen::Ref<const Trajectory2>& points);

// Heading of each frame from the path tangent (central difference of the neighbours,
// one-sided at the ends), unwrapped so consecutive headings never jump by more than pi.
//
// Inputs:
//   points      #N by 2 trajectory
//   fixed       frame ranges whose heading stays constant (stationary sections): every
//               frame in a range takes `fallback` for that range
//   fallback    #R headings, one per fixed range
//   min_step    tangents shorter than this (stage units) are treated as standing still;
//               such a frame keeps the heading of the nearest moving frame
// Returns #N headings. Throws InvalidInput on bad shapes or ranges.
Eigen::VectorXd TangentHeadings(const Eigen::Ref<const Trajectory2>& points,
                                const std::vector<FrameRange>& fixed,
                                const Eigen::Ref<const Eigen::VectorXd>& fallback,
                                double min_step);

// Turn of each frame's heading (radians, counter-clockwise) when a path goes from `source`
// to `edited`: the local rotation the edit applies to the path around the frame, so that an
// edited body faces its source heading plus this turn (never the edited path's tangent).
//
// The rotation of frame i is the least-squares rotation taking the source steps near it onto
// the edited ones: the angle of the sum of conj(s_k) e_k (steps as complex numbers) over the
// steps within two nested box windows of `window` frames each side, so each step counts by the
// product of its lengths and a step that barely moves cannot flip it. Where the source moves
// less than `min_travel` from `window` frames before to `window` frames after (a stand, a turn on
// the spot, the top of a jump: a displacement, so the jitter of a standing root is no travel)
// the turn is interpolated, by frame, from the frames around it that move at least
// four times as far (held beyond the first and last); with none, it is the whole
// path's rotation. A frame that moves between the two counts its own turn in proportion, on top
// of that: a slow shuffle nudged a few centimetres sideways is not a turn of the body, a walk
// bent by the same amount is. Each fixed range turns by its own angle, as one rigid body, and the `window` frames
// either side of it blend from that angle into the moving frames'. An unedited path turns by
// exactly 0, a rigidly turned walk by its angle; with nothing that moves and no fixed range, 0.
// A source step longer than `max_step` is a cut, not a motion (a clip whose first frame is its
// rest pose at the origin, a teleport): it counts for nothing, so its length cannot outweigh
// the steps around it and make the turn jump where it leaves the windows.
//
// Inputs:
//   source, edited  #N by 2 trajectories (stage units), paired by frame
//   fixed           inclusive frame ranges that turn rigidly (stationary sections)
//   fixed_turn      #R turn of each fixed range
//   window          half-width of each box window, frames (at least 1)
//   min_travel      stage units
//   max_step        stage units per frame (0: no step is a cut)
//   keep_spot       a path that stays about one spot keeps its facing (see below)
//
// With `keep_spot` (and min_travel > 0), a frame's own turn counts only as far as the path
// goes somewhere around it: over windows of three turn windows each side, its chord must be
// at least 0.4 of the distance walked (in full from 0.7). And with no frame sure of its turn,
// the whole path's rotation counts only as far as the whole path goes somewhere, and holds
// every frame as strongly as the rest falls short. A clip that moves about one spot (a boxer's
// bounce, a dance, an idle's shuffle) moved by an edit then keeps its facing: the rotation the
// edit gives its wiggles is not the body's; nor is any other turn of such a path, rigid or not
// (they cannot be told apart here: the path editor turns a component moved as one rigid body
// by its angle without asking). Without it (a group member, turned with its formation), as
// before.
// Returns #N turns, unwrapped. Throws InvalidInput on bad shapes or ranges.
Eigen::VectorXd DeformationTurns(const Eigen::Ref<const Trajectory2>& source,
                                 const Eigen::Ref<const Trajectory2>& edited,
                                 const std::vector<FrameRange>& fixed,
                                 const Eigen::Ref<const Eigen::VectorXd>& fixed_turn, int window,
                                 double min_travel, double max_step = 0.0, bool keep_spot = true);

// How far a path stays about one spot, in [0, 1], as DeformationTurns (with keep_spot) holds it
// when no frame travels far enough to be sure of its own turn: 1 minus the straightness of the
// whole path (its chord over the distance walked, 0 at most 0.4 of it, 1 from 0.7); 0 when some
// frame is sure, or min_travel is 0. A boxer's bounce, a dance, an idle's shuffle: near 1.
// Same arguments as DeformationTurns (the fixed ranges aside: a path with any has them to turn by).
double SpotWeight(const Eigen::Ref<const Trajectory2>& source, int window, double min_travel, double max_step = 0.0);

// Adds multiples of 2*pi so consecutive angles differ by at most pi.
void UnwrapAngles(Eigen::Ref<Eigen::VectorXd> angles);

}  // namespace mocapedit
