#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <optional>

#include "mocapedit/collisions.h"
#include "mocapedit/regions.h"
#include "registry.h"

namespace py = pybind11;

namespace {

using mocapedit::Trajectory2;

// Collision intervals as arrays, one entry per interval (the Python view of
// std::vector<Collision>).
struct CollisionIntervals {
  Eigen::VectorXi agent_a, agent_b, first, last, deepest;
  Eigen::VectorXd depth;

  explicit CollisionIntervals(const std::vector<mocapedit::Collision>& intervals) {
    const Eigen::Index n = static_cast<Eigen::Index>(intervals.size());
    agent_a.resize(n), agent_b.resize(n), first.resize(n), last.resize(n), deepest.resize(n), depth.resize(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      const mocapedit::Collision& c = intervals[static_cast<size_t>(i)];
      agent_a[i] = c.agent_a, agent_b[i] = c.agent_b, first[i] = c.first, last[i] = c.last;
      deepest[i] = c.deepest, depth[i] = c.depth;
    }
  }
};

// detect_collisions' result: the collision intervals, those below the watch distance, and
// each agent's smallest clearance.
struct Detection {
  CollisionIntervals collisions;
  std::optional<CollisionIntervals> near;
  Eigen::VectorXd min_clearance;
  Eigen::VectorXi min_clearance_sample;
  int64_t colliding_samples = 0;
  int64_t pair_tests = 0;

  Detection(const mocapedit::CollisionResult& r, bool with_near)
      : collisions(r.collisions),
        min_clearance(r.min_clearance),
        min_clearance_sample(r.min_clearance_sample),
        colliding_samples(r.colliding_samples),
        pair_tests(r.pair_tests) {
    if (with_near) near.emplace(r.near);
  }
};

// The result classes first: the functions' signatures name them.
void BindCollisionClasses(py::module_& m) {
  py::class_<CollisionIntervals>(m, "CollisionIntervals",
                                 "Collision intervals, one entry per interval, sorted by (agent_a, agent_b, first).")
      .def_readonly("agent_a", &CollisionIntervals::agent_a, py::return_value_policy::copy, "(N,) first agent, agent_a < agent_b")
      .def_readonly("agent_b", &CollisionIntervals::agent_b, py::return_value_policy::copy, "(N,) second agent")
      .def_readonly("first", &CollisionIntervals::first, py::return_value_policy::copy, "(N,) first sample (inclusive)")
      .def_readonly("last", &CollisionIntervals::last, py::return_value_policy::copy, "(N,) last sample (inclusive)")
      .def_readonly("deepest", &CollisionIntervals::deepest, py::return_value_policy::copy, "(N,) sample of the maximal overlap")
      .def_readonly("depth", &CollisionIntervals::depth, py::return_value_policy::copy, "(N,) margin (or watch distance) minus the clearance there")
      .def("__len__", [](const CollisionIntervals& c) { return c.agent_a.size(); });
  py::class_<Detection>(m, "CollisionResult", "Result of detect_collisions.")
      .def_readonly("collisions", &Detection::collisions, py::return_value_policy::copy, "intervals below the margin")
      .def_readonly("near", &Detection::near, py::return_value_policy::copy, "intervals below watch_distance, or None when none was asked for")
      .def_readonly("min_clearance", &Detection::min_clearance, py::return_value_policy::copy,
                    "(A,) smallest clearance of each agent, +inf beyond report_distance")
      .def_readonly("min_clearance_sample", &Detection::min_clearance_sample, py::return_value_policy::copy, "(A,) its sample, -1 when +inf")
      .def_readonly("colliding_samples", &Detection::colliding_samples, py::return_value_policy::copy, "(pair, sample) records below the margin")
      .def_readonly("pair_tests", &Detection::pair_tests, py::return_value_policy::copy, "narrow-phase capsule tests done");
  py::class_<mocapedit::RegionNearest>(m, "RegionNearest", "Nearest boundary points of a region (nearest_on_region).")
      .def_readonly("boundary", &mocapedit::RegionNearest::boundary, py::return_value_policy::copy, "(N, 2) nearest points on the boundary")
      .def_readonly("normal", &mocapedit::RegionNearest::normal, py::return_value_policy::copy, "(N, 2) unit outward normals there")
      .def_readonly("distance", &mocapedit::RegionNearest::distance, py::return_value_policy::copy, "(N,) signed distances, negative inside");
  py::class_<mocapedit::RegionPush>(m, "RegionPush", "Points closer to a region than their clearance (push_out_of_region).")
      .def_readonly("index", &mocapedit::RegionPush::index, py::return_value_policy::copy, "(P,) indices into the points, ascending")
      .def_readonly("target", &mocapedit::RegionPush::target, py::return_value_policy::copy, "(P, 2) nearest positions at exactly the clearance")
      .def_readonly("normal", &mocapedit::RegionPush::normal, py::return_value_policy::copy, "(P, 2) unit outward directions")
      .def_readonly("depth", &mocapedit::RegionPush::depth, py::return_value_policy::copy, "(P,) clearance minus signed distance, > 0");
}

}  // namespace

