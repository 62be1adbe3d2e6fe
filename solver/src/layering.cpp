#include "mocapedit/layering.h"
#include "mocapedit/errors.h"

#include "view_checks.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace mocapedit {
namespace {

using detail::HasSize;
using detail::ViewHasSize;
using detail::ViewsPartiallyOverlap;

// ---- slerp without trigonometry -------------------------------------------------------
//
// D. Eberly, "A Fast and Accurate Algorithm for Computing SLERP" (JGT 2011):
//   sin(t*theta) / sin(theta) = t * sum_i P_i(t) (x - 1)^i,  x = cos(theta) in [0, 1],
//   P_0 = 1, P_i = prod_{k<=i} (t^2 - k^2) / (k (2k + 1)),
// truncated after kTerms terms with the last factor scaled by kMu to balance the error. With
// 16 terms and kMu fitted over t, x in [0, 1], the coefficient is within 3.1e-8 of exact in
// double (1.5e-7 in float). The coefficients depend on t only, so for a weight shared by many
// joints they are computed once per pose.
constexpr int kTerms = 16;
constexpr double kMu = 1.9166674358140934;

struct SlerpWeights {
  float t = 0.f, d = 1.f;      // weight of the second quaternion, and of the first (1 - t)
  float pt[kTerms + 1] = {};   // P_i(t)
  float pd[kTerms + 1] = {};   // P_i(1 - t)
};

// P_i(t) = P_{i-1}(t) * (u_i t^2 - v_i) with u_i = 1 / (i (2i + 1)), v_i = i / (2i + 1).
struct EberlyTable {
  float u[kTerms + 1] = {}, v[kTerms + 1] = {};
  constexpr EberlyTable() {
    for (int k = 1; k <= kTerms; ++k) {
      const double scale = k == kTerms ? kMu : 1.0;
      u[k] = static_cast<float>(scale / (k * (2.0 * k + 1.0)));
      v[k] = static_cast<float>(scale * k / (2.0 * k + 1.0));
    }
  }
};
constexpr EberlyTable kEberly;

// At t = 1 the first factor is u_1 - v_1 = 0 exactly, so P_i(1) = (1, 0, 0, ...).
void Coefficients(float t, float* p) {
  float acc = 1.f;
  p[0] = 1.f;
  for (int k = 1; k <= kTerms; ++k) {
    acc *= kEberly.u[k] * (t * t) - kEberly.v[k];
    p[k] = acc;
  }
}

SlerpWeights MakeSlerpWeights(float t) {
  SlerpWeights w;
  w.t = t;
  w.d = 1.f - t;
  Coefficients(w.t, w.pt);
  Coefficients(w.d, w.pd);
  return w;
}

// ---- the rotation kernel, on lanes of joints ---------------------------------------
//
// Quaternions are gathered from the (x, y, z, w) arrays into lanes, one vector per component,
// so the polynomial (a long chain of dependent multiply-adds for one joint) runs on kLanes
// joints side by side. The vectors are GCC/Clang vector types of W floats: plain arithmetic
// on them compiles to SIMD on every target. The kernel is built for 8-float vectors with AVX2
// and for 4-float vectors for the baseline; the first call picks one for the machine. Both do
// the same IEEE operations in the same order (no FMA contraction), so both give the same bits.
constexpr int kLanes = 16;

#define MOCAPEDIT_INLINE inline __attribute__((always_inline))
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MOCAPEDIT_AVX2 1
#endif
#if defined(__GNUC__) && !defined(__clang__)
// Vectors never cross a call boundary (the helpers are all inlined): their ABI does not matter.
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

template <int W>
struct Vec {
  typedef float F __attribute__((vector_size(4 * W)));
  typedef int I __attribute__((vector_size(4 * W)));
};

template <typename F, typename I>
MOCAPEDIT_INLINE F Select(I mask, F a, F b) {  // mask ? a : b, lane by lane
  return reinterpret_cast<F>((reinterpret_cast<I>(a) & mask) | (reinterpret_cast<I>(b) & ~mask));
}

template <typename F>
MOCAPEDIT_INLINE F LoadVec(const float* p) {
  F v;
  std::memcpy(&v, p, sizeof(F));
  return v;
}

template <typename F>
MOCAPEDIT_INLINE void StoreVec(float* p, const F& v) {
  std::memcpy(p, &v, sizeof(F));
}

// W quaternions (4 W floats, x y z w each) to component vectors and back, by in-lane
// shuffles. With W = 8 the lanes come out in the order 0 2 4 6 1 3 5 7; Untranspose undoes
// exactly what Transpose does and every lane is computed on its own, so that does not matter.
template <typename F>
MOCAPEDIT_INLINE void Transpose(const float* q, F& x, F& y, F& z, F& w) {
  constexpr int W = sizeof(F) / sizeof(float);
  const F r0 = LoadVec<F>(q), r1 = LoadVec<F>(q + W), r2 = LoadVec<F>(q + 2 * W), r3 = LoadVec<F>(q + 3 * W);
  if constexpr (W == 4) {
    const F t0 = __builtin_shufflevector(r0, r1, 0, 4, 1, 5), t1 = __builtin_shufflevector(r0, r1, 2, 6, 3, 7);
    const F t2 = __builtin_shufflevector(r2, r3, 0, 4, 1, 5), t3 = __builtin_shufflevector(r2, r3, 2, 6, 3, 7);
    x = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
    y = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
    z = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
    w = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
  } else {
    const F t0 = __builtin_shufflevector(r0, r1, 0, 8, 1, 9, 4, 12, 5, 13);
    const F t1 = __builtin_shufflevector(r0, r1, 2, 10, 3, 11, 6, 14, 7, 15);
    const F t2 = __builtin_shufflevector(r2, r3, 0, 8, 1, 9, 4, 12, 5, 13);
    const F t3 = __builtin_shufflevector(r2, r3, 2, 10, 3, 11, 6, 14, 7, 15);
    x = __builtin_shufflevector(t0, t2, 0, 1, 8, 9, 4, 5, 12, 13);
    y = __builtin_shufflevector(t0, t2, 2, 3, 10, 11, 6, 7, 14, 15);
    z = __builtin_shufflevector(t1, t3, 0, 1, 8, 9, 4, 5, 12, 13);
    w = __builtin_shufflevector(t1, t3, 2, 3, 10, 11, 6, 7, 14, 15);
  }
}

template <typename F>
MOCAPEDIT_INLINE void Untranspose(const F& x, const F& y, const F& z, const F& w, float* q) {
  constexpr int W = sizeof(F) / sizeof(float);
  if constexpr (W == 4) {
    const F t0 = __builtin_shufflevector(x, y, 0, 4, 1, 5), t1 = __builtin_shufflevector(z, w, 0, 4, 1, 5);
    const F t2 = __builtin_shufflevector(x, y, 2, 6, 3, 7), t3 = __builtin_shufflevector(z, w, 2, 6, 3, 7);
    StoreVec(q, F(__builtin_shufflevector(t0, t1, 0, 1, 4, 5)));
    StoreVec(q + 4, F(__builtin_shufflevector(t0, t1, 2, 3, 6, 7)));
    StoreVec(q + 8, F(__builtin_shufflevector(t2, t3, 0, 1, 4, 5)));
    StoreVec(q + 12, F(__builtin_shufflevector(t2, t3, 2, 3, 6, 7)));
  } else {
    const F t0 = __builtin_shufflevector(x, y, 0, 1, 8, 9, 4, 5, 12, 13);
    const F t2 = __builtin_shufflevector(x, y, 2, 3, 10, 11, 6, 7, 14, 15);
    const F t1 = __builtin_shufflevector(z, w, 0, 1, 8, 9, 4, 5, 12, 13);
    const F t3 = __builtin_shufflevector(z, w, 2, 3, 10, 11, 6, 7, 14, 15);
    StoreVec(q, F(__builtin_shufflevector(t0, t1, 0, 2, 8, 10, 4, 6, 12, 14)));
    StoreVec(q + 8, F(__builtin_shufflevector(t0, t1, 1, 3, 9, 11, 5, 7, 13, 15)));
    StoreVec(q + 16, F(__builtin_shufflevector(t2, t3, 0, 2, 8, 10, 4, 6, 12, 14)));
    StoreVec(q + 24, F(__builtin_shufflevector(t2, t3, 1, 3, 9, 11, 5, 7, 13, 15)));
  }
}

template <int W>
struct QuatLanes {
  typedef typename Vec<W>::F F;
  static constexpr int kVectors = kLanes / W;
  F x[kVectors], y[kVectors], z[kVectors], w[kVectors];

