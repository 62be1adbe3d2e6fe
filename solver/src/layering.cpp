#include "mocapedit/layering.h"

#include "view_checks.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

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

void Coefficients(double t, float* p) {
  double acc = 1.0;
  p[0] = 1.f;
  for (int k = 1; k <= kTerms; ++k) {
    const double scale = k == kTerms ? kMu : 1.0;
    acc *= scale * (t * t - double(k) * double(k)) / (double(k) * (2.0 * k + 1.0));
    p[k] = static_cast<float>(acc);
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

inline float Horner(const float* p, float xm1) {
  float c = p[kTerms];
  for (int i = kTerms - 1; i >= 0; --i) c = c * xm1 + p[i];
  return c;
}

// Shortest-arc slerp of a to b, normalised. `a` and `b` are (x, y, z, w).
inline void SlerpKernel(const float* a, const float* b, const SlerpWeights& w, float* out) {
  float x = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  const float sign = x < 0.f ? -1.f : 1.f;
  x = std::fabs(x);
  // |a.b| may exceed 1 by rounding (or for quaternions that are not quite unit).
  const float xm1 = (x < 1.f ? x : 1.f) - 1.f;
  const float ct = sign * w.t * Horner(w.pt, xm1);
  const float cd = w.d * Horner(w.pd, xm1);
  float q[4];
  for (int i = 0; i < 4; ++i) q[i] = cd * a[i] + ct * b[i];
  const float n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int i = 0; i < 4; ++i) out[i] = q[i] / n;
}

// slerp((0, 0, 0, 1), delta, w), normalised: the weighted additive delta. A delta of exactly
// identity gives exactly identity (sqrt(v * v) == v in IEEE arithmetic).
inline void WeightedDelta(const float* delta, const SlerpWeights& w, float* out) {
  const float sign = delta[3] < 0.f ? -1.f : 1.f;
  const float x = std::fabs(delta[3]);
  const float xm1 = (x < 1.f ? x : 1.f) - 1.f;
  const float ct = sign * w.t * Horner(w.pt, xm1);
  const float cd = w.d * Horner(w.pd, xm1);
  const float q[4] = {ct * delta[0], ct * delta[1], ct * delta[2], cd + ct * delta[3]};
  const float n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int i = 0; i < 4; ++i) out[i] = q[i] / n;
}

// Hamilton product a * b of (x, y, z, w) quaternions: rotates by b, then by a.
inline void Multiply(const float* a, const float* b, float* out) {
  const float x = a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1];
  const float y = a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0];
  const float z = a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3];
  const float w = a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2];
  out[0] = x;
  out[1] = y;
  out[2] = z;
  out[3] = w;
}

bool InUnitRange(float v) { return v >= 0.f && v <= 1.f; }  // false for NaN

// ---- the pipeline ---------------------------------------------------------------------

void CopySource(const LayeringJob& job) {
  auto copy = [](Span<const float> from, Span<float> to) {
    if (from.size && from.data != to.data) std::memcpy(to.data, from.data, from.size * sizeof(float));
  };
  copy(job.source.translations, job.output.translations);
  copy(job.source.rotations, job.output.rotations);
  copy(job.source.scales, job.output.scales);
}

// Per pose: the layer weight and its slerp coefficients, made once for every joint whose
// joint weight is 1; a joint with a fractional joint weight gets its own.
struct PoseWeight {
  float weight;
  SlerpWeights slerp;
};

void BlendLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const std::size_t nj = job.num_joints;
  const bool masked = !layer.joint_weights.empty();
  for (std::size_t t = 0; t < job.num_poses; ++t) {
    const float w = layer.weights[t];
    if (w == 0.f) continue;
    const SlerpWeights pose_slerp = MakeSlerpWeights(w);
    for (std::size_t j = 0; j < nj; ++j) {
      const float wj = masked ? w * layer.joint_weights[j] : w;
      if (wj == 0.f) continue;
      const std::size_t i = t * nj + j;
      const float* lt = &layer.transforms.translations[i * 3];
      const float* lr = &layer.transforms.rotations[i * 4];
      const float* ls = &layer.transforms.scales[i * 3];
      float* ot = &job.output.translations[i * 3];
      float* orot = &job.output.rotations[i * 4];
      float* os = &job.output.scales[i * 3];
      if (wj == 1.f) {
        for (int k = 0; k < 3; ++k) ot[k] = lt[k];
        for (int k = 0; k < 4; ++k) orot[k] = lr[k];
        for (int k = 0; k < 3; ++k) os[k] = ls[k];
        continue;
      }
      const float vd = 1.f - wj;
      for (int k = 0; k < 3; ++k) ot[k] = vd * ot[k] + wj * lt[k];
      for (int k = 0; k < 3; ++k) os[k] = vd * os[k] + wj * ls[k];
      if (wj == w)
        SlerpKernel(orot, lr, pose_slerp, orot);
      else
        SlerpKernel(orot, lr, MakeSlerpWeights(wj), orot);
    }
  }
}

void AddLayer(const LayeringJob& job, const LayeringJob::Layer& layer) {
  const std::size_t nj = job.num_joints;
  const bool masked = !layer.joint_weights.empty();
  for (std::size_t t = 0; t < job.num_poses; ++t) {
    const float w = layer.weights[t];
    if (w == 0.f) continue;
    const SlerpWeights pose_slerp = MakeSlerpWeights(w);
    const std::size_t base = t * nj;
    const float* dt = &layer.transforms.translations[base * 3];
    const float* dr = &layer.transforms.rotations[base * 4];
    const float* ds = &layer.transforms.scales[base * 3];
    float* ot = &job.output.translations[base * 3];
    float* orot = &job.output.rotations[base * 4];
    float* os = &job.output.scales[base * 3];
    for (std::size_t j = 0; j < nj; ++j) {
      const float wj = masked ? w * layer.joint_weights[j] : w;
      if (wj == 0.f) continue;
      for (int k = 0; k < 3; ++k) ot[j * 3 + k] += wj * dt[j * 3 + k];
      for (int k = 0; k < 3; ++k) os[j * 3 + k] *= 1.f + wj * (ds[j * 3 + k] - 1.f);
      float q[4];
      if (wj == 1.f) {
        // The delta itself, on its short arc (q and -q are the same rotation).
        const float sign = dr[j * 4 + 3] < 0.f ? -1.f : 1.f;
        for (int k = 0; k < 4; ++k) q[k] = sign * dr[j * 4 + k];
      } else if (wj == w) {
        WeightedDelta(&dr[j * 4], pose_slerp, q);
      } else {
        WeightedDelta(&dr[j * 4], MakeSlerpWeights(wj), q);
      }
      Multiply(q, &orot[j * 4], &orot[j * 4]);
    }
  }
}

}  // namespace

void Slerp(const float a[4], const float b[4], float t, float out[4]) {
  SlerpKernel(a, b, MakeSlerpWeights(t), out);
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
