// Ground-plane trajectory utilities shared by every solve.
//
// A trajectory is a #N by 2 list of root positions on the ground plane, one row per
// source frame, in stage units. Headings are angles in radians, counter-clockwise about
// the up axis, measured from the ground plane's first axis.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

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
// Returns #N headings. Throws std::invalid_argument on bad shapes or ranges.
Eigen::VectorXd TangentHeadings(const Eigen::Ref<const Trajectory2>& points,
                                const std::vector<FrameRange>& fixed,
                                const Eigen::Ref<const Eigen::VectorXd>& fallback,
                                double min_step);

// Adds multiples of 2*pi so consecutive angles differ by at most pi.
void UnwrapAngles(Eigen::Ref<Eigen::VectorXd> angles);

}  // namespace mocapedit
