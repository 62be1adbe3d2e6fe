// Collision detection between agents (chapter 6 of the deliverable).
//
// Each agent is a vertical capsule standing on its ground position: a segment along the
// up axis from base + radius to base + height - radius, swept by a sphere of `radius`
// (a capsule shorter than two radii degenerates to a sphere at base + height / 2). Agents
// are sampled at #K common shot times (constant steps after time warping); the caller
// does the sampling. The clearance of two capsules is the distance between their axes
// minus both radii; the pair collides at a sample when the clearance is below `margin`.
//
// For every pair of agents, each contiguous run of colliding samples is one collision
// interval; its deepest sample is the maximal overlap that the resolution pushes apart.
//
// Positions are laid out time-major: a #K*#A by 2 list, row k*#A + a holds agent a's
// ground position at sample k, in stage units.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mocapedit/trajectory.h"
#include "mocapedit/errors.h"

namespace mocapedit {

// The capsules and which agents take part.
struct CapsuleSet {
  Eigen::VectorXd radius;  // #A capsule radii, stage units, > 0
  Eigen::VectorXd height;  // #A capsule heights along up from the base, stage units, > 0
  Eigen::VectorXd base;    // #A base elevations along up (0 = on the ground plane)
  std::vector<char> active;  // #A flags; an inactive agent neither collides nor is hit
};

struct CollisionSettings {
  double margin = 0.0;          // clearance wanted between capsules, stage units (>= 0)
  double report_distance = 0.0;  // min_clearance is exact up to this clearance (>= margin)
  // Clearance (stage units) below which pairs are also gathered into `near` intervals;
  // <= margin: none. Collision avoidance watches near misses with it in the same pass.
  double watch_distance = 0.0;
  int threads = 0;              // worker threads over time samples; 0 = hardware (at most 2)
};

// One contiguous collision interval of one pair of agents.
struct Collision {
  int agent_a = 0;   // a < b
  int agent_b = 0;
  int first = 0;     // first colliding sample (inclusive)
  int last = 0;      // last colliding sample (inclusive)
  int deepest = 0;   // sample of the maximal overlap
  double depth = 0;  // margin minus clearance at the deepest sample, > 0
};

struct CollisionResult {
  std::vector<Collision> collisions;  // sorted by (agent_a, agent_b, first)
  // Intervals below watch_distance, sorted the same way, depth = watch_distance minus the
  // clearance (empty when watch_distance <= margin).
  std::vector<Collision> near;
  // #A smallest clearance of each agent to any other over all samples; +inf when no other
  // agent came within report_distance (the value is exact below it).
  Eigen::VectorXd min_clearance;
  Eigen::VectorXi min_clearance_sample;  // #A sample of that clearance, -1 when +inf
  int64_t colliding_samples = 0;  // (pair, sample) records below margin
  int64_t pair_tests = 0;          // narrow-phase capsule tests done
};

// Clearance between two vertical capsules (negative when they overlap).
double CapsuleClearance(double dx, double dy, double radius_a, double height_a, double base_a,
                        double radius_b, double height_b, double base_b);

// Finds every collision interval with a uniform grid per sample (cell = the largest
// reach of any pair), so only agents in neighbouring cells are tested.
//
// Inputs:
//   positions  #K*#A by 2 ground positions, time-major (see above)
//   samples    #K, the number of samples
//   capsules   #A radii, heights, bases and active flags
//   settings   margin, report distance, threads
// Returns the intervals and each agent's minimum clearance.
// Throws InvalidInput on bad shapes, non-positive radii or heights, a negative
// margin, or non-finite positions of an active agent.
CollisionResult DetectCollisions(const Eigen::Ref<const Trajectory2>& positions, int samples,
                                 const CapsuleSet& capsules, const CollisionSettings& settings);

// The same result by testing all pairs at every sample; the reference for tests and the
// peer of the benchmark.
CollisionResult DetectCollisionsBruteForce(const Eigen::Ref<const Trajectory2>& positions,
                                           int samples, const CapsuleSet& capsules,
                                           const CollisionSettings& settings);

}  // namespace mocapedit
