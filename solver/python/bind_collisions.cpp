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

template <typename T>
py::array_t<T> ToArray(const std::vector<T>& v) {
  py::array_t<T> out(static_cast<py::ssize_t>(v.size()));
  std::copy(v.begin(), v.end(), out.mutable_data());
  return out;
}

py::dict IntervalsToDict(const std::vector<mocapedit::Collision>& intervals) {
  std::vector<int> a, b, first, last, deepest;
  std::vector<double> depth;
  for (const auto& c : intervals) {
    a.push_back(c.agent_a);
    b.push_back(c.agent_b);
    first.push_back(c.first);
    last.push_back(c.last);
    deepest.push_back(c.deepest);
    depth.push_back(c.depth);
  }
  py::dict d;
  d["agent_a"] = ToArray(a);
  d["agent_b"] = ToArray(b);
  d["first"] = ToArray(first);
  d["last"] = ToArray(last);
  d["deepest"] = ToArray(deepest);
  d["depth"] = ToArray(depth);
  return d;
}

py::dict CollisionsToDict(const mocapedit::CollisionResult& r, bool near) {
  py::dict d = IntervalsToDict(r.collisions);
  if (near) d["near"] = IntervalsToDict(r.near);
  d["min_clearance"] = r.min_clearance;
  d["min_clearance_sample"] = r.min_clearance_sample;
  d["colliding_samples"] = r.colliding_samples;
  d["pair_tests"] = r.pair_tests;
  return d;
}

}  // namespace

MOCAPEDIT_BINDINGS(BindCollisions) {
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
        return CollisionsToDict(result, watch_distance > margin);
      },
      py::arg("positions"), py::arg("samples"), py::arg("radius"), py::arg("height"),
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
      "Returns a dict of arrays, one entry per collision interval sorted by (agent_a, agent_b, first):\n"
      "agent_a < agent_b, first, last (inclusive samples), deepest (sample of the maximal overlap),\n"
      "depth (margin minus clearance there); and per agent min_clearance (A,) and\n"
      "min_clearance_sample (A,) (-1 when +inf); colliding_samples and pair_tests (counts); with a\n"
      "watch_distance above margin, near: a dict of the same interval arrays below watch_distance\n"
      "(depth = watch_distance minus clearance).");
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
        mocapedit::RegionNearest nearest;
        {
          py::gil_scoped_release release;
          nearest = mocapedit::NearestOnRegion(region, points);
        }
        py::dict d;
        d["boundary"] = nearest.boundary;
        d["normal"] = nearest.normal;
        d["distance"] = nearest.distance;
        return d;
      },
      py::arg("region"), py::arg("points"),
      "For (N, 2) ground points, a dict: boundary (N, 2) nearest boundary points, normal (N, 2) unit\n"
      "outward normals there, distance (N,) signed distances (negative inside).");
  m.def(
      "push_out_of_region",
      [](const mocapedit::GroundRegion& region, const Eigen::Ref<const Trajectory2>& points,
         const Eigen::VectorXd& clearance) {
        mocapedit::RegionPush push;
        {
          py::gil_scoped_release release;
          push = mocapedit::PushOutOfRegion(region, points, clearance);
        }
        py::dict d;
        d["index"] = push.index;
        d["target"] = push.target;
        d["normal"] = push.normal;
        d["depth"] = push.depth;
        return d;
      },
      py::arg("region"), py::arg("points"), py::arg("clearance"),
      "Points of (N, 2) closer to the region than their clearance ((N,) or (1,)), as a dict:\n"
      "index (P,), target (P, 2) the nearest position at exactly the clearance, normal (P, 2)\n"
      "outward unit directions, depth (P,) how far inside the clearance each point was.");
}
