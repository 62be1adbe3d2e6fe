// Forward kinematics: the skeleton-space transforms of some joints of a stream of poses.
//
// Written in the style of ozz-animation's LocalToModelJob: non-owning views in and out, a
// Validate() that lists every failure condition, and a Run() that validates and then, pose by
// pose, composes each needed joint's local matrix (scale, then rotate, then translate) and
// carries it by its parent's skeleton-space matrix. Only the wanted joints and their ancestors
// are composed. mocapedit.geometry.kinematics.skeleton_space_numpy is the same job in numpy.
//
// Matrices are USD's row-vector 4x4 (a point moves as p * M, the translation in the last row;
// a child's skeleton-space matrix is local * parent), 16 doubles row by row. Poses are #T by #C
// joint-local transforms, pose-major (pose t, column c at index t * #C + c): translations
// (x, y, z), rotations as quaternions (x, y, z, w; normalised here), scales (x, y, z), floats.
#pragma once

#include <cstdint>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"  // Span, ConstPoseStreamView

namespace mocapedit {

struct SkeletonSpaceJob {
  // #J parent of each joint, -1 for a root; every parent precedes its children.
  Span<const std::int64_t> parents;
  // #J: the pose column that animates each joint, or -1 where the joint keeps its rest transform.
  Span<const std::int64_t> columns;
  // #J * 16: each joint's rest transform (read only for joints of column -1).
  Span<const double> rest;
  // #T * #C local transforms, and #C.
  ConstPoseStreamView pose;
  std::int64_t pose_columns = 0;
  // #K joints whose skeleton-space matrices are wanted.
  Span<const std::int64_t> joints;

  // Output: #T * #K * 16 doubles, pose-major, joints in the order of `joints`.
  Span<double> matrices;
  // Optional output (or empty): #T * #K * 4, each matrix's rotation as a unit quaternion
  // (x, y, z, w; w >= 0) once its rows' scales are divided out (a mirror carried by the first
  // scale), as mocapedit.solve.layering.trs_from_matrices extracts it.
  Span<double> rotations;

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - parents and columns do not hold #J values, or rest #J * 16; a parent does not precede
  //    its joint; a column is below -1 or not below #C;
  //  - pose_columns is not positive, or a pose view does not hold #T * #C entries of its width
  //    (the same #T for all three);
  //  - a wanted joint is out of range;
  //  - matrices does not hold #T * #K * 16 values, rotations neither 0 nor #T * #K * 4, or an
  //    output overlaps an input or the other output.
  // #T and #K may be 0 (nothing to do).
  void Validate() const;

  // Validates, then writes every output. Throws InvalidInput (outputs untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
