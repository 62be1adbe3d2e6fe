// Laplacian time warping of agents' time maps (section 5.4.2.6 of the deliverable; Kim et
// al. 2009, "Synchronized multi-character motion editing").
//
// The time map of an agent is the shot time at which each of its source frames plays.
// At rest it is the clip's own sample times. Time constraints make a frame play at a shot
// time; sync constraints make one agent's frame play a fixed time after another agent's
// frame. The warp keeps the *change of successive intervals* of each time map as close
// to the rest map's as it can:
//
//   E(T) = sum_i ((d_i^rest - d_{i-1}^rest) - (d_i - d_{i-1}))^2,  d_i = T[i+1] - T[i]
//
// plus a tiny stretch term sum_i stretch_weight (d_i - d_i^rest)^2 that picks, among the
// warps E cannot tell apart, the one that stretches least (so one time constraint alone
// shifts a clip without stretching it), plus the squared residuals of soft constraints.
// Hard constraints are met exactly, by eliminating variables. Every warped interval stays
// at or above a minimum (a fraction of the source interval): time never runs backwards.
// When the unconstrained minimiser breaks that, a primal active-set method solves the
// bounded problem exactly and reports which agents sit at the minimum.
//
// Agents linked by sync constraints share one system; the agents are split into
// independent components (union-find), each factored once. A component without any time
// constraint is free to slide in time as a whole: tiny anchors on its synchronised frames
// hold it near its rest timing (both sides of a handshake meet half way).
//
// Sparse problems follow the precompute / solve split: TimeWarpPrecompute builds and
// factors every component from the constraint *structure* (which frames, hard or soft,
// weights); TimeWarpSolve takes the constraint *values* (times, offsets) and is cheap to
// repeat while a handle is dragged. A singular system (which the regularisers normally
// prevent) falls back from LDLT to SPQR and says so.
#pragma once

#include <Eigen/Core>
#include <Eigen/Sparse>
#include <memory>
#include <string>
#include <vector>

#include "mocapedit/errors.h"  // TimeWarpConflict

namespace mocapedit {

using FramePairs = Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>;  // (agent, frame)
using FrameQuads = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;  // (agent, frame, target, targetFrame)
using Flags = Eigen::Array<bool, Eigen::Dynamic, 1>;

// The structure of a time-warp problem: everything but the constraint values.
struct TimeWarpProblem {
  // #A lists of #F_a strictly increasing shot times: each agent's time map at rest.
  std::vector<Eigen::VectorXd> rest_times;
  // #A lists of #F_a - 1 smallest allowed warped intervals (time codes, > 0). An empty
  // list takes min_interval_fraction times the rest interval.
  std::vector<Eigen::VectorXd> min_intervals;
  double min_interval_fraction = 0.1;  // in (0, 1]

  // #T by 2 list of (agent, frame) of the time constraints ("frame plays at a time").
  FramePairs time_frames = FramePairs(0, 2);
  Flags time_hard = Flags(0);                   // #T: met exactly (true) or weighted (false)
  Eigen::VectorXd time_weights = Eigen::VectorXd(0);  // #T weights (>= 0) of the soft ones

  // #S by 4 list of (agent, frame, target, targetFrame) of the sync constraints
  // ("agent's frame plays offset time codes after target's targetFrame").
  FrameQuads sync_frames = FrameQuads(0, 4);
  Flags sync_hard = Flags(0);                   // #S
  Eigen::VectorXd sync_weights = Eigen::VectorXd(0);  // #S

  // Weight of the stretch term relative to the interval-change term (>= 0). Zero leaves
  // the stretch of a clip with a single constraint undetermined (a singular system).
  double stretch_weight = 1e-6;
  // Weight of the anchors that hold a component without time constraints near its rest
  // timing (> 0).
  double anchor_weight = 1e-6;
  // Cap on active-set iterations per component; < 0 means 10 * frames + 100.
  int max_active_set_iterations = -1;
  // For re-solving as constraint values change (a dragged time): each component that reads
  // at most 16 constraint values also keeps its unbounded solution's response to each of
  // them (one solve per value), so that TimeWarpSolve only sums them; it still runs the
  // active set when an interval falls below its minimum, and gives known times exactly.
  bool precompute_responses = false;
};

struct TimeWarpComponent;  // one factored component (defined in time_warp.cpp)

// Precomputed data: the component split and each component's factored system.
struct TimeWarpData {
  TimeWarpData();
  ~TimeWarpData();
  TimeWarpData(TimeWarpData&&) noexcept;
  TimeWarpData& operator=(TimeWarpData&&) noexcept;

  TimeWarpProblem problem;
  int agents = 0;
  int time_constraints = 0;
  int sync_constraints = 0;
  std::vector<int> agent_component;  // #A component of each agent, -1 if unconstrained
  std::vector<std::unique_ptr<TimeWarpComponent>> components;
};

struct TimeWarpResult {
  std::vector<Eigen::VectorXd> time_maps;  // #A lists of #F_a warped shot times
  Eigen::VectorXd time_residuals;          // #T |T[frame] - time|
  Eigen::VectorXd sync_residuals;          // #S |T_a[frame] - T_b[targetFrame] - offset|
  Eigen::VectorXd min_interval;            // #A smallest warped interval (inf for one frame)
  Eigen::VectorXi min_enforced;            // #A intervals held at their minimum by the active set
  Eigen::VectorXi component;               // #A component index, -1 if unconstrained
  std::vector<std::string> solver;         // #A "rest", "LDLT" or "SPQR fallback"
  Eigen::VectorXi iterations;              // #C active-set iterations per component (0: none needed)
};

// Splits the agents into components and factors each one.
//
// Inputs:
//   problem  the structure: rest time maps, constraint frames, hardness and weights
// Outputs:
//   data     replaced: the factored components, for TimeWarpSolve
// Throws InvalidInput on bad shapes, indices, frames out of range, weights or rest times
// that do not increase; NumericalError when a factorization fails.
void TimeWarpPrecompute(const TimeWarpProblem& problem, TimeWarpData& data);

// Warps every time map to the constraint values. Const on data; may run from several
// threads.
//
// Inputs:
//   data     from TimeWarpPrecompute
//   times    #T shot times of the time constraints
//   offsets  #S sync offsets (time codes)
// Outputs:
//   result   replaced: the warped time maps (agents without constraints keep their rest
//            map) and the figures to report
// Throws TimeWarpConflict (an InvalidInput) when hard constraints contradict each other or
// the minimum interval, InvalidInput on bad shapes or non-finite values.
void TimeWarpSolve(const TimeWarpData& data, const Eigen::Ref<const Eigen::VectorXd>& times,
                   const Eigen::Ref<const Eigen::VectorXd>& offsets, TimeWarpResult& result);

// Precompute and solve in one call.
void TimeWarp(const TimeWarpProblem& problem, const Eigen::Ref<const Eigen::VectorXd>& times,
              const Eigen::Ref<const Eigen::VectorXd>& offsets, TimeWarpResult& result);

}  // namespace mocapedit