  // Gathers the quaternions of joints js[0..count) (count <= kLanes) from an (x, y, z, w)
  // array; unused lanes hold identity. W consecutive joints load straight from the array.
  MOCAPEDIT_INLINE void Gather(const float* quats, const int* js, int count) {
    for (int v = 0; v < kVectors; ++v) {
      const int first = v * W, n = std::min(W, count - first);
      if (n == W && js[first + W - 1] == js[first] + W - 1) {
        Transpose(quats + js[first] * 4, x[v], y[v], z[v], w[v]);
        continue;
      }
      alignas(32) float q[4 * W];
      for (int l = 0; l < W; ++l) {
        if (l < n) {
          std::memcpy(q + l * 4, quats + js[first + l] * 4, 4 * sizeof(float));
        } else {
          q[l * 4] = q[l * 4 + 1] = q[l * 4 + 2] = 0.f;
          q[l * 4 + 3] = 1.f;
        }
      }
      Transpose(q, x[v], y[v], z[v], w[v]);
    }
  }

  MOCAPEDIT_INLINE void Scatter(float* quats, const int* js, int count) const {
    for (int v = 0; v < kVectors; ++v) {
      const int first = v * W, n = std::min(W, count - first);
      if (n <= 0) break;
      if (n == W && js[first + W - 1] == js[first] + W - 1) {
        Untranspose(x[v], y[v], z[v], w[v], quats + js[first] * 4);
        continue;
      }
      alignas(32) float q[4 * W];
      Untranspose(x[v], y[v], z[v], w[v], q);
      for (int l = 0; l < n; ++l) std::memcpy(quats + js[first + l] * 4, q + l * 4, 4 * sizeof(float));
    }
  }

