// Size and aliasing checks shared by the jobs (internal).
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

// True when the `na` bytes at a and the `nb` bytes at b share memory.
inline bool BytesOverlap(const void* a, std::size_t na, const void* b, std::size_t nb) {
  if (na == 0 || nb == 0) return false;
  std::less<const char*> lt;
  const char *ca = static_cast<const char*>(a), *cb = static_cast<const char*>(b);
  return lt(ca, cb + nb) && lt(cb, ca + na);
}

// The same for `na` values at a and `nb` at b.
template <typename A, typename B>
bool Overlap(const A* a, std::size_t na, const B* b, std::size_t nb) {
  return BytesOverlap(a, na * sizeof(A), b, nb * sizeof(B));
}

}  // namespace mocapedit::detail
