#include "mocapedit/placement.h"

#include <cmath>
#include <functional>
#include <string>

#include "view_checks.h"

namespace mocapedit {
namespace {

using detail::Overlap;

// p * m for a row-vector 4x4 m: the rotation rows summed in order, then the translation row.
void Transform(const double* p, const double* m, double* out) {
  for (int j = 0; j < 3; ++j) out[j] = p[0] * m[j] + p[1] * m[4 + j] + p[2] * m[8 + j] + m[12 + j];
}

// a * b, (x, y, z, w), term by term as quat_multiply writes it.
void Multiply(const double* a, const double* b, double* out) {
  const double ax = a[0], ay = a[1], az = a[2], aw = a[3], bx = b[0], by = b[1], bz = b[2], bw = b[3];
  out[0] = aw * bx + ax * bw + ay * bz - az * by;
  out[1] = aw * by - ax * bz + ay * bw + az * bx;
  out[2] = aw * bz + ax * by - ay * bx + az * bw;
  out[3] = aw * bw - ax * bx - ay * by - az * bz;
}

}  // namespace

void PlacementJob::Validate() const {
  const char* job = "PlacementJob";
  if (point_count < 0 || rotation_count < 0) throw InvalidInput(job, "point_count and rotation_count must not be negative");
  const std::size_t n = turn.size, p = static_cast<std::size_t>(point_count), q = static_cast<std::size_t>(rotation_count);
  if (n && !turn.data) throw InvalidInput(job, "turn must not be null");
  const struct { Span<const double> s; std::size_t size; const char* name; } inputs[] = {
      {placement, n * 16, "placement"}, {placement_rotation, n * 4, "placement_rotation"}, {motion, n * 16, "motion"},
      {turn, n, "turn"}, {up, 3, "up"}, {points, n * p * 3, "points"}, {rotations, n * q * 4, "rotations"}};
  for (const auto& in : inputs)
    if (in.s.size != in.size || (in.size && !in.s.data))
      throw InvalidInput(job, std::string(in.name) + " must hold " + std::to_string(in.size) + " values");
  const double len = std::sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
  if (!std::isfinite(len) || std::abs(len - 1.0) > 1e-6) throw InvalidInput(job, "up must be a unit vector");
  const struct { Span<double> s; std::size_t size; const char* name; } outputs[] = {
      {source_points, n * p * 3, "source_points"}, {edited_points, n * p * 3, "edited_points"},
      {source_rotations, n * q * 4, "source_rotations"}, {edited_rotations, n * q * 4, "edited_rotations"}};
  for (const auto& out : outputs)
    if (out.s.size != out.size || (out.size && !out.s.data))
      throw InvalidInput(job, std::string(out.name) + " must hold " + std::to_string(out.size) + " values");
  for (std::size_t i = 0; i < 4; ++i) {
    for (const auto& in : inputs)
      if (Overlap(outputs[i].s.data, outputs[i].s.size, in.s.data, in.s.size))
        throw InvalidInput(job, std::string(outputs[i].name) + " overlaps the input " + in.name);
    for (std::size_t j = i + 1; j < 4; ++j)
      if (Overlap(outputs[i].s.data, outputs[i].s.size, outputs[j].s.data, outputs[j].s.size))
        throw InvalidInput(job, std::string(outputs[i].name) + " overlaps " + outputs[j].name);
  }
}

void PlacementJob::Run() const {
  Validate();
  const std::size_t n = turn.size, p = static_cast<std::size_t>(point_count), q = static_cast<std::size_t>(rotation_count);
  for (std::size_t t = 0; t < n; ++t) {
    for (std::size_t k = 0; k < p; ++k) {
      const std::size_t i = 3 * (t * p + k);
      Transform(&points[i], &placement[16 * t], &source_points[i]);
      Transform(&source_points[i], &motion[16 * t], &edited_points[i]);
    }
    const double half = 0.5 * turn[t], s = std::sin(half);
    const double yaw[4] = {s * up[0], s * up[1], s * up[2], std::cos(half)};
    for (std::size_t k = 0; k < q; ++k) {
      const std::size_t i = 4 * (t * q + k);
      Multiply(&placement_rotation[4 * t], &rotations[i], &source_rotations[i]);
      Multiply(yaw, &source_rotations[i], &edited_rotations[i]);
    }
  }
}

}  // namespace mocapedit
