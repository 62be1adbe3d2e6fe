#include "mocapedit/clip_sampling.h"
#include "mocapedit/errors.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace mocapedit {

namespace {

// Rotations closer than this (sine of the angle between them) blend linearly.
constexpr double kSmallAngle = 1e-6;

void Slerp(const float* q0, const float* q1, double t, float* out) {
  double a[4], b[4];
  double dot = 0.0;
  for (int k = 0; k < 4; ++k) {
    a[k] = q0[k];
    b[k] = q1[k];
    dot += a[k] * b[k];
  }
  if (dot < 0) {  // shortest arc
    for (double& v : b) v = -v;
    dot = -dot;
  }
  // sin(theta) from the dot product, and sin((1 - t) theta) = sin(theta) cos(t theta) -
  // cos(theta) sin(t theta): one acos and one sin/cos pair per joint.
  const double c = std::min(dot, 1.0);
  const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
  double w0 = 1.0 - t, w1 = t;
  if (s >= kSmallAngle) {
    const double theta = std::acos(c);
    const double st = std::sin(t * theta), ct = std::cos(t * theta);
    w0 = (s * ct - c * st) / s;
    w1 = st / s;
  }
  double r[4], norm = 0.0;
  for (int k = 0; k < 4; ++k) {
    r[k] = w0 * a[k] + w1 * b[k];
    norm += r[k] * r[k];
  }
  norm = std::sqrt(norm);
  for (int k = 0; k < 4; ++k) out[k] = static_cast<float>(r[k] / norm);
}

}  // namespace

void SampleClip(const Eigen::Ref<const Vec3fRows>& translations, const Eigen::Ref<const Quatf4Rows>& rotations,
                const Eigen::Ref<const Vec3fRows>& scales, int joints,
                const Eigen::Ref<const Eigen::VectorXd>& frames, Eigen::Ref<Vec3fRows> out_translations,
                Eigen::Ref<Quatf4Rows> out_rotations, Eigen::Ref<Vec3fRows> out_scales) {
  if (joints <= 0) throw InvalidInput("SampleClip", "joints must be positive");
  const Eigen::Index rows = translations.rows();
  if (rows == 0 || rows % joints != 0)
    throw InvalidInput("SampleClip", "translations must hold a whole number (> 0) of frames of " +
                                std::to_string(joints) + " joints");
  if (rotations.rows() != rows || scales.rows() != rows)
    throw InvalidInput("SampleClip", "translations, rotations and scales need the same number of rows");
  if (!frames.allFinite()) throw InvalidInput("SampleClip", "frames must be finite");
  const Eigen::Index count = rows / joints;
  const Eigen::Index out_rows = frames.size() * joints;
  if (out_translations.rows() != out_rows || out_rotations.rows() != out_rows || out_scales.rows() != out_rows)
    throw InvalidInput("SampleClip", "the outputs need " + std::to_string(out_rows) + " rows");
  for (Eigen::Index i = 0; i < frames.size(); ++i) {
    const double f = std::clamp(frames[i], 0.0, static_cast<double>(count - 1));
    const Eigen::Index i0 = static_cast<Eigen::Index>(std::floor(f));
    const Eigen::Index i1 = std::min(i0 + 1, count - 1);
    const double a = f - static_cast<double>(i0);
    const Eigen::Index r0 = i0 * joints, r1 = i1 * joints, o = i * joints;
    if (a == 0.0) {
      out_translations.middleRows(o, joints) = translations.middleRows(r0, joints);
      out_rotations.middleRows(o, joints) = rotations.middleRows(r0, joints);
      out_scales.middleRows(o, joints) = scales.middleRows(r0, joints);
      continue;
    }
    for (Eigen::Index j = 0; j < joints; ++j) {
      for (int k = 0; k < 3; ++k) {
        out_translations(o + j, k) = static_cast<float>(translations(r0 + j, k) * (1.0 - a) +
                                                        translations(r1 + j, k) * a);
        out_scales(o + j, k) = static_cast<float>(scales(r0 + j, k) * (1.0 - a) + scales(r1 + j, k) * a);
      }
      Slerp(rotations.row(r0 + j).data(), rotations.row(r1 + j).data(), a, out_rotations.row(o + j).data());
    }
  }
}

Eigen::VectorXd FramesAtTimes(const Eigen::Ref<const Eigen::VectorXd>& time_map,
                              const Eigen::Ref<const Eigen::VectorXd>& times) {
  const Eigen::Index n = time_map.size();
  if (n == 0) throw InvalidInput("FramesAtTimes", "the time map is empty");
  for (Eigen::Index i = 1; i < n; ++i)
    if (!(time_map[i] > time_map[i - 1]))
      throw InvalidInput("FramesAtTimes", "the time map must increase (frame " + std::to_string(i) + ")");
  if (!times.allFinite()) throw InvalidInput("FramesAtTimes", "times must be finite");
  Eigen::VectorXd out(times.size());
  const double* begin = time_map.data();
  const double* end = begin + n;
  for (Eigen::Index i = 0; i < times.size(); ++i) {
    const double t = times[i];
    if (!(t > time_map[0])) {
      out[i] = 0.0;
    } else if (t >= time_map[n - 1]) {
      out[i] = static_cast<double>(n - 1);
    } else {
      const Eigen::Index j = (std::upper_bound(begin, end, t) - begin) - 1;  // time_map[j] <= t < time_map[j + 1]
      out[i] = static_cast<double>(j) + (t - time_map[j]) / (time_map[j + 1] - time_map[j]);
    }
  }
  return out;
}

}  // namespace mocapedit
