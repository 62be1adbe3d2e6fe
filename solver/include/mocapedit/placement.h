// Placement: skeleton-space points and rotations of a stream of poses carried into the world by
// each pose's placement, and on by an edit's ground motion (a turn about up, then a shift).
//
// Written in the style of ozz-animation's runtime jobs: non-owning views in and out, a
// Validate() that lists every failure condition, and a Run() that validates and then, pose by
// pose, writes:
//
//   source point   = point * placement            (row vectors; 4x4 row-vector matrices)
//   edited point   = source point * motion
//   source rotation = placement_rotation * rotation (Hamilton: a * b rotates by b, then a)
//   edited rotation = turn * source rotation, turn the quaternion of `turn` radians about up
//
// with the terms summed in the order numpy's mocapedit.geometry.kinematics.transform_points and
// mocapedit.solve.layering.quat_multiply sum them, so the two round alike. Quaternions are
// (x, y, z, w).
#pragma once

#include <cstdint>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"  // Span

namespace mocapedit {

struct PlacementJob {
  // Per pose (#N): the placement (16 doubles, row-vector, translation in the last row) and its
  // rotation (4), the edit's ground motion (16) and its turn about up (radians).
  Span<const double> placement;
  Span<const double> placement_rotation;
  Span<const double> motion;
  Span<const double> turn;
  // World up, 3 doubles, unit length.
  Span<const double> up;
  // #N * #P points (3 each) and #N * #Q rotations (4 each), skeleton space, pose-major.
  Span<const double> points;
  Span<const double> rotations;
  std::int64_t point_count = 0;     // #P
  std::int64_t rotation_count = 0;  // #Q

  // Outputs, laid out as the inputs.
  Span<double> source_points, edited_points;
  Span<double> source_rotations, edited_rotations;

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - point_count or rotation_count is negative;
  //  - placement, placement_rotation, motion or turn do not hold #N entries of their width (#N
  //    from turn); up does not hold 3 values of unit length (to 1e-6);
  //  - points do not hold #N * #P * 3 values, or rotations #N * #Q * 4;
  //  - an output does not hold as many values as its input, or overlaps an input or another output.
  void Validate() const;

  // Validates, then writes every output. Throws InvalidInput (outputs untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
