#include "mocapedit/layering.h"

#include "view_checks.h"

#include <algorithm>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace mocapedit {
namespace {

using detail::Fail;
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
// Quaternions are gathered from the (x, y, z, w) arrays into lanes, one vector per component
// and four joints per vector, so the polynomial (a long chain of dependent multiply-adds for
// one joint) runs on kLanes joints side by side. F4 is a GCC/Clang vector type: plain
// arithmetic on it compiles to SIMD on every target.
typedef float F4 __attribute__((vector_size(16)));
typedef int I4 __attribute__((vector_size(16)));
constexpr int kVectors = 4;
constexpr int kLanes = 4 * kVectors;

inline F4 Sqrt(F4 v) {
#if defined(__SSE__)
  return _mm_sqrt_ps(v);
#else
  for (int i = 0; i < 4; ++i) v[i] = std::sqrt(v[i]);
  return v;
#endif
}

inline F4 Select(I4 mask, F4 a, F4 b) {  // mask ? a : b, lane by lane
  return reinterpret_cast<F4>((reinterpret_cast<I4>(a) & mask) | (reinterpret_cast<I4>(b) & ~mask));
}

struct QuatLanes {
  F4 x[kVectors], y[kVectors], z[kVectors], w[kVectors];

  void Load(int lane, const float* q) {
    x[lane / 4][lane % 4] = q[0];
    y[lane / 4][lane % 4] = q[1];
    z[lane / 4][lane % 4] = q[2];
    w[lane / 4][lane % 4] = q[3];
  }
  void Store(int lane, float* q) const {
    q[0] = x[lane / 4][lane % 4];
    q[1] = y[lane / 4][lane % 4];
    q[2] = z[lane / 4][lane % 4];
    q[3] = w[lane / 4][lane % 4];
  }
  // Gathers the quaternions of joints js[0..count) from an (x, y, z, w) array; unused lanes
  // hold identity. Four consecutive joints load as one 4x4 transpose.
  void Gather(const float* quats, const int* js, int count) {
    for (int v = 0; v < kVectors; ++v) {
      const int first = v * 4, n = std::min(4, count - first);
#if defined(__SSE__)
      if (n == 4 && js[first + 3] == js[first] + 3) {
        const float* p = quats + js[first] * 4;
        __m128 r0 = _mm_loadu_ps(p), r1 = _mm_loadu_ps(p + 4), r2 = _mm_loadu_ps(p + 8), r3 = _mm_loadu_ps(p + 12);
        _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
        x[v] = r0;
        y[v] = r1;
        z[v] = r2;
        w[v] = r3;
        continue;
      }
#endif
      x[v] = y[v] = z[v] = F4{};
      w[v] = F4{} + 1.f;
      for (int l = 0; l < n; ++l) Load(first + l, quats + js[first + l] * 4);
    }
  }
  void Scatter(float* quats, const int* js, int count) const {
    for (int v = 0; v < kVectors; ++v) {
      const int first = v * 4, n = std::min(4, count - first);
#if defined(__SSE__)
      if (n == 4 && js[first + 3] == js[first] + 3) {
        float* p = quats + js[first] * 4;
        __m128 r0 = x[v], r1 = y[v], r2 = z[v], r3 = w[v];
        _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
        _mm_storeu_ps(p, r0);
        _mm_storeu_ps(p + 4, r1);
        _mm_storeu_ps(p + 8, r2);
        _mm_storeu_ps(p + 12, r3);
        continue;
      }
#endif
      for (int l = 0; l < n; ++l) Store(first + l, quats + js[first + l] * 4);
    }
  }
  void FillIdentity() {
    for (int v = 0; v < kVectors; ++v) {
      x[v] = y[v] = z[v] = F4{};
      w[v] = F4{} + 1.f;
    }
  }
};

// out = slerp(a, b, t) on the short arc, lane by lane, normalised. At t == 1 the result is b
// (with the sign that puts it on a's side) and is not renormalised, so it stays bit for bit.
// For a == b == identity the result is exactly identity.
void SlerpLanes(const QuatLanes& a, const QuatLanes& b, const SlerpWeights& sw, QuatLanes& out) {
  for (int v = 0; v < kVectors; ++v) {
    const F4 dot = a.x[v] * b.x[v] + a.y[v] * b.y[v] + a.z[v] * b.z[v] + a.w[v] * b.w[v];
    const I4 negative = dot < 0.f;
    const F4 x = Select(negative, -dot, dot);
    // |a.b| may exceed 1 by rounding (or for quaternions that are not quite unit).
    const F4 xm1 = Select(x < 1.f, x, F4{} + 1.f) - 1.f;
    F4 ht = F4{} + sw.pt[kTerms], hd = F4{} + sw.pd[kTerms];
    for (int k = kTerms - 1; k >= 0; --k) {
      ht = ht * xm1 + sw.pt[k];
      hd = hd * xm1 + sw.pd[k];
    }
    const F4 ct = Select(negative, F4{} - sw.t, F4{} + sw.t) * ht, cd = sw.d * hd;
    F4 qx = cd * a.x[v] + ct * b.x[v], qy = cd * a.y[v] + ct * b.y[v];
    F4 qz = cd * a.z[v] + ct * b.z[v], qw = cd * a.w[v] + ct * b.w[v];
    if (sw.t != 1.f) {
      // One division: for q = (0, 0, 0, v) with v within an ulp of 1 (identity slerped with
      // identity), v * (1 / sqrt(v * v)) is still exactly 1.
      const F4 inv = 1.f / Sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
      qx *= inv;
      qy *= inv;
      qz *= inv;
      qw *= inv;
    }
    out.x[v] = qx;
    out.y[v] = qy;
    out.z[v] = qz;
    out.w[v] = qw;
  }
}

// out = a * b (Hamilton product: rotate by b, then by a), lane by lane.
void MultiplyLanes(const QuatLanes& a, const QuatLanes& b, QuatLanes& out) {
  for (int v = 0; v < kVectors; ++v) {
    const F4 x = a.w[v] * b.x[v] + a.x[v] * b.w[v] + a.y[v] * b.z[v] - a.z[v] * b.y[v];
    const F4 y = a.w[v] * b.y[v] - a.x[v] * b.z[v] + a.y[v] * b.w[v] + a.z[v] * b.x[v];
    const F4 z = a.w[v] * b.z[v] + a.x[v] * b.y[v] - a.y[v] * b.x[v] + a.z[v] * b.w[v];
    const F4 w = a.w[v] * b.w[v] - a.x[v] * b.x[v] - a.y[v] * b.y[v] - a.z[v] * b.z[v];
    out.x[v] = x;
    out.y[v] = y;
    out.z[v] = z;
    out.w[v] = w;
  }
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

void BlendLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const std::size_t nj = job.num_joints;
  const LayerJoints joints(layer, nj);
  QuatLanes from, to;
  for (std::size_t t = 0; t < job.num_poses; ++t) {
    const float w = layer.weights[t];
    if (w == 0.f) continue;
    const std::size_t base = t * nj;
    const float* lt = &layer.transforms.translations[base * 3];
    const float* lr = &layer.transforms.rotations[base * 4];
    const float* ls = &layer.transforms.scales[base * 3];
    float* ot = &job.output.translations[base * 3];
    float* orot = &job.output.rotations[base * 4];
    float* os = &job.output.scales[base * 3];
    joints.ForRuns(w, [&](int begin, int end, float wj) {
      // (1 - w) a + w b: exactly a at 0 and exactly b at 1.
      const float vd = 1.f - wj;
      for (int i = begin; i < end; ++i) ot[i] = vd * ot[i] + wj * lt[i];
      for (int i = begin; i < end; ++i) os[i] = vd * os[i] + wj * ls[i];
    });
    if (w == 1.f)  // the layer's rotations, bit for bit, on the joints at the full weight
      for (const auto& [b, e] : joints.runs) std::memcpy(orot + b * 4, lr + b * 4, (e - b) * 4 * sizeof(float));
    joints.ForLanes(w, w != 1.f, [&](const int* js, int count, const SlerpWeights& sw) {
      from.Gather(orot, js, count);
      to.Gather(lr, js, count);
      SlerpLanes(from, to, sw, from);
      from.Scatter(orot, js, count);
    });
  }
}

void AddLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const std::size_t nj = job.num_joints;
  const LayerJoints joints(layer, nj);
  QuatLanes identity, delta, source;
  identity.FillIdentity();
  for (std::size_t t = 0; t < job.num_poses; ++t) {
    const float w = layer.weights[t];
    if (w == 0.f) continue;
    const std::size_t base = t * nj;
    const float* dt = &layer.transforms.translations[base * 3];
    const float* dr = &layer.transforms.rotations[base * 4];
    const float* ds = &layer.transforms.scales[base * 3];
    float* ot = &job.output.translations[base * 3];
    float* orot = &job.output.rotations[base * 4];
    float* os = &job.output.scales[base * 3];
    joints.ForRuns(w, [&](int begin, int end, float wj) {
      for (int i = begin; i < end; ++i) ot[i] += wj * dt[i];
      for (int i = begin; i < end; ++i) os[i] *= 1.f + wj * (ds[i] - 1.f);
    });
    // slerp(identity, delta, w) * source
    joints.ForLanes(w, true, [&](const int* js, int count, const SlerpWeights& sw) {
      delta.Gather(dr, js, count);
      source.Gather(orot, js, count);
      SlerpLanes(identity, delta, sw, delta);
      MultiplyLanes(delta, source, source);
      source.Scatter(orot, js, count);
    });
  }
}

}  // namespace

