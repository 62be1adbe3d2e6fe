// Offline builder: turns a clip into an additive clip, its difference from a reference pose.
//
// The runtime (LayeringJob with LayerMode::kAdditive) only applies deltas; making them is
// done once per clip and reference pose, here, as ozz-animation's AdditiveAnimationBuilder
// does. Applying an additive layer to a clip that was never converted to deltas is a classic
// bug: the whole layer pose would be added on top of the source.
//
// Per frame f and joint j, with R the reference pose and C the clip:
//   translation delta = C.t - R.t
//   rotation delta    = C.r * inverse(R.r)   (Hamilton product; then normalised and given
//                                             w >= 0, so weighting it takes the short arc)
//   scale delta       = C.s / R.s            (component-wise)
// so that delta * R.r == C.r: the delta added on top of the reference pose at weight 1 gives
// the clip back. The deltas are computed in double from the float inputs, so a frame equal
// to the reference gives exactly (0, 0, 0), (0, 0, 0, 1) and (1, 1, 1).
#pragma once

#include <cstddef>
#include <string>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"

namespace mocapedit {

struct AdditiveClipBuilder {
  std::size_t num_frames = 0;  // #F
  std::size_t num_joints = 0;  // #J
  // #J transforms: the pose subtracted (the clip's first frame, or the skeleton's rest pose).
  ConstPoseStreamView reference;
  // #F * #J transforms, frame-major (frame f, joint j at f * #J + j).
  ConstPoseStreamView clip;
  // #F * #J deltas written by Run(); may be the very same buffers as `clip`.
  PoseStreamView output;

  // Returns when the builder can run. Otherwise throws InvalidInput naming the reason, when:
  //  - reference translations/scales do not hold #J * 3 floats or rotations #J * 4;
  //  - clip or output translations/scales do not hold #F * #J * 3 floats or rotations
  //    #F * #J * 4;
  //  - an output buffer partially overlaps its clip buffer;
  //  - a reference rotation has zero length or is not finite (it has no inverse);
  //  - a reference scale component is zero or not finite (it cannot be divided by).
  void Validate() const;

  // Validates, then writes the deltas to `output`. Throws InvalidInput (output untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
