#include "mocapedit/regions.h"
#include "mocapedit/errors.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace mocapedit {
namespace {

double Cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

// Distance from p to the polygon's boundary, the nearest boundary point and the outward
// normal of the edge it lies on (used when p is on the boundary itself).
double NearestOnBoundary(const Trajectory2& poly, const Eigen::Vector2d& p, Eigen::Vector2d* nearest,
                         Eigen::Vector2d* edge_normal) {
  double best = std::numeric_limits<double>::infinity();
  const Eigen::Index n = poly.rows();
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector2d a = poly.row(i).transpose();
    const Eigen::Vector2d b = poly.row((i + 1) % n).transpose();
    const Eigen::Vector2d e = b - a;
    const double len2 = e.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((p - a).dot(e) / len2, 0.0, 1.0) : 0.0;
    const Eigen::Vector2d q = a + t * e;
    const double d = (p - q).norm();
    if (d < best) {
      best = d;
      *nearest = q;
      // Counter-clockwise polygon: the outward normal is the edge turned clockwise.
      *edge_normal = Eigen::Vector2d(e.y(), -e.x()).normalized();
    }
  }
  return best;
}

bool Inside(const Trajectory2& poly, const Eigen::Vector2d& p) {
  const Eigen::Index n = poly.rows();
  for (Eigen::Index i = 0; i < n; ++i)
    if (Cross(poly.row(i).transpose(), poly.row((i + 1) % n).transpose(), p) < 0.0) return false;
  return true;
}

void CheckFinite(const Eigen::Ref<const Trajectory2>& points, const char* what) {
  if (!points.allFinite()) throw InvalidInput(what, "points must be finite");
}

}  // namespace

Trajectory2 ConvexHull(const Eigen::Ref<const Trajectory2>& points) {
  CheckFinite(points, "ConvexHull");
  std::vector<Eigen::Index> order(static_cast<size_t>(points.rows()));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
    return points(a, 0) < points(b, 0) || (points(a, 0) == points(b, 0) && points(a, 1) < points(b, 1));
  });
  // Andrew's monotone chain; strict turns drop collinear and repeated points.
  std::vector<Eigen::Vector2d> hull;
  auto add = [&](Eigen::Index idx, size_t floor) {
    const Eigen::Vector2d p = points.row(idx).transpose();
    while (hull.size() >= floor + 2 && Cross(hull[hull.size() - 2], hull.back(), p) <= 0.0) hull.pop_back();
    hull.push_back(p);
  };
  for (Eigen::Index idx : order) add(idx, 0);
  if (order.size() > 1) {
    const size_t lower = hull.size() - 1;
    for (auto it = order.rbegin() + 1; it != order.rend(); ++it) add(*it, lower);
    hull.pop_back();  // the first point closes the chain
  }
  if (hull.size() == 2 && hull[0] == hull[1]) hull.pop_back();
  Trajectory2 out(static_cast<Eigen::Index>(hull.size()), 2);
  for (size_t i = 0; i < hull.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = hull[i].transpose();
  return out;
}

GroundRegion CircleRegion(const Eigen::Vector2d& center, double radius) {
  if (!center.allFinite()) throw InvalidInput("CircleRegion", "the centre must be finite");
  if (!(radius > 0.0) || !std::isfinite(radius))
    throw InvalidInput("CircleRegion", "the radius must be positive and finite");
  GroundRegion r;
  r.is_circle = true;
  r.center = center;
  r.radius = radius;
  return r;
}

GroundRegion HullRegion(const Eigen::Ref<const Trajectory2>& points) {
  GroundRegion r;
  r.polygon = ConvexHull(points);
  if (r.polygon.rows() < 3) throw InvalidInput("HullRegion", "the footprint has no area");
  return r;
}

Eigen::VectorXd RegionSignedDistance(const GroundRegion& region,
                                     const Eigen::Ref<const Trajectory2>& points) {
  CheckFinite(points, "RegionSignedDistance");
  Eigen::VectorXd out(points.rows());
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector2d p = points.row(i).transpose();
    if (region.is_circle) {
      out[i] = (p - region.center).norm() - region.radius;
    } else {
      Eigen::Vector2d q, n;
      const double d = NearestOnBoundary(region.polygon, p, &q, &n);
      out[i] = Inside(region.polygon, p) ? -d : d;
    }
  }
  return out;
}

