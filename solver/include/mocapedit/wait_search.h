// Waiting in collision avoidance: the least delay of one walker that parts it from another.
//
// Of two walkers who would collide, the one that reaches the crossing later slows down
// before it, through its time map, until the other has passed. A delay d is taken up by a
// smoothstep between shot times `start` and `end` (SmoothDelay): no interval shrinks, every
// one after `end` is unchanged and the pace is continuous. WaitSearch tries delays in steps
// and keeps the least one after which the walker keeps its clearance from the other over
// their encounter and meets nobody it did not meet already, but for walkers going its way
// (they wait in their turn, as a queue does).
//
// Positions are ground-plane coordinates in stage units, sampled at #K common shot times
// for #A agents and laid out time-major as in collisions.h: row k*#A + a of a #K*#A by 2
// list holds agent a at sample k. Times are in time codes.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <map>
#include <utility>
#include <vector>

#include "mocapedit/errors.h"
#include "mocapedit/trajectory.h"

namespace mocapedit {

// The time map `times` (#F increasing shot times of the frames) with `delay` time codes
// taken up between shot times `start` and `end` by a smoothstep:
// times + delay * u^2 (3 - 2u), u = clamp((times - start) / (end - start), 0, 1).
Eigen::VectorXd SmoothDelay(const Eigen::Ref<const Eigen::VectorXd>& times, double start, double end,
                            double delay);

struct WaitSettings {
  double time_codes_per_second = 24.0;  // > 0
  double sample_step = 1.0;             // time codes between samples, > 0
  double step = 6.0;                    // delays are tried in steps of this, time codes, > 0
  double margin = 0.0;                  // clearance kept beyond both radii, stage units, >= 0
  double slowest_pace = 0.5;            // least fraction of the source pace while slowing, in (0, 1)
  double passing_cos = 0.7;             // walkers whose directions are closer go the same way
  int block = 24;                       // samples per bounding box of the broad phase, >= 1
};

// One walker that may wait, and the one it would meet.
struct WaitQuery {
  int walker = 0, other = 0;
  int first = 0, last = 0;   // samples of their encounter (inclusive)
  double room = 0.0;         // largest delay the walker may still take up, time codes
  double guess = 0.0;        // first guess of the delay, time codes (non-finite: none)
};

// The walker's frames: ground path, current time map and source time map (its pace bound),
// #F each; and the shot time before which its time map must stay as it is (a frame an artist
// placed at a moment of the shot plays then): no delay is taken up before it, nor before the
// clip starts.
struct WaitWalker {
  Eigen::Ref<const Trajectory2> path;
  Eigen::Ref<const Eigen::VectorXd> times;
  Eigen::Ref<const Eigen::VectorXd> source_times;
  double earliest = -std::numeric_limits<double>::infinity();
};

struct WaitDelay {
  bool found = false;
  double delay = 0.0;        // time codes
  double start = 0.0, end = 0.0;  // shot times over which it is taken up
  Eigen::VectorXd times;     // #F the walker's new time map
};

// One round of waiting: every agent at the round's samples, and each agent's bounding box
// over blocks of `settings.block` samples (the broad phase of each query).
class WaitSearch {
 public:
  // positions: #K*#A by 2 (time-major); times: #K sample times; radius: #A capsule radii.
  // Throws InvalidInput on bad shapes or settings.
  WaitSearch(const Eigen::Ref<const Trajectory2>& positions, const Eigen::Ref<const Eigen::VectorXd>& times,
             const Eigen::Ref<const Eigen::VectorXd>& radius, const WaitSettings& settings);

  // The least delay of query.walker, from a step below query.guess (rounded to steps) up to
  // four steps above it and at most query.room, that parts it from query.other over the
  // samples from a second before the encounter to a second and the room past it, meets no
  // agent it did not meet already but those walking its way (direction cosine at least
  // passing_cos over that window), keeps its pace at or above slowest_pace of its source's
  // and starts after its clip does (it ends 0.1 s before the encounter and lasts at least
  // a second). Not found when no delay does. Throws InvalidInput on agents or samples out
  // of range or a walker whose arrays disagree in length.
  WaitDelay LeastDelay(const WaitQuery& query, const WaitWalker& walker) const;

  int samples() const { return samples_; }
  int agents() const { return agents_; }

 private:
  Trajectory2 positions_;
  Eigen::VectorXd times_, radius_;
  WaitSettings settings_;
  int samples_ = 0, agents_ = 0, blocks_ = 0;
  // Per agent, per block: lowest and highest x and y ({lo x, lo y, hi x, hi y}), agent-major.
  std::vector<double> boxes_;
  // Per block: the agents whose box of that block covers each cell of a uniform grid.
  struct BlockGrid {
    double x0 = 0.0, y0 = 0.0, cell = 1.0;
    int nx = 0, ny = 0;
    std::vector<int> start;   // #cells+1 offsets into agents, cell = y * nx + x
    std::vector<int> agents;
    // Inclusive cell range (clamped to the grid) of a box.
    void Cells(double lx, double ly, double hx, double hy, int c0[2], int c1[2]) const;
  };
  std::vector<BlockGrid> grids_;
  double speed_ = 0.0;           // largest move of any agent between samples, either axis
  double largest_radius_ = 0.0;
};

// One encounter of a round of waiting: the walker that would wait, the other, the samples of
// their encounter (inclusive) and the first guess of the delay (time codes).
struct WaitEncounter {
  int walker = 0, other = 0;
  int first = 0, last = 0;
  double guess = 0.0;
};

// The pairs tried so far, over the rounds: (walker, other) -> the delays both had taken then.
using WaitTried = std::map<std::pair<int, int>, std::pair<double, double>>;

// One round of waiting: the encounters in the order given, each walker taking the least delay
// (WaitSearch::LeastDelay) of the first of its encounters that has one. An encounter is passed
// over when its walker has already taken a delay in this round, has less than `step` left of
// `budget` (time codes, `delay` holding what each agent has taken so far), or was tried in an
// earlier round or encounter with both agents' delays as they are now; every one tried is
// recorded in `tried`. `walkers` holds each agent's frames (only the walkers' are read).
// Adds the delays taken to `delay` and returns them (walker, delay) in the order taken.
std::vector<std::pair<int, WaitDelay>> WaitRound(const WaitSearch& search, const std::vector<WaitEncounter>& encounters,
                                                 const std::vector<WaitWalker>& walkers, double budget, double step,
                                                 std::vector<double>& delay, WaitTried& tried);

}  // namespace mocapedit