  MOCAPEDIT_INLINE void FillIdentity() {
    for (int v = 0; v < kVectors; ++v) {
      x[v] = y[v] = z[v] = F{};
      w[v] = F{} + 1.f;
    }
  }
};

// out = slerp(a, b, t) on the short arc, lane by lane, normalised. At t == 1 the result is b
// (with the sign that puts it on a's side), not renormalised, so it stays bit for bit. For
// a == b == identity the result is exactly identity.
template <int W>
MOCAPEDIT_INLINE void SlerpLanes(const QuatLanes<W>& a, const QuatLanes<W>& b, const SlerpWeights& sw,
                                 QuatLanes<W>& out) {
  typedef typename Vec<W>::F F;
  typedef typename Vec<W>::I I;
  for (int v = 0; v < QuatLanes<W>::kVectors; ++v) {
    const F dot = a.x[v] * b.x[v] + a.y[v] * b.y[v] + a.z[v] * b.z[v] + a.w[v] * b.w[v];
    const I negative = dot < 0.f;
    if (sw.t == 1.f) {  // P_i(1) = (1, 0, 0, ...) and 1 - t = 0: the polynomial is not needed
      const F sign = Select(negative, F{} - 1.f, F{} + 1.f);
      out.x[v] = sign * b.x[v];
      out.y[v] = sign * b.y[v];
      out.z[v] = sign * b.z[v];
      out.w[v] = sign * b.w[v];
      continue;
    }
    const F x = Select(negative, -dot, dot);
    // |a.b| may exceed 1 by rounding (or for quaternions that are not quite unit).
    const F xm1 = Select(x < 1.f, x, F{} + 1.f) - 1.f;
    F ht = F{} + sw.pt[kTerms], hd = F{} + sw.pd[kTerms];
    for (int k = kTerms - 1; k >= 0; --k) {
      ht = ht * xm1 + sw.pt[k];
      hd = hd * xm1 + sw.pd[k];
    }
    const F ct = Select(negative, F{} - sw.t, F{} + sw.t) * ht, cd = sw.d * hd;
    const F qx = cd * a.x[v] + ct * b.x[v], qy = cd * a.y[v] + ct * b.y[v];
    const F qz = cd * a.z[v] + ct * b.z[v], qw = cd * a.w[v] + ct * b.w[v];
    // One division: for q = (0, 0, 0, s) with s within an ulp of 1 (identity slerped with
    // identity), s * (1 / sqrt(s * s)) is still exactly 1.
    F n = qx * qx + qy * qy + qz * qz + qw * qw;
    for (int l = 0; l < W; ++l) n[l] = std::sqrt(n[l]);
    const F inv = 1.f / n;
    out.x[v] = qx * inv;
    out.y[v] = qy * inv;
    out.z[v] = qz * inv;
    out.w[v] = qw * inv;
  }
}

// out = a * b (Hamilton product: rotate by b, then by a), lane by lane.
template <int W>
MOCAPEDIT_INLINE void MultiplyLanes(const QuatLanes<W>& a, const QuatLanes<W>& b, QuatLanes<W>& out) {
  typedef typename Vec<W>::F F;
  for (int v = 0; v < QuatLanes<W>::kVectors; ++v) {
    const F x = a.w[v] * b.x[v] + a.x[v] * b.w[v] + a.y[v] * b.z[v] - a.z[v] * b.y[v];
    const F y = a.w[v] * b.y[v] - a.x[v] * b.z[v] + a.y[v] * b.w[v] + a.z[v] * b.x[v];
    const F z = a.w[v] * b.z[v] + a.x[v] * b.y[v] - a.y[v] * b.x[v] + a.z[v] * b.w[v];
    const F w = a.w[v] * b.w[v] - a.x[v] * b.x[v] - a.y[v] * b.y[v] - a.z[v] * b.z[v];
    out.x[v] = x;
    out.y[v] = y;
    out.z[v] = z;
    out.w[v] = w;
  }
}

// rotations[j] = slerp(identity, deltas[j], w) * rotations[j] for joints js[0..count).
template <int W>
MOCAPEDIT_INLINE void AddRotations(const float* deltas, float* rotations, const int* js, int count,
                                   const SlerpWeights& sw) {
  QuatLanes<W> identity, delta, source;
  identity.FillIdentity();
  delta.Gather(deltas, js, count);
  source.Gather(rotations, js, count);
  SlerpLanes(identity, delta, sw, delta);
  MultiplyLanes(delta, source, source);
  source.Scatter(rotations, js, count);
}

// rotations[j] = slerp(rotations[j], layer[j], w) for joints js[0..count).
template <int W>
MOCAPEDIT_INLINE void BlendRotations(const float* layer, float* rotations, const int* js, int count,
                                     const SlerpWeights& sw) {
  QuatLanes<W> from, to;
  from.Gather(rotations, js, count);
  to.Gather(layer, js, count);
  SlerpLanes(from, to, sw, from);
  from.Scatter(rotations, js, count);
}

struct RotationKernels {
  void (*add)(const float*, float*, const int*, int, const SlerpWeights&);
  void (*blend)(const float*, float*, const int*, int, const SlerpWeights&);
};

void AddRotations4(const float* d, float* r, const int* js, int n, const SlerpWeights& sw) {
  AddRotations<4>(d, r, js, n, sw);
}
void BlendRotations4(const float* l, float* r, const int* js, int n, const SlerpWeights& sw) {
  BlendRotations<4>(l, r, js, n, sw);
}
#ifdef MOCAPEDIT_AVX2
__attribute__((target("avx2"))) void AddRotations8(const float* d, float* r, const int* js, int n,
                                                   const SlerpWeights& sw) {
  AddRotations<8>(d, r, js, n, sw);
}
__attribute__((target("avx2"))) void BlendRotations8(const float* l, float* r, const int* js, int n,
                                                     const SlerpWeights& sw) {
  BlendRotations<8>(l, r, js, n, sw);
}
#endif

// The kernels for this machine; MOCAPEDIT_NO_AVX2=1 in the environment forces the baseline.
const RotationKernels& Kernels() {
  static const RotationKernels kernels = [] {
#ifdef MOCAPEDIT_AVX2
    __builtin_cpu_init();
    const char* no_avx2 = std::getenv("MOCAPEDIT_NO_AVX2");
    if (__builtin_cpu_supports("avx2") && !(no_avx2 && std::string(no_avx2) == "1"))
      return RotationKernels{AddRotations8, BlendRotations8};
#endif
    return RotationKernels{AddRotations4, BlendRotations4};
  }();
  return kernels;
}

// ---- the pipeline ---------------------------------------------------------------------

bool InUnitRange(float v) { return v >= 0.f && v <= 1.f; }  // false for NaN

void CopySource(const LayeringJob& job) {
  auto copy = [](Span<const float> from, Span<float> to) {
    if (from.size && from.data != to.data) std::memcpy(to.data, from.data, from.size * sizeof(float));
  };
  copy(job.source.translations, job.output.translations);
  copy(job.source.rotations, job.output.rotations);
  copy(job.source.scales, job.output.scales);
}

// The joints a layer touches, grouped by joint weight: joints at joint weight 1 (all of
// them without a joint mask; the subtree of a 0/1 mask) take the pose's layer weight and share
// one set of slerp coefficients per pose, and are also listed as runs of consecutive joints,
// which UsdSkel's parent-first order makes of a subtree. Joints at a fractional joint weight
// get their own coefficients; joints at joint weight 0 are not touched.
struct LayerJoints {
  std::vector<int> uniform;                       // joints at joint weight 1
  std::vector<std::pair<int, int>> runs;          // the same joints as [begin, end) ranges
  std::vector<std::pair<int, float>> fractional;  // (joint, joint weight)

