// Regions of the ground plane that agents must stay out of (negative constraints,
// section 4.3.2 of the deliverable).
//
// A region is a convex footprint on the ground plane, in stage units: a circle, or a
// convex polygon (the hull of the projected corners of a box or of a bound). Agents are
// kept out of the footprint grown by a clearance (their capsule radius plus the region's
// margin): a ground position closer than that is pushed to the nearest point at exactly
// that clearance, which for a convex footprint is the nearest point outside the grown
// region.
#pragma once

#include <Eigen/Core>

#include "mocapedit/trajectory.h"
#include "mocapedit/errors.h"

namespace mocapedit {

struct GroundRegion {
  bool is_circle = false;
  Eigen::Vector2d center = Eigen::Vector2d::Zero();  // circle centre
  double radius = 0.0;                               // circle radius, > 0
  Trajectory2 polygon;  // #V by 2 convex polygon, counter-clockwise (V >= 3)
};

// Convex hull of #N by 2 points, counter-clockwise, without repeated or collinear points.
// Returns #H by 2 (H may be below 3 when the points are collinear).
Trajectory2 ConvexHull(const Eigen::Ref<const Trajectory2>& points);

// A circle region. Throws InvalidInput unless radius > 0 and everything is finite.
GroundRegion CircleRegion(const Eigen::Vector2d& center, double radius);

// The convex hull of #N by 2 points as a region. Throws InvalidInput when the
// hull has no area (fewer than three non-collinear points) or a value is not finite.
GroundRegion HullRegion(const Eigen::Ref<const Trajectory2>& points);

// #N signed distances of #N by 2 ground points to the region's boundary: negative inside.
Eigen::VectorXd RegionSignedDistance(const GroundRegion& region,
                                     const Eigen::Ref<const Trajectory2>& points);

// The nearest boundary point of every point, and the outward normal there.
struct RegionNearest {
  Trajectory2 boundary;         // #N by 2 nearest points on the boundary
  Trajectory2 normal;           // #N by 2 unit outward normals (for a point on the boundary: its edge's)
  Eigen::VectorXd distance;     // #N signed distances, negative inside
};

RegionNearest NearestOnRegion(const GroundRegion& region, const Eigen::Ref<const Trajectory2>& points);

// Points closer to the region than their clearance, and where they go.
struct RegionPush {
  Eigen::VectorXi index;  // #P indices into the points, ascending
  Trajectory2 target;     // #P by 2 nearest positions at exactly the clearance
  Trajectory2 normal;     // #P by 2 unit outward directions (target = boundary + clearance * normal)
  Eigen::VectorXd depth;  // #P clearance minus signed distance, > 0
};

// Inputs:
//   region     the footprint
//   points     #N by 2 ground positions
//   clearance  #N distances to keep from the footprint (>= 0), or a single value for all
RegionPush PushOutOfRegion(const GroundRegion& region, const Eigen::Ref<const Trajectory2>& points,
                           const Eigen::Ref<const Eigen::VectorXd>& clearance);

}  // namespace mocapedit
