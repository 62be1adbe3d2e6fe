// Animation layering (section 7.1 of the deliverable): blend and additive layers over a
// stream of poses, in each joint's local space.
//
// Written in the style of ozz-animation's BlendingJob: a small job struct whose inputs and
// output are non-owning views, a Validate() that lists every failure condition, and a
// Run() that validates and then runs a short, named pipeline:
//
//   CopySource -> for each layer, in order: BlendLayer | AddLayer
//
// Layers stack: each one applies on top of the result of the ones before it, so the order
// of `layers` matters (a blend layer at weight 1 hides every layer below it on its joints;
// an additive layer above it still adds on top).
//
// Poses are #T by #J joint-local transforms stored pose-major (pose t, joint j at index
// t * #J + j), the memory layout of (T, J, 3) and (T, J, 4) float32 numpy arrays:
// translations (x, y, z), rotations as quaternions (x, y, z, w), scales (x, y, z).
//
// Quaternion conventions: Hamilton product; a * b rotates by b first, then by a (column
// vectors). In USD's row-vector matrices that is R(a * b) = R(b) R(a). The additive delta is
// applied on the left, `slerp(identity, delta, w) * source`, with `delta = layer *
// inverse(reference)` (see additive_clip.h): so at weight 1 a source equal to the reference
// pose becomes exactly the layer pose, and the delta acts in the joint's parent space after
// the source rotation.
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "mocapedit/errors.h"

namespace mocapedit {

// A non-owning view of a contiguous array (a C++17 stand-in for std::span).
template <typename T>
struct Span {
  T* data = nullptr;
  std::size_t size = 0;

  Span() = default;
  Span(T* d, std::size_t n) : data(d), size(n) {}
  template <typename U>
  Span(const Span<U>& other) : data(other.data), size(other.size) {}  // Span<T> -> Span<const T>
  template <typename Container, typename = decltype(std::declval<Container&>().data())>
  Span(Container& c) : data(c.data()), size(c.size()) {}  // std::vector and friends

  T& operator[](std::size_t i) const { return data[i]; }
  bool empty() const { return size == 0; }
  T* begin() const { return data; }
  T* end() const { return data + size; }
};

// Views of #N joint-local transforms (N = #T * #J for a stream of poses, #J for one pose).
struct PoseStreamView {
  Span<float> translations;  // #N by 3
  Span<float> rotations;     // #N by 4 quaternions (x, y, z, w)
  Span<float> scales;        // #N by 3
};

struct ConstPoseStreamView {
  Span<const float> translations;  // #N by 3
  Span<const float> rotations;     // #N by 4 quaternions (x, y, z, w)
  Span<const float> scales;        // #N by 3

  ConstPoseStreamView() = default;
  ConstPoseStreamView(Span<const float> t, Span<const float> r, Span<const float> s)
      : translations(t), rotations(r), scales(s) {}
  ConstPoseStreamView(const PoseStreamView& v)  // NOLINT: a mutable view reads as a const one
      : translations(v.translations), rotations(v.rotations), scales(v.scales) {}
};

enum class LayerMode : int {
  // Interpolates the local transforms from the pose below to the layer's by weight:
  // translations and scales linearly, rotations by normalised shortest-arc slerp.
  kBlend = 0,
  // Adds the layer's delta (made offline by AdditiveClipBuilder) on top, scaled by weight:
  // translation + w * delta, rotation slerp(identity, delta, w) * rotation,
  // scale * (1 + w * (delta - 1)).
  kAdditive = 1,
};

// Applies layers to a stream of #T poses of #J joints.
struct LayeringJob {
  struct Layer {
    LayerMode mode = LayerMode::kAdditive;
    // #T * #J transforms: for kBlend the layer's local transforms; for kAdditive its deltas
    // from its reference pose (AdditiveClipBuilder output). Rotations need not be unit
    // length for kBlend; additive deltas are expected to be unit (the builder makes them so).
    ConstPoseStreamView transforms;
    // #T weights in [0, 1], one per pose: the ease in and out.
    Span<const float> weights;
    // #J per-joint weights in [0, 1] multiplying `weights` (a joint mask, e.g. from
    // SubtreeJointWeights); empty means 1 for every joint. A joint whose weight is 0 is left
    // exactly as it is (joints the layer clip does not animate, joints outside the subtree).
    Span<const float> joint_weights;
  };

  std::size_t num_poses = 0;   // #T
  std::size_t num_joints = 0;  // #J
  // #T * #J source transforms (the time-warped source pose).
  ConstPoseStreamView source;
  // Layers in stacking order: each applies to the result of the ones before it.
  Span<const Layer> layers;
  // #T * #J transforms written by Run(). May be the very same buffers as `source` (in
  // place); any other overlap with `source` is invalid.
  PoseStreamView output;

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - source or output translations/scales do not hold #T * #J * 3 floats, or
  //    rotations #T * #J * 4;
  //  - an output buffer partially overlaps its source buffer (same start is in place: fine);
  //  - a layer's mode is not kBlend or kAdditive;
  //  - a layer's transforms do not hold #T * #J transforms;
  //  - a layer's weights do not hold #T values, or one is not within [0, 1] (or is NaN);
  //  - a layer's joint_weights is neither empty nor #J values, or one is not within [0, 1].
  // #T or #J may be 0 (nothing to do).
  void Validate() const;

  // Validates, then writes the layered poses to `output`. Throws InvalidInput (output untouched) when
  // Validate() does. Poses whose layer weight is 0 and joints whose joint weight is 0
  // are left bit for bit as they were; a blend at weight 1 copies the layer bit for bit; an
  // additive delta of exactly identity leaves its joint bit for bit.
  void Run() const;
};

// #J joint weights: 1 for `root` and every joint below it, 0 for every other joint.
//
// Inputs:
//   parents  #J parent index of each joint, -1 for a root; every parent precedes its
//            children (UsdSkel's joint order)
//   root     joint at the top of the subtree, or -1 for the whole skeleton
// Throws InvalidInput when a parent does not precede its child or `root` is out of
// range.
std::vector<float> SubtreeJointWeights(Span<const int> parents, int root);

// Normalised shortest-arc slerp of two quaternions (x, y, z, w) by t in [0, 1], the kernel
// the job uses (Eberly's polynomial slerp, no trigonometry; each component within 5e-7 of
// exact slerp on unit float quaternions). t = 0 gives a (normalised), t = 1 gives b with the
// sign that puts it on a's side, bit for bit.
void Slerp(const float a[4], const float b[4], float t, float out[4]);

}  // namespace mocapedit