void Slerp(const float a[4], const float b[4], float t, float out[4]) {
  QuatLanes qa, qb;
  qa.FillIdentity();
  qb.FillIdentity();
  qa.Load(0, a);
  qb.Load(0, b);
  SlerpLanes(qa, qb, MakeSlerpWeights(t), qa);
  qa.Store(0, out);
}

bool LayeringJob::Validate(std::string* error) const {
  const std::size_t n = num_poses * num_joints;
  if (!ViewHasSize(source, n))
    return Fail(error, "source must hold #T*#J = " + std::to_string(n) +
                           " transforms (translations and scales 3 floats each, rotations 4)");
  if (!ViewHasSize(ConstPoseStreamView(output), n))
    return Fail(error, "output must hold #T*#J = " + std::to_string(n) + " transforms");
  if (ViewsPartiallyOverlap(output, source))
    return Fail(error, "output partially overlaps source (only the very same buffers may alias)");
  for (std::size_t l = 0; l < layers.size; ++l) {
    const Layer& layer = layers[l];
    const std::string which = "layer " + std::to_string(l) + ": ";
    if (layer.mode != LayerMode::kBlend && layer.mode != LayerMode::kAdditive)
      return Fail(error, which + "mode must be blend or additive");
    if (!ViewHasSize(layer.transforms, n))
      return Fail(error, which + "transforms must hold #T*#J = " + std::to_string(n) + " transforms");
    if (!HasSize(layer.weights, num_poses))
      return Fail(error, which + "weights must hold one value per pose (" + std::to_string(num_poses) +
                             "), got " + std::to_string(layer.weights.size));
    for (std::size_t t = 0; t < num_poses; ++t)
      if (!InUnitRange(layer.weights[t]))
        return Fail(error, which + "weight of pose " + std::to_string(t) + " is " +
                               std::to_string(layer.weights[t]) + ", outside [0, 1]");
    if (!layer.joint_weights.empty() && !HasSize(layer.joint_weights, num_joints))
      return Fail(error, which + "joint_weights must be empty or hold one value per joint (" +
                             std::to_string(num_joints) + "), got " +
                             std::to_string(layer.joint_weights.size));
    for (std::size_t j = 0; j < layer.joint_weights.size; ++j)
      if (!InUnitRange(layer.joint_weights[j]))
        return Fail(error, which + "joint weight of joint " + std::to_string(j) + " is " +
                               std::to_string(layer.joint_weights[j]) + ", outside [0, 1]");
  }
  return true;
}

bool LayeringJob::Run(std::string* error) const {
  if (!Validate(error)) return false;
  CopySource(*this);
  for (const Layer& layer : layers) {
    if (layer.mode == LayerMode::kBlend)
      BlendLayer(*this, layer);
    else
      AddLayer(*this, layer);
  }
  return true;
}

std::vector<float> SubtreeJointWeights(Span<const int> parents, int root) {
  const int n = static_cast<int>(parents.size);
  if (root < -1 || root >= n)
    throw std::invalid_argument("SubtreeJointWeights: root " + std::to_string(root) +
                                " is not a joint index (0.." + std::to_string(n - 1) + ") or -1");
  std::vector<float> weights(parents.size, root < 0 ? 1.f : 0.f);
  for (int j = 0; j < n; ++j) {
    const int p = parents[j];
    if (p < -1 || p >= j)
      throw std::invalid_argument("SubtreeJointWeights: the parent of joint " + std::to_string(j) +
                                  " is " + std::to_string(p) + "; parents must precede their children");
    if (root >= 0) weights[j] = (j == root || (p >= 0 && weights[p] == 1.f)) ? 1.f : 0.f;
  }
  return weights;
}

}  // namespace mocapedit