  LayerJoints(const LayeringJob::Layer& layer, std::size_t num_joints) {
    for (std::size_t j = 0; j < num_joints; ++j) {
      const int joint = static_cast<int>(j);
      const float jw = layer.joint_weights.empty() ? 1.f : layer.joint_weights[j];
      if (jw == 1.f) {
        if (!runs.empty() && runs.back().second == joint)
          ++runs.back().second;
        else
          runs.emplace_back(joint, joint + 1);
        uniform.push_back(joint);
      } else if (jw != 0.f) {
        fractional.emplace_back(joint, jw);
      }
    }
  }

  // Calls `vec3(begin, end, weight)` on runs of joints that share a weight, in floats.
  template <typename Fn>
  void ForRuns(float w, Fn&& vec3) const {
    for (const auto& [b, e] : runs) vec3(b * 3, e * 3, w);
    for (const auto& [j, jw] : fractional) vec3(j * 3, j * 3 + 3, w * jw);
  }

  // Calls `rotate(joints, count, slerp weights)` on lanes of at most kLanes joints;
  // `with_uniform` false leaves out the joints at joint weight 1.
  template <typename Fn>
  void ForLanes(float w, bool with_uniform, Fn&& rotate) const {
    const SlerpWeights pose_weights = MakeSlerpWeights(w);
    for (std::size_t i = 0; with_uniform && i < uniform.size(); i += kLanes) {
      const int count = static_cast<int>(std::min<std::size_t>(kLanes, uniform.size() - i));
      rotate(&uniform[i], count, pose_weights);
    }
    for (const auto& [j, jw] : fractional) rotate(&j, 1, MakeSlerpWeights(w * jw));
  }
};

// One pose of a layer and of the output: pointers to its #J transforms.
struct PoseSlice {
  const float *t, *r, *s;  // the layer's (blend) or its deltas (additive)
  float *out_t, *out_r, *out_s;
};

// Calls fn(weight, slice) for every pose whose layer weight is not 0.
template <typename Fn>
void ForWeightedPoses(const LayeringJob& job, const LayeringJob::Layer& layer, Fn&& fn) {
  for (std::size_t t = 0; t < job.num_poses; ++t) {
    const float w = layer.weights[t];
    if (w == 0.f) continue;
    const std::size_t base = t * job.num_joints;
    fn(w, PoseSlice{&layer.transforms.translations[base * 3], &layer.transforms.rotations[base * 4],
                    &layer.transforms.scales[base * 3], &job.output.translations[base * 3],
                    &job.output.rotations[base * 4], &job.output.scales[base * 3]});
  }
}

void BlendLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const LayerJoints joints(layer, job.num_joints);
  const RotationKernels& kernels = Kernels();
  ForWeightedPoses(job, layer, [&](float w, const PoseSlice& p) {
    joints.ForRuns(w, [&](int begin, int end, float wj) {
      // (1 - w) a + w b: exactly a at 0 and exactly b at 1.
      const float vd = 1.f - wj;
      for (int i = begin; i < end; ++i) p.out_t[i] = vd * p.out_t[i] + wj * p.t[i];
      for (int i = begin; i < end; ++i) p.out_s[i] = vd * p.out_s[i] + wj * p.s[i];
    });
    if (w == 1.f)  // the layer's rotations, bit for bit, on the joints at the full weight
      for (const auto& [b, e] : joints.runs) std::memcpy(p.out_r + b * 4, p.r + b * 4, (e - b) * 4 * sizeof(float));
    joints.ForLanes(w, w != 1.f, [&](const int* js, int count, const SlerpWeights& sw) {
      kernels.blend(p.r, p.out_r, js, count, sw);
    });
  });
}

void AddLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const LayerJoints joints(layer, job.num_joints);
  const RotationKernels& kernels = Kernels();
  ForWeightedPoses(job, layer, [&](float w, const PoseSlice& p) {
    joints.ForRuns(w, [&](int begin, int end, float wj) {
      for (int i = begin; i < end; ++i) p.out_t[i] += wj * p.t[i];
      for (int i = begin; i < end; ++i) p.out_s[i] *= 1.f + wj * (p.s[i] - 1.f);
    });
    // slerp(identity, delta, w) * rotation
    joints.ForLanes(w, true, [&](const int* js, int count, const SlerpWeights& sw) {
      kernels.add(p.r, p.out_r, js, count, sw);
    });
  });
}

}  // namespace

void Slerp(const float a[4], const float b[4], float t, float out[4]) {
  const int joint = 0;
  float q[4] = {a[0], a[1], a[2], a[3]};
  Kernels().blend(b, q, &joint, 1, MakeSlerpWeights(t));
  std::memcpy(out, q, sizeof(q));
}

void LayeringJob::Validate() const {
  const std::size_t n = num_poses * num_joints;
  if (!ViewHasSize(source, n))
    throw InvalidInput("LayeringJob", "source must hold #T*#J = " + std::to_string(n) +
                           " transforms (translations and scales 3 floats each, rotations 4)");
  if (!ViewHasSize(ConstPoseStreamView(output), n))
    throw InvalidInput("LayeringJob", "output must hold #T*#J = " + std::to_string(n) + " transforms");
  if (ViewsPartiallyOverlap(output, source))
    throw InvalidInput("LayeringJob", "output partially overlaps source (only the very same buffers may alias)");
  for (std::size_t l = 0; l < layers.size; ++l) {
    const Layer& layer = layers[l];
    const std::string which = "layer " + std::to_string(l) + ": ";
    if (layer.mode != LayerMode::kBlend && layer.mode != LayerMode::kAdditive)
      throw InvalidInput("LayeringJob", which + "mode must be blend or additive");
    if (!ViewHasSize(layer.transforms, n))
      throw InvalidInput("LayeringJob", which + "transforms must hold #T*#J = " + std::to_string(n) + " transforms");
    if (!HasSize(layer.weights, num_poses))
      throw InvalidInput("LayeringJob", which + "weights must hold one value per pose (" + std::to_string(num_poses) +
                             "), got " + std::to_string(layer.weights.size));
    for (std::size_t t = 0; t < num_poses; ++t)
      if (!InUnitRange(layer.weights[t]))
        throw InvalidInput("LayeringJob", which + "weight of pose " + std::to_string(t) + " is " +
                               std::to_string(layer.weights[t]) + ", outside [0, 1]");
    if (!layer.joint_weights.empty() && !HasSize(layer.joint_weights, num_joints))
      throw InvalidInput("LayeringJob", which + "joint_weights must be empty or hold one value per joint (" +
                             std::to_string(num_joints) + "), got " +
                             std::to_string(layer.joint_weights.size));
    for (std::size_t j = 0; j < layer.joint_weights.size; ++j)
      if (!InUnitRange(layer.joint_weights[j]))
        throw InvalidInput("LayeringJob", which + "joint weight of joint " + std::to_string(j) + " is " +
                               std::to_string(layer.joint_weights[j]) + ", outside [0, 1]");
  }
}

void LayeringJob::Run() const {
  Validate();
  CopySource(*this);
  for (const Layer& layer : layers) {
    if (layer.mode == LayerMode::kBlend)
      BlendLayer(*this, layer);
    else
      AddLayer(*this, layer);
  }
}

std::vector<float> SubtreeJointWeights(Span<const int> parents, int root) {
  const int n = static_cast<int>(parents.size);
  if (root < -1 || root >= n)
    throw InvalidInput("SubtreeJointWeights", "root " + std::to_string(root) +
                                " is not a joint index (0.." + std::to_string(n - 1) + ") or -1");
  std::vector<float> weights(parents.size, root < 0 ? 1.f : 0.f);
  for (int j = 0; j < n; ++j) {
    const int p = parents[j];
    if (p < -1 || p >= j)
      throw InvalidInput("SubtreeJointWeights", "the parent of joint " + std::to_string(j) +
                                  " is " + std::to_string(p) + "; parents must precede their children");
    if (root >= 0) weights[j] = (j == root || (p >= 0 && weights[p] == 1.f)) ? 1.f : 0.f;
  }
  return weights;
}

}  // namespace mocapedit
