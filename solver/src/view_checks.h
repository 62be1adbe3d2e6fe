// Size and aliasing checks shared by the jobs that take pose views (internal).
#pragma once

#include <cstddef>
#include <functional>
#include <string>

#include "mocapedit/layering.h"

namespace mocapedit::detail {

inline bool HasSize(Span<const float> s, std::size_t n) { return s.size == n && (n == 0 || s.data); }

// True when the view holds n transforms: 3 floats per translation and scale, 4 per rotation.
inline bool ViewHasSize(const ConstPoseStreamView& v, std::size_t n) {
  return HasSize(v.translations, n * 3) && HasSize(v.rotations, n * 4) && HasSize(v.scales, n * 3);
}

// True when [a, a + n) and [b, b + n) overlap without being the same range.
inline bool PartialOverlap(const float* a, const float* b, std::size_t n) {
  if (a == b || n == 0) return false;
  std::less<const float*> lt;
  return lt(a, b + n) && lt(b, a + n);
}

inline bool ViewsPartiallyOverlap(const PoseStreamView& out, const ConstPoseStreamView& in) {
  return PartialOverlap(out.translations.data, in.translations.data, in.translations.size) ||
         PartialOverlap(out.rotations.data, in.rotations.data, in.rotations.size) ||
         PartialOverlap(out.scales.data, in.scales.data, in.scales.size);
}

}  // namespace mocapedit::detail
