#include "mocapedit/skeleton_space.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "view_checks.h"

namespace mocapedit {
namespace {

using detail::BytesOverlap;

// The local matrix of one transform: scale, then rotate (the quaternion normalised), then
// translate; terms in the order of mocapedit.geometry.kinematics.compose_trs.
void Compose(const float* t, const float* r, const float* s, double* m) {
  double x = r[0], y = r[1], z = r[2], w = r[3];
  const double n = std::sqrt(x * x + y * y + z * z + w * w);
  x /= n, y /= n, z /= n, w /= n;
  const double xx = x * x, yy = y * y, zz = z * z, xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y,
               wz = w * z;
  const double rows[3][3] = {{1 - 2 * (yy + zz), 2 * (xy + wz), 2 * (xz - wy)},
                             {2 * (xy - wz), 1 - 2 * (xx + zz), 2 * (yz + wx)},
                             {2 * (xz + wy), 2 * (yz - wx), 1 - 2 * (xx + yy)}};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[4 * i + j] = rows[i][j] * static_cast<double>(s[i]);
    m[4 * i + 3] = 0.0;
  }
  m[12] = t[0], m[13] = t[1], m[14] = t[2], m[15] = 1.0;
}

// out = a * b (4x4, row-major).
void Multiply(const double* a, const double* b, double* out) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      out[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j] + a[4 * i + 3] * b[12 + j];
}

// The rotation of a row-vector matrix's upper 3x3 (rows scaled), as trs_from_matrices finds it:
// rows divided by their lengths, a mirror flipped into the first row, then the quaternion of the
// column-vector matrix from its largest diagonal candidate.
void Rotation(const double* m, double* q) {
  double r[3][3];
  for (int i = 0; i < 3; ++i) {
    const double* row = m + 4 * i;
    const double s = std::sqrt(row[0] * row[0] + row[1] * row[1] + row[2] * row[2]);
    for (int j = 0; j < 3; ++j) r[i][j] = row[j] / s;
  }
  const double det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0]) +
                     r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
  if (det < 0)
    for (int j = 0; j < 3; ++j) r[0][j] = -r[0][j];
  auto c = [&](int i, int j) { return r[j][i]; };  // column-vector rotation
  const double tr = c(0, 0) + c(1, 1) + c(2, 2);
  const double cand[4] = {1 + 2 * c(0, 0) - tr, 1 + 2 * c(1, 1) - tr, 1 + 2 * c(2, 2) - tr, 1 + tr};
  int k = 0;
  for (int i = 1; i < 4; ++i)
    if (cand[i] > cand[k]) k = i;
  const double big = 0.5 * std::sqrt(std::max(cand[k], 1e-300)), f = 0.25 / big;
  switch (k) {
    case 0: q[0] = big, q[1] = (c(0, 1) + c(1, 0)) * f, q[2] = (c(0, 2) + c(2, 0)) * f, q[3] = (c(2, 1) - c(1, 2)) * f; break;
    case 1: q[0] = (c(0, 1) + c(1, 0)) * f, q[1] = big, q[2] = (c(1, 2) + c(2, 1)) * f, q[3] = (c(0, 2) - c(2, 0)) * f; break;
    case 2: q[0] = (c(0, 2) + c(2, 0)) * f, q[1] = (c(1, 2) + c(2, 1)) * f, q[2] = big, q[3] = (c(1, 0) - c(0, 1)) * f; break;
    default: q[0] = (c(2, 1) - c(1, 2)) * f, q[1] = (c(0, 2) - c(2, 0)) * f, q[2] = (c(1, 0) - c(0, 1)) * f, q[3] = big;
  }
  if (q[3] < 0)
    for (int i = 0; i < 4; ++i) q[i] = -q[i];
}

}  // namespace

