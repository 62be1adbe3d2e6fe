// Foot locking: two-bone leg IK that holds planted feet in place after every other edit.
//
// Written in the style of ozz-animation's runtime jobs: a job struct whose inputs and
// outputs are non-owning views, a Validate() that lists every failure condition, and a
// Run() that validates and then runs a short, named pipeline per agent:
//
//   BlendTargets -> LowerPelvis (required drop, then eased) -> SolveLegs -> ToLocal
//
// The job works on #A agents at once, each owning a run of poses (its output frames), and
// two legs per pose (hip -> knee -> ankle, each the child of the one before). It knows
// nothing of USD: everything is world space, as numpy arrays. Agents are independent, so
// Run() splits them over threads; a job only reads its inputs and writes its outputs, so
// several jobs may run at once on different outputs.
//
// Layout: #N = offsets[#A] poses, pose-major with 2 legs per pose: positions are #N * 2 * 3
// doubles, rotations #N * 2 * 4 doubles (quaternions x, y, z, w, unit), weights #N * 2.
// Quaternions are Hamilton: a * b rotates by b first, then by a (column vectors); a joint's
// world rotation is parent_world * local.
//
// What the pipeline guarantees:
//  - bone lengths are those of the input pose (only rotations and one pelvis translation
//    change);
//  - the knee bends in the plane of the input pose (of its hinge when nearly straight), to
//    the same side (never backwards), and
//    never straightens with a snap: a reach beyond `soft_reach` of the leg's length (or the
//    input pose's own stretch, if larger) is squeezed smoothly towards `max_reach` (or that
//    stretch, if larger);
//  - the pelvis (every hip of the agent) is lowered along -up only where a leg cannot reach
//    its target, by the least amount, then eased: a running maximum and a running mean over
//    `smooth[a]` frames each side, so the drop never falls short of what is required;
//  - the ankle's world rotation is slerped from the input towards the target rotation by
//    the weight; at weight 0 a leg that the pelvis does not move is left as it is (to
//    rounding).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"  // Span

namespace mocapedit {

struct FootLockJob {
  // #A + 1 increasing pose offsets, offsets[0] = 0: agent a owns poses offsets[a] ..
  // offsets[a + 1] - 1.
  Span<const std::int64_t> offsets;
  // #A: frames over which each agent's pelvis drop eases in and out (>= 0).
  Span<const std::int64_t> smooth;
  // World up, 3 doubles, unit length.
  Span<const double> up;

  // Inputs, per pose and leg (#N * 2 entries): the pose before locking, world space.
  Span<const double> hip;         // positions, 3 each
  Span<const double> knee;
  Span<const double> ankle;
  Span<const double> parent_rot;  // world rotation of the hip's parent, 4 each
  Span<const double> hip_rot;     // world rotations, 4 each
  Span<const double> knee_rot;
  Span<const double> ankle_rot;
  // Where each ankle should be (3 each) and how it should be turned (4 each), and how much of
  // that to reach (#N * 2 weights in [0, 1]): target = ankle + weight * (target - ankle).
  Span<const double> target;
  Span<const double> target_rot;
  Span<const double> weight;
  // The knee's hinge axis in world space (3 each, any length but 0): the normal of its bend
  // plane where the pose is too straight to say (see bend_noise).
  Span<const double> hinge;
  // Optional, #N flags (or empty): poses the pelvis drop must not touch (a stationary range
  // that must keep its shape). The drop is 0 there and eases back in linearly over
  // `smooth[a]` + 1 poses on each side.
  Span<const std::uint8_t> keep;

  double soft_reach = 0.97;   // fraction of a leg's length where the reach starts to soften
  double max_reach = 0.9995;  // fraction of a leg's length never exceeded
  // The knee's plane is the input pose's where the sine of its bend exceeds bend_noise +
  // bend_trust, the hinge's where it is below bend_noise, and a blend in between.
  double bend_noise = 0.05;
  double bend_trust = 0.2;
  int threads = 0;            // 0: up to two, as the machine allows

  // Outputs.
  Span<double> hip_local;    // #N * 2 * 4 joint-local rotations (w >= 0)
  Span<double> knee_local;
  Span<double> ankle_local;
  Span<double> drop;         // #N: how far the pelvis is lowered along -up, world units
  Span<double> reached;      // #N * 2 * 3: world ankle positions after locking

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - offsets is empty, does not start at 0, or decreases; smooth does not hold #A values
  //    or one is negative;
  //  - up does not hold 3 finite values of unit length (to 1e-6);
  //  - an input does not hold #N * 2 entries of its width, or an output #N * 2 (drop: #N);
  //  - a weight is not within [0, 1] (or is NaN); keep is neither empty nor #N flags;
  //  - soft_reach is not within (0, max_reach], or max_reach not within (0, 1); bend_noise is
//    negative or bend_trust not positive;
  //  - an output overlaps an input or another output.
  // #N may be 0 (nothing to do).
  void Validate() const;

  // Validates, then writes every output. Throws InvalidInput (outputs untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
