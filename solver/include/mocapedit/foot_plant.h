// Foot plants: where each planted foot goes while an edit drags the body, and how much of it
// the legs reach, for many agents at once (the targets of FootLockJob).
//
// Written in the style of ozz-animation's runtime jobs, like FootLockJob: non-owning views in
// and out, a Validate() that lists every failure condition, and a Run() that validates and
// then runs a short, named pipeline per agent and leg:
//
//   Contacts (one row per contact, over the frames its ramp reaches) -> Leash (turn, then
//   ground shift) -> Replant (steps where a leashed foot would slide) -> Blend (targets and
//   weights)
//
// Each contact of the source clip gets one plant: the source foot carried by one turn about
// up and one ground shift, chosen where the edit puts the foot (least squares), turned about
// the planted foot itself. While the edited foot stays within a leash of the plant (as far as
// the leg reaches with the pelvis lowered a little, from `leash_m` to `max_leash_m` times the
// agent's `reach_leash`, and
// `leash_degrees` times the agent's `turn_leash` of turn) the plant stays put; beyond, it follows at the leash's length, from
// the start that slides least (frames inside a stationary range keep the plant, which is
// followed outwards from them). Where a leashed plant would slide further than `step_slide_m`
// (or turn further than `step_slide_degrees`) and the other foot bears the weight, the foot
// steps instead: it lifts by `step_height_m`, moves to where the body now is and is set down,
// in `step_seconds` to `step_longest_seconds`, moving the foot against its hip no faster than
// `step_foot_speed_ratio` times the source's fastest, turning it and bending the knee no faster
// than the source's fastest, or a calm step's pace where the source holds the leg nearly still
// (the step_min_ speeds), times the agent's `stretch`. A lock eases in and out over `blend` frames before and
// after its contact (longer where the plant lies further than `leash_m` from the edited foot),
// and where the ramps of two contacts meet their plants blend by weight.
//
// mocapedit.solve.footplant.plan_feet_numpy is the same job in numpy, contact rows and all;
// the tests compare the two. Agents are independent, so Run() splits them over threads.
//
// Layout: #N = offsets[#A] poses, agent after agent, two legs per pose: positions are
// #N * 2 * 3 doubles, rotations #N * 2 * 4 (unit quaternions x, y, z, w; Hamilton: a * b
// rotates by b, then a), per-pose values #N. Lengths are stage units except those named `_m`
// (metres; divided by `meters_per_unit`).
#pragma once

#include <cstddef>
#include <cstdint>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"  // Span

namespace mocapedit {

struct FootPlantJob {
  // #A + 1 increasing pose offsets, offsets[0] = 0: agent a owns poses offsets[a] .. offsets[a + 1] - 1.
  Span<const std::int64_t> offsets;
  // Per pose (#N): the (fractional) source frame it plays, its time in seconds, whether it lies
  // inside a stationary range of the source (0 or 1), and the edit's turn of the body about up
  // (radians, counter-clockwise).
  Span<const double> frames;
  Span<const double> seconds;
  Span<const std::uint8_t> stationary;
  Span<const double> turn;
  // Per pose and leg, world space, as edited: the leg's joints and the ankle's rotation.
  Span<const double> hip, knee, ankle;  // 3 each
  Span<const double> ankle_rot;         // 4 each
  // Per pose and leg, world space, the source as posed before the edit's ground motion.
  Span<const double> source_hip, source_ankle;                         // 3 each
  Span<const double> source_hip_rot, source_knee_rot, source_ankle_rot;  // 4 each
  // #2A + 1 increasing offsets into the contacts, contact_offsets[0] = 0: leg k of agent a owns
  // contacts contact_offsets[2a + k] .. contact_offsets[2a + k + 1] - 1. Each contact is two
  // doubles: its first and last source frame (inclusive). A contact on none of the agent's
  // poses is left out.
  Span<const std::int64_t> contact_offsets;
  Span<const double> contacts;
  // #A: frames a lock eases in and out over, at least (> 0).
  Span<const double> blend;
  // #A * 2: how many times longer each leg's steps are made (> 0; 1 as planned).
  Span<const double> stretch;
  // #A: how many times leash_degrees each agent's plants may lag the edited foot's turn (> 0;
  // 1 as planned).
  Span<const double> turn_leash;
  // #A: how many times max_leash_m each agent's plants may lie from where the edit puts the
  // foot, where its leg reaches (>= 1; 1 as planned).
  Span<const double> reach_leash;
  // #A: how many times max_leash_m a foot may lie from its plant before it steps (>= 1; above
  // reach_leash counts as reach_leash). Below reach_leash, a foot steps as at that shorter
  // leash, and only where it cannot step is its plant held as far as reach_leash lets it (a
  // body dragged faster than one foot at a time can step).
  Span<const double> step_leash;
  // World up, 3 doubles: +Y (0, 1, 0) or +Z (0, 0, 1). The plant's turn is about it.
  Span<const double> up;

