#include "mocapedit/additive_clip.h"

#include "view_checks.h"

#include <cmath>
#include <string>

namespace mocapedit {
using detail::ViewHasSize;
using detail::ViewsPartiallyOverlap;

void AdditiveClipBuilder::Validate() const {
  const std::size_t n = num_frames * num_joints;
  if (!ViewHasSize(reference, num_joints))
    throw InvalidInput("AdditiveClipBuilder", "reference must hold one pose of #J = " + std::to_string(num_joints) +
                           " transforms (translations and scales 3 floats each, rotations 4)");
  if (!ViewHasSize(clip, n))
    throw InvalidInput("AdditiveClipBuilder", "clip must hold #F*#J = " + std::to_string(n) + " transforms");
  if (!ViewHasSize(ConstPoseStreamView(output), n))
    throw InvalidInput("AdditiveClipBuilder", "output must hold #F*#J = " + std::to_string(n) + " transforms");
  if (ViewsPartiallyOverlap(output, clip))
    throw InvalidInput("AdditiveClipBuilder", "output partially overlaps clip (only the very same buffers may alias)");
  for (std::size_t j = 0; j < num_joints; ++j) {
    const float* r = &reference.rotations[j * 4];
    const double len2 = double(r[0]) * r[0] + double(r[1]) * r[1] + double(r[2]) * r[2] + double(r[3]) * r[3];
    if (!(len2 > 0.0) || !std::isfinite(len2))
      throw InvalidInput("AdditiveClipBuilder", "reference rotation of joint " + std::to_string(j) +
                             " has zero length or is not finite: it has no inverse");
    for (int k = 0; k < 3; ++k) {
      const float s = reference.scales[j * 3 + k];
      if (s == 0.f || !std::isfinite(s))
        throw InvalidInput("AdditiveClipBuilder", "reference scale of joint " + std::to_string(j) +
                               " is zero or not finite: deltas divide by it");
    }
  }
}

void AdditiveClipBuilder::Run() const {
  Validate();
  for (std::size_t f = 0; f < num_frames; ++f) {
    for (std::size_t j = 0; j < num_joints; ++j) {
      const std::size_t i = f * num_joints + j;
      const float* rt = &reference.translations[j * 3];
      const float* rr = &reference.rotations[j * 4];
      const float* rs = &reference.scales[j * 3];
      for (int k = 0; k < 3; ++k) {
        output.translations[i * 3 + k] = static_cast<float>(double(clip.translations[i * 3 + k]) - rt[k]);
        output.scales[i * 3 + k] = static_cast<float>(double(clip.scales[i * 3 + k]) / rs[k]);
      }
      // c * conjugate(r), in double: products of floats are exact there, so a frame equal to
      // the reference cancels to exactly (0, 0, 0, |r|^2).
      const float* c = &clip.rotations[i * 4];
      const double ax = c[0], ay = c[1], az = c[2], aw = c[3];
      const double bx = -double(rr[0]), by = -double(rr[1]), bz = -double(rr[2]), bw = rr[3];
      double q[4] = {aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz};
      const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      const double sign = q[3] < 0.0 ? -1.0 : 1.0;
      for (int k = 0; k < 4; ++k) output.rotations[i * 4 + k] = static_cast<float>(sign * q[k] / len);
    }
  }
}

}  // namespace mocapedit
