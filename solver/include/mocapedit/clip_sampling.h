// Sampling a clip's joint transforms between its frames, and finding which (fractional)
// source frame plays at a shot time under a time map.
//
// A clip is #F frames of #J joint-local transforms, stored frame-major: row f * J + j
// holds joint j at frame f. Translations and scales interpolate linearly; rotations by
// normalised shortest-arc slerp. A whole frame returns its stored values bit for bit.
#pragma once

#include <Eigen/Core>

#include "mocapedit/errors.h"

namespace mocapedit {

using Vec3fRows = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
using Quatf4Rows = Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor>;

// Samples a clip at fractional frames.
//
// Inputs:
//   translations  #F*J by 3 joint-local translations
//   rotations     #F*J by 4 unit quaternions (x, y, z, w)
//   scales        #F*J by 3 joint-local scales
//   joints        J, the joint count (> 0)
//   frames        #T fractional frames, clamped to [0, F-1]
// Outputs (allocated by the caller, so a binding can write straight into its arrays):
//   out_translations  #T*J by 3
//   out_rotations     #T*J by 4, unit length
//   out_scales        #T*J by 3
// Throws InvalidInput on inconsistent shapes or non-finite frames.
void SampleClip(const Eigen::Ref<const Vec3fRows>& translations, const Eigen::Ref<const Quatf4Rows>& rotations,
                const Eigen::Ref<const Vec3fRows>& scales, int joints,
                const Eigen::Ref<const Eigen::VectorXd>& frames, Eigen::Ref<Vec3fRows> out_translations,
                Eigen::Ref<Quatf4Rows> out_rotations, Eigen::Ref<Vec3fRows> out_scales);

// The fractional source frame playing at each shot time: the inverse of a time map,
// interpolated linearly between frames and clamped to [0, F-1] outside it.
//
// Inputs:
//   time_map  #F strictly increasing shot times, one per source frame
//   times     #T shot times (any order)
// Returns #T fractional frames; a time equal to time_map[f] gives exactly f.
// Throws InvalidInput when the time map is empty or does not increase.
Eigen::VectorXd FramesAtTimes(const Eigen::Ref<const Eigen::VectorXd>& time_map,
                              const Eigen::Ref<const Eigen::VectorXd>& times);

}  // namespace mocapedit