  double meters_per_unit = 1.0;
  double leash_m = 0.08;              // a plant always lies this close to the edited foot
  double max_leash_m = 0.15;          // ... and never further, however far the leg reaches
  double max_drop_m = 0.08;           // the pelvis lowering the leash counts on
  double leash_degrees = 15.0;        // a plant's turn away from the edited foot's
  double soft_reach = 0.97;           // fraction of a leg's length it reaches comfortably
  double step_slide_m = 0.05;         // a foot steps through contacts that slide further
  double step_slide_degrees = 10.0;   // ... or turn further
  double step_seconds = 0.3;          // the shortest step
  double step_longest_seconds = 1.5;  // the longest step
  double step_height_m = 0.05;        // how far a stepping foot lifts
  // A step moves the foot against its hip at most step_foot_speed_ratio times as fast as the
  // source ever does, turns the foot and bends the knee at most as fast as the source ever
  // does; where the source holds a leg nearly still (an idle), at least as fast as a calm step:
  // step_min_foot_speed_m metres per second, step_min_turn_speed and step_min_knee_speed
  // radians per second.
  double step_foot_speed_ratio = 2.0;
  double step_min_foot_speed_m = 1.0;
  double step_min_turn_speed = 1.5;
  double step_min_knee_speed = 2.0;
  double trigger = 0.6;  // a planted foot steps once the edited foot lies this much of the leash away
  double lead = 0.5;     // ... and lands this much of the leash ahead of where the body drifts
  int threads = 0;       // 0: up to two, as the machine allows

  // Outputs, per pose and leg.
  Span<double> target;           // 3 each: the planted ankle (the edited ankle where weight is 0)
  Span<double> target_rot;       // 4 each: its rotation (the edited ankle's where weight is 0)
  Span<double> weight;           // 1 each, in [0, 1]: how much of the plant the leg reaches
  Span<std::uint8_t> stepping;   // 1 each: the foot is stepping (in the air)
  Span<std::int64_t> steps;      // #A: steps each agent takes

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - offsets is empty, does not start at 0, or decreases;
  //  - frames, seconds, stationary or turn do not hold #N values; a pose or leg input does not
  //    hold #N * 2 entries of its width; a frame, second or turn is not finite;
  //  - contact_offsets does not hold #2A + 1 values, does not start at 0, decreases, or does
  //    not end at the contacts' count; contacts is not 2 doubles each, or a frame is not finite;
  //  - blend, stretch or turn_leash do not hold #A (#A * 2, #A) finite positive values, or
  //    reach_leash or step_leash #A finite values of at least 1;
  //  - up is neither +Y nor +Z;
  //  - meters_per_unit, leash_m, leash_degrees, soft_reach, step_seconds are not positive, or
  //    soft_reach is above 1, max_leash_m below leash_m, step_longest_seconds below
  //    step_seconds, max_drop_m, step_slide_m, step_slide_degrees, step_height_m,
  //    step_min_foot_speed_m, step_min_turn_speed or step_min_knee_speed negative, trigger,
  //    lead or step_foot_speed_ratio not positive (any of them not finite);
  //  - an output does not hold #N * 2 entries of its width (steps: #A), or overlaps an input or
  //    another output.
  // #N and #A may be 0 (nothing to do).
  void Validate() const;

  // Validates, then writes every output. Throws InvalidInput (outputs untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