MOCAPEDIT_BINDINGS(BindCollisions) {
  BindCollisionClasses(m);
  m.def(
      "detect_collisions",
      [](const Eigen::Ref<const Trajectory2>& positions, int samples, const Eigen::VectorXd& radius,
         const Eigen::VectorXd& height, std::optional<Eigen::VectorXd> base,
         std::optional<std::vector<bool>> active, double margin, double report_distance, int threads,
         bool brute_force, double watch_distance) {
        mocapedit::CapsuleSet capsules;
        capsules.radius = radius;
        capsules.height = height;
        capsules.base = base ? *base : Eigen::VectorXd::Zero(radius.size());
        if (active) capsules.active.assign(active->begin(), active->end());
        mocapedit::CollisionSettings settings;
        settings.margin = margin;
        settings.report_distance = report_distance;
        settings.threads = threads;
        settings.watch_distance = watch_distance;
        mocapedit::CollisionResult result;
        {
          py::gil_scoped_release release;
          result = brute_force ? mocapedit::DetectCollisionsBruteForce(positions, samples, capsules, settings)
                               : mocapedit::DetectCollisions(positions, samples, capsules, settings);
        }
        return Detection(result, watch_distance > margin);
      },
      py::kw_only(), py::arg("positions"), py::arg("samples"), py::arg("radius"), py::arg("height"),
      py::arg("base") = py::none(), py::arg("active") = py::none(), py::arg("margin") = 0.0,
      py::arg("report_distance") = 0.0, py::arg("threads") = 0, py::arg("brute_force") = false,
      py::arg("watch_distance") = 0.0,
      "Collision intervals between vertical capsules sampled at common shot times.\n\n"
      "positions: (K*A, 2) ground positions, time-major (row k*A + a is agent a at sample k);\n"
      "radius, height, base: (A,) capsule radius, height and base elevation (stage units);\n"
      "active: (A,) flags, None = all; margin: wanted clearance (stage units);\n"
      "report_distance: min_clearance is exact up to this clearance, +inf beyond;\n"
      "brute_force: test all pairs at every sample instead of using the grid (the reference);\n"
      "watch_distance: when above margin, intervals below this clearance are also returned as 'near'.\n\n"
      "Returns a CollisionResult. Keyword arguments only.");
  m.def("capsule_clearance", &mocapedit::CapsuleClearance, py::arg("dx"), py::arg("dy"), py::arg("radius_a"),
        py::arg("height_a"), py::arg("base_a"), py::arg("radius_b"), py::arg("height_b"), py::arg("base_b"),
        "Clearance between two vertical capsules whose ground positions differ by (dx, dy); "
        "negative when they overlap.");

  py::class_<mocapedit::GroundRegion>(m, "GroundRegion",
                                      "A convex footprint on the ground plane: a circle or a convex polygon.")
      .def_static("circle", &mocapedit::CircleRegion, py::arg("center"), py::arg("radius"),
                  "A circle of radius > 0 (stage units) around a ground point.")
      .def_static("hull", &mocapedit::HullRegion, py::arg("points"),
                  "The convex hull of (N, 2) ground points; ValueError if it has no area.")
      .def_readonly("is_circle", &mocapedit::GroundRegion::is_circle)
      .def_readonly("center", &mocapedit::GroundRegion::center)
      .def_readonly("radius", &mocapedit::GroundRegion::radius)
      .def_readonly("polygon", &mocapedit::GroundRegion::polygon,
                    "(V, 2) counter-clockwise corners (empty for a circle).");
  m.def("convex_hull", &mocapedit::ConvexHull, py::arg("points"),
        "(H, 2) counter-clockwise convex hull of (N, 2) points, without collinear points.");
  m.def(
      "region_signed_distance",
      [](const mocapedit::GroundRegion& region, const Eigen::Ref<const Trajectory2>& points) {
        py::gil_scoped_release release;
        return mocapedit::RegionSignedDistance(region, points);
      },
      py::arg("region"), py::arg("points"), "(N,) signed distances of (N, 2) ground points; negative inside.");
  m.def(
      "nearest_on_region",
      [](const mocapedit::GroundRegion& region, const Eigen::Ref<const Trajectory2>& points) {
        py::gil_scoped_release release;
        return mocapedit::NearestOnRegion(region, points);
      },
      py::arg("region"), py::arg("points"),
      "RegionNearest of (N, 2) ground points: the nearest boundary points, outward normals there and\n"
      "signed distances.");
  m.def(
      "push_out_of_region",
      [](const mocapedit::GroundRegion& region, const Eigen::Ref<const Trajectory2>& points,
         const Eigen::VectorXd& clearance) {
        py::gil_scoped_release release;
        return mocapedit::PushOutOfRegion(region, points, clearance);
      },
      py::arg("region"), py::arg("points"), py::arg("clearance"),
      "RegionPush: the points of (N, 2) closer to the region than their clearance ((N,) or (1,)),\n"
      "where they go (at exactly the clearance), the outward directions and how deep they were.");
}