void SkeletonSpaceJob::Validate() const {
  const char* job = "SkeletonSpaceJob";
  const std::size_t count = parents.size;
  if (count && !parents.data) throw InvalidInput(job, "parents must hold #J values");
  if (columns.size != count || (count && !columns.data)) throw InvalidInput(job, "columns must hold #J values");
  if (rest.size != count * 16 || (count && !rest.data)) throw InvalidInput(job, "rest must hold #J * 16 values");
  for (std::size_t j = 0; j < count; ++j)
    if (parents[j] < -1 || parents[j] >= static_cast<std::int64_t>(j))
      throw InvalidInput(job, "joint " + std::to_string(j) + ": its parent must precede it (or be -1)");
  if (pose_columns <= 0) throw InvalidInput(job, "pose_columns must be positive");
  for (std::size_t j = 0; j < count; ++j)
    if (columns[j] < -1 || columns[j] >= pose_columns)
      throw InvalidInput(job, "joint " + std::to_string(j) + ": its column must be -1 or below pose_columns");
  const auto c = static_cast<std::size_t>(pose_columns);
  if (pose.translations.size % (3 * c) != 0) throw InvalidInput(job, "translations must hold #T * #C * 3 values");
  const std::size_t poses = pose.translations.size / (3 * c);
  if (pose.rotations.size != poses * c * 4 || pose.scales.size != poses * c * 3)
    throw InvalidInput(job, "rotations and scales must hold #T * #C entries, as translations do");
  if (poses && (!pose.translations.data || !pose.rotations.data || !pose.scales.data))
    throw InvalidInput(job, "the pose views must not be null");
  for (const std::int64_t j : joints)
    if (j < 0 || j >= static_cast<std::int64_t>(count)) throw InvalidInput(job, "a wanted joint is out of range");
  if (matrices.size != poses * joints.size * 16 || (matrices.size && !matrices.data))
    throw InvalidInput(job, "matrices must hold " + std::to_string(poses * joints.size * 16) + " values");
  if (rotations.size != 0 && (rotations.size != poses * joints.size * 4 || !rotations.data))
    throw InvalidInput(job, "rotations must be empty or hold " + std::to_string(poses * joints.size * 4) + " values");
  if (BytesOverlap(matrices.data, matrices.size * sizeof(double), rotations.data, rotations.size * sizeof(double)))
    throw InvalidInput(job, "rotations overlaps matrices");
  const struct { const void* data; std::size_t bytes; const char* name; } inputs[] = {
      {parents.data, parents.size * sizeof(std::int64_t), "parents"},
      {columns.data, columns.size * sizeof(std::int64_t), "columns"},
      {rest.data, rest.size * sizeof(double), "rest"},
      {pose.translations.data, pose.translations.size * sizeof(float), "translations"},
      {pose.rotations.data, pose.rotations.size * sizeof(float), "rotations"},
      {pose.scales.data, pose.scales.size * sizeof(float), "scales"},
      {joints.data, joints.size * sizeof(std::int64_t), "joints"}};
  for (const auto& in : inputs) {
    if (BytesOverlap(matrices.data, matrices.size * sizeof(double), in.data, in.bytes))
      throw InvalidInput(job, std::string("matrices overlaps the input ") + in.name);
    if (BytesOverlap(rotations.data, rotations.size * sizeof(double), in.data, in.bytes))
      throw InvalidInput(job, std::string("rotations overlaps the input ") + in.name);
  }
}

void SkeletonSpaceJob::Run() const {
  Validate();
  const std::size_t count = parents.size, c = static_cast<std::size_t>(pose_columns);
  const std::size_t poses = pose.translations.size / (3 * c), wanted = joints.size;
  // The joints to compose: the wanted ones and their ancestors, parents first (joint order).
  std::vector<char> needed(count, 0);
  for (std::int64_t j : joints)
    for (; j >= 0 && !needed[static_cast<std::size_t>(j)]; j = parents[static_cast<std::size_t>(j)])
      needed[static_cast<std::size_t>(j)] = 1;
  std::vector<std::size_t> order;
  for (std::size_t j = 0; j < count; ++j)
    if (needed[j]) order.push_back(j);
  std::vector<double> skel(count * 16), local(16);
  for (std::size_t t = 0; t < poses; ++t) {
    for (const std::size_t j : order) {
      const std::int64_t col = columns[j];
      const double* m = &rest[16 * j];
      if (col >= 0) {
        const std::size_t i = t * c + static_cast<std::size_t>(col);
        Compose(&pose.translations[3 * i], &pose.rotations[4 * i], &pose.scales[3 * i], local.data());
        m = local.data();
      }
      const std::int64_t p = parents[j];
      if (p < 0) {
        std::copy(m, m + 16, &skel[16 * j]);
      } else {
        Multiply(m, &skel[16 * static_cast<std::size_t>(p)], &skel[16 * j]);
      }
    }
    for (std::size_t k = 0; k < wanted; ++k) {
      const double* m = &skel[16 * static_cast<std::size_t>(joints[k])];
      std::copy(m, m + 16, &matrices[16 * (t * wanted + k)]);
      if (!rotations.empty()) Rotation(m, &rotations[4 * (t * wanted + k)]);
    }
  }
}

}  // namespace mocapedit