RegionNearest NearestOnRegion(const GroundRegion& region, const Eigen::Ref<const Trajectory2>& points) {
  CheckFinite(points, "NearestOnRegion");
  if (!region.is_circle && region.polygon.rows() < 3)
    throw InvalidInput("NearestOnRegion", "the region's polygon has fewer than three corners");
  RegionNearest out;
  const Eigen::Index n = points.rows();
  out.boundary.resize(n, 2);
  out.normal.resize(n, 2);
  out.distance.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector2d p = points.row(i).transpose();
    Eigen::Vector2d boundary, normal;
    if (region.is_circle) {
      const Eigen::Vector2d d = p - region.center;
      const double len = d.norm();
      normal = len > 0.0 ? Eigen::Vector2d(d / len) : Eigen::Vector2d(1.0, 0.0);
      boundary = region.center + region.radius * normal;
      out.distance[i] = len - region.radius;
    } else {
      Eigen::Vector2d edge_normal;
      const double d = NearestOnBoundary(region.polygon, p, &boundary, &edge_normal);
      const bool inside = Inside(region.polygon, p);
      out.distance[i] = inside ? -d : d;
      normal = d > 0.0 ? Eigen::Vector2d((inside ? boundary - p : p - boundary) / d) : edge_normal;
    }
    out.boundary.row(i) = boundary.transpose();
    out.normal.row(i) = normal.transpose();
  }
  return out;
}

RegionPush PushOutOfRegion(const GroundRegion& region, const Eigen::Ref<const Trajectory2>& points,
                           const Eigen::Ref<const Eigen::VectorXd>& clearance) {
  CheckFinite(points, "PushOutOfRegion");
  const Eigen::Index n = points.rows();
  if (clearance.size() != n && clearance.size() != 1)
    throw InvalidInput("PushOutOfRegion", "clearance needs one value per point, or one value");
  if (!clearance.allFinite() || (clearance.size() && clearance.minCoeff() < 0.0))
    throw InvalidInput("PushOutOfRegion", "clearances must be finite and not negative");
  if (!region.is_circle && region.polygon.rows() < 3)
    throw InvalidInput("PushOutOfRegion", "the region's polygon has fewer than three corners");
  std::vector<Eigen::Index> hit;
  std::vector<Eigen::Vector2d> targets, normals;
  std::vector<double> depths;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double c = clearance.size() == 1 ? clearance[0] : clearance[i];
    const Eigen::Vector2d p = points.row(i).transpose();
    Eigen::Vector2d boundary, normal;
    double signed_distance;
    if (region.is_circle) {
      const Eigen::Vector2d d = p - region.center;
      const double len = d.norm();
      signed_distance = len - region.radius;
      if (signed_distance >= c) continue;
      normal = len > 0.0 ? Eigen::Vector2d(d / len) : Eigen::Vector2d(1.0, 0.0);
      boundary = region.center + region.radius * normal;
    } else {
      Eigen::Vector2d edge_normal;
      const double d = NearestOnBoundary(region.polygon, p, &boundary, &edge_normal);
      const bool inside = Inside(region.polygon, p);
      signed_distance = inside ? -d : d;
      if (signed_distance >= c) continue;
      if (d > 0.0)
        normal = inside ? Eigen::Vector2d((boundary - p) / d) : Eigen::Vector2d((p - boundary) / d);
      else
        normal = edge_normal;
    }
    hit.push_back(i);
    targets.push_back(boundary + c * normal);
    normals.push_back(normal);
    depths.push_back(c - signed_distance);
  }
  RegionPush out;
  const auto m = static_cast<Eigen::Index>(hit.size());
  out.index.resize(m);
  out.target.resize(m, 2);
  out.normal.resize(m, 2);
  out.depth.resize(m);
  for (Eigen::Index k = 0; k < m; ++k) {
    out.index[k] = static_cast<int>(hit[static_cast<size_t>(k)]);
    out.target.row(k) = targets[static_cast<size_t>(k)].transpose();
    out.normal.row(k) = normals[static_cast<size_t>(k)].transpose();
    out.depth[k] = depths[static_cast<size_t>(k)];
  }
  return out;
}

}  // namespace mocapedit
