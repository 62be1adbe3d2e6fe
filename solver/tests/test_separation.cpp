#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mocapedit/path_edit.h"
#include "mocapedit/separation.h"
#include "mocapedit/two_threads.h"

using mocapedit::SeparationProblem;
using mocapedit::SeparationResult;
using mocapedit::SeparationRows;
using mocapedit::SeparationSettings;
using mocapedit::Trajectory2;

namespace {

// Two agents of n frames walking at each other along x, 0.1 per frame, one 0.02 to the side.
SeparationProblem HeadOn(int n = 81) {
  SeparationProblem p;
  p.rest.resize(2 * n, 2);
  for (int i = 0; i < n; ++i) {
    p.rest.row(i) << -4.0 + 0.1 * i, 0.0;
    p.rest.row(n + i) << 4.0 - 0.1 * i, 0.02;
  }
  p.starts.resize(3);
  p.starts << 0, n, 2 * n;
  return p;
}

struct RowBuilder {
  SeparationRows rows;
  std::vector<double> dir_x, dir_y, rhs, soft;
  std::vector<int> kind, term_row, term_vertex;
  std::vector<double> term_weight;

  void Add(double dx, double dy, double value, double softness, int k, std::vector<std::pair<int, double>> terms) {
    const int r = static_cast<int>(rhs.size());
    dir_x.push_back(dx);
    dir_y.push_back(dy);
    rhs.push_back(value);
    soft.push_back(softness);
    kind.push_back(k);
    for (auto [v, w] : terms) {
      term_row.push_back(r);
      term_vertex.push_back(v);
      term_weight.push_back(w);
    }
  }

  SeparationRows Build() {
    SeparationRows out;
    const int r = static_cast<int>(rhs.size());
    out.direction.resize(r, 2);
    for (int i = 0; i < r; ++i) out.direction.row(i) << dir_x[i], dir_y[i];
    out.rhs = Eigen::Map<Eigen::VectorXd>(rhs.data(), r);
    out.softness = Eigen::Map<Eigen::VectorXd>(soft.data(), r);
    out.kind = Eigen::Map<Eigen::VectorXi>(kind.data(), r);
    const int t = static_cast<int>(term_row.size());
    out.term_row = Eigen::Map<Eigen::VectorXi>(term_row.data(), t);
    out.term_vertex = Eigen::Map<Eigen::VectorXi>(term_vertex.data(), t);
    out.term_weight = Eigen::Map<Eigen::VectorXd>(term_weight.data(), t);
    return out;
  }
};

SeparationResult Solve(const SeparationProblem& p, const SeparationRows& rows, int sweeps = 500) {
  mocapedit::SeparationData data;
  mocapedit::SeparationPrecompute(p, data);
  SeparationSettings settings;
  settings.max_sweeps = sweeps;
  settings.tolerance = 1e-9;
  SeparationResult result;
  mocapedit::SeparationSolve(data, rows, settings, result);
  return result;
}

}  // namespace

TEST(Separation, ValidityRejectsBadInput) {
  {
    SeparationProblem p = HeadOn();
    p.starts[2] = 5;
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  {
    SeparationProblem p = HeadOn();
    p.anchor_weight = 0.0;
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  {
    SeparationProblem p = HeadOn();
    p.rates = Eigen::VectorXd::Ones(3);  // one per agent: there are two
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
    p.rates = Eigen::Vector2d(1.0, 0.0);
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
    p.rates.resize(0);
    p.anchor_frames = Eigen::VectorXd::Constant(p.rest.rows(), 0.5);   // each stands for a frame at least
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
    p.anchor_frames.resize(0);
    p.cut_into = Eigen::VectorXi::Zero(5);   // one per vertex
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  {
    SeparationProblem p = HeadOn();
    p.min_baseline = -0.1;
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  {
    SeparationProblem p = HeadOn();
    p.rigid = {{70, 90}};  // spans both agents
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  {
    SeparationProblem p = HeadOn();
    p.rigid = {{10, 20}, {15, 30}};
    mocapedit::SeparationData data;
    EXPECT_THROW(mocapedit::SeparationPrecompute(p, data), mocapedit::InvalidInput);
  }
  mocapedit::SeparationData data;
  mocapedit::SeparationPrecompute(HeadOn(), data);
  SeparationResult result;
  {
    RowBuilder b;
    b.Add(1, 0, 0, 0, 0, {{500, 1.0}});  // vertex out of range
    EXPECT_THROW(mocapedit::SeparationSolve(data, b.Build(), SeparationSettings{}, result), mocapedit::InvalidInput);
  }
  {
    RowBuilder b;
    b.Add(1, 0, 0, -1.0, 0, {{5, 1.0}});  // negative softness
    EXPECT_THROW(mocapedit::SeparationSolve(data, b.Build(), SeparationSettings{}, result), mocapedit::InvalidInput);
  }
  {
    RowBuilder b;
    b.Add(1, 0, 0, 0, 0, {{5, 0.0}});  // a row that touches nothing
    EXPECT_THROW(mocapedit::SeparationSolve(data, b.Build(), SeparationSettings{}, result), mocapedit::InvalidInput);
  }
}

TEST(Separation, NoRowsKeepsTheRestPaths) {
  const SeparationProblem p = HeadOn();
  const SeparationResult r = Solve(p, RowBuilder().Build());
  EXPECT_EQ(r.moved_agents, 0);
  EXPECT_NEAR((r.positions - p.rest).cwiseAbs().maxCoeff(), 0.0, 1e-15);
}

TEST(Separation, AHardSeparationIsMetAndSpreadsSmoothly) {
  const int n = 81;
  const SeparationProblem p = HeadOn(n);
  RowBuilder b;
  // Agent 0 at least 0.7 above agent 1 (y) at the crossing frame 40.
  b.Add(0, -1, 0.7, 0, 0, {{40, -1.0}, {n + 40, 1.0}});
  // Pins at both agents' first frames.
  b.Add(1, 0, p.rest(0, 0), 0, 0, {{0, 1.0}});
  b.Add(0, 1, p.rest(0, 1), 0, 0, {{0, 1.0}});
  const SeparationResult r = Solve(p, b.Build());
  EXPECT_EQ(r.moved_agents, 2);
  EXPECT_NEAR(r.residuals[0], 0.0, 1e-9);
  EXPECT_NEAR(r.residuals[1], 0.0, 1e-12);
  EXPECT_NEAR(r.residuals[2], 0.0, 1e-12);
  EXPECT_GT(r.forces[0], 0.0);
  // The detour is local and smooth: far frames barely move, no frame jumps.
  EXPECT_LT((r.positions.row(n - 1) - p.rest.row(n - 1)).norm(), 0.05);  // a push of 0.35 each
  for (int i = 1; i < 2 * n; ++i) {
    if (i == n) continue;
    EXPECT_LT((r.positions.row(i) - r.positions.row(i - 1)).norm(), 0.2) << "frame " << i;
  }
  // Step 2 keeps the length of each step (the agents go round, not faster).
  double rest_length = 0, length = 0;
  for (int i = 1; i < n; ++i) {
    rest_length += (p.rest.row(i) - p.rest.row(i - 1)).norm();
    length += (r.positions.row(i) - r.positions.row(i - 1)).norm();
  }
  EXPECT_NEAR(length / rest_length, 1.0, 0.05);
}

// The same crossing sampled twice as often, told so, steps aside over the same stretch of
// its walk; untold, its detour was narrower and steeper.
TEST(Separation, ADetourLastsAsLongAtAnyRate) {
  const auto crossing = [](int per_step, bool told) {
    const int n = 80 * per_step + 1;
    SeparationProblem p;
    p.rest.resize(2 * n, 2);
    for (int i = 0; i < n; ++i) {
      p.rest.row(i) << -4.0 + 0.1 * i / per_step, 0.0;
      p.rest.row(n + i) << 4.0 - 0.1 * i / per_step, 0.02;
    }
    p.starts = Eigen::Vector3i(0, n, 2 * n);
    p.anchor_weight = 1e-4;
    if (told) p.rates = Eigen::Vector2d::Constant(per_step);
    RowBuilder b;
    b.Add(0, -1, 0.7, 0, 1, {{40 * per_step, -1.0}, {n + 40 * per_step, 1.0}});
    const Trajectory2 moved = Solve(p, b.Build()).positions - p.rest;
    Eigen::VectorXd out(81);   // agent 0's sideways move at the frames of the coarse walk
    for (int i = 0; i <= 80; ++i) out[i] = moved(i * per_step, 1);
    return out;
  };
  const Eigen::VectorXd once = crossing(1, true), twice = crossing(2, true), untold = crossing(2, false);
  EXPECT_GT(once.cwiseAbs().maxCoeff(), 0.3);
  EXPECT_LT((twice - once).cwiseAbs().maxCoeff(), 0.005) << (twice - once).cwiseAbs().maxCoeff();
  EXPECT_GT((untold - once).cwiseAbs().maxCoeff(), 0.05) << (untold - once).cwiseAbs().maxCoeff();
  // Rates of 1 are no rates, bit for bit.
  SeparationProblem ones = HeadOn(), none = HeadOn();
  ones.rates = Eigen::Vector2d(1.0, 1.0);
  RowBuilder b;
  b.Add(0, -1, 0.7, 0, 0, {{40, -1.0}, {81 + 40, 1.0}});
  EXPECT_EQ((Solve(ones, b.Build()).positions - Solve(none, b.Build()).positions).cwiseAbs().maxCoeff(), 0.0);
}

// A last frame whose anchor stands for the 200 frames it is held gives way less to the same
// push than one anchored as a frame, and the other agent more.
TEST(Separation, AHeldFrameIsAnchoredForTheFramesItStandsFor) {
  const int n = 81;
  RowBuilder b;
  b.Add(0, -1, 0.7, 0, 1, {{n - 1, -1.0}, {n + 40, 1.0}});
  const SeparationRows rows = b.Build();
  SeparationProblem one = HeadOn(n), held = HeadOn(n);
  held.anchor_frames = Eigen::VectorXd::Ones(2 * n);
  held.anchor_frames[n - 1] = 201.0;
  const SeparationResult r1 = Solve(one, rows), r2 = Solve(held, rows);
  const double end1 = (r1.positions.row(n - 1) - one.rest.row(n - 1)).norm();
  const double end2 = (r2.positions.row(n - 1) - held.rest.row(n - 1)).norm();
  EXPECT_LT(end2, 0.5 * end1) << end1 << " " << end2;
  EXPECT_GT((r2.positions.row(n + 40) - held.rest.row(n + 40)).norm(), (r1.positions.row(n + 40) - one.rest.row(n + 40)).norm());
}

// A walker whose first frame is a rest pose 3 away (a cut), held there, pushed aside at its
// middle under a weak anchor: the take moves as it does without the rest frame. Kept rigid in
// the take's frame, the cut's step would swing the held frame round with the take, which it
// cannot, and drag the take.
TEST(Separation, ShapeTermsAcrossACutBarelyHoldTheTake) {
  const int n = 81;
  SeparationProblem cut;
  cut.rest.resize(n, 2);
  cut.rest.row(0) << -4.0, 3.0;
  for (int i = 1; i < n; ++i) cut.rest.row(i) << -4.0 + 0.1 * i, 0.0;
  cut.starts = Eigen::Vector2i(0, n);
  cut.anchor_weight = 1e-8;
  cut.cut_into = Eigen::VectorXi::Zero(n);
  cut.cut_into[1] = 1;
  SeparationProblem take;
  take.rest = cut.rest.bottomRows(n - 1);
  take.starts = Eigen::Vector2i(0, n - 1);
  take.anchor_weight = cut.anchor_weight;
  RowBuilder with_pin, alone;
  with_pin.Add(0, 1, 0.5, 0, 1, {{50, 1.0}});
  with_pin.Add(1, 0, cut.rest(0, 0), 0, 0, {{0, 1.0}});
  with_pin.Add(0, 1, cut.rest(0, 1), 0, 0, {{0, 1.0}});
  alone.Add(0, 1, 0.5, 0, 1, {{49, 1.0}});
  const SeparationRows rows = with_pin.Build();
  const Trajectory2 free = Solve(take, alone.Build()).positions;
  const SeparationResult r = Solve(cut, rows);
  EXPECT_NEAR((r.positions.row(0) - cut.rest.row(0)).norm(), 0.0, 1e-9);
  EXPECT_GT((free.row(0) - take.rest.row(0)).norm(), 0.1);   // the push moves the whole take
  EXPECT_LT((r.positions.bottomRows(n - 1) - free).cwiseAbs().maxCoeff(), 1e-9);
  cut.cut_into.resize(0);
  EXPECT_GT((Solve(cut, rows).positions.bottomRows(n - 1) - free).cwiseAbs().maxCoeff(), 0.05);
}

TEST(Separation, OneSidedRowsPushButNeverPull) {
  const int n = 81;
  const SeparationProblem p = HeadOn(n);
  RowBuilder b;
  // Already satisfied: agent 0's frame 0 is 8 away along x from agent 1's frame 0.
  b.Add(-1, 0, 1.0, 0, 1, {{0, 1.0}, {n, -1.0}});
  // Violated: must be 0.7 apart along y at the crossing.
  b.Add(0, -1, 0.7, 0, 1, {{40, -1.0}, {n + 40, 1.0}});
  const SeparationResult r = Solve(p, b.Build());
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.forces[0], 0.0);
  EXPECT_GE(r.residuals[0], 0.0);
  EXPECT_GT(r.forces[1], 0.0);
  EXPECT_NEAR(r.residuals[1], 0.0, 1e-6);
  // As an equality the first row would pull the agents together to 1.0.
  RowBuilder eq;
  eq.Add(-1, 0, 1.0, 0, 0, {{0, 1.0}, {n, -1.0}});
  const SeparationResult pulled = Solve(p, eq.Build());
  EXPECT_NEAR(pulled.residuals[0], 0.0, 1e-9);
}

TEST(Separation, StationaryRangesMoveRigidly) {
  const int n = 81;
  SeparationProblem p = HeadOn(n);
  // Agent 0 stands still on frames 30..50 (all at one spot), agent 1 turns in place rigidly
  // along a small arc on frames 35..45.
  for (int i = 30; i <= 50; ++i) p.rest.row(i) << -1.0, 0.0;
  p.rigid = {{30, 50}, {n + 35, n + 45}};
  RowBuilder b;
  b.Add(0, -1, 0.7, 0, 0, {{40, -1.0}, {n + 40, 1.0}});
  const SeparationResult r = Solve(p, b.Build());
  EXPECT_NEAR(r.residuals[0], 0.0, 1e-9);
  for (int i = 31; i <= 50; ++i) EXPECT_NEAR((r.positions.row(i) - r.positions.row(30)).norm(), 0.0, 1e-9);
  EXPECT_GT((r.positions.row(30) - p.rest.row(30)).norm(), 0.01);
  // Agent 1's range keeps its pairwise distances.
  for (int i = n + 35; i <= n + 45; ++i)
    for (int j = n + 35; j <= n + 45; ++j)
      EXPECT_NEAR((r.positions.row(i) - r.positions.row(j)).norm(), (p.rest.row(i) - p.rest.row(j)).norm(), 1e-9);
}

TEST(Separation, ContradictingHardRowsAreRegularized) {
  const SeparationProblem p = HeadOn();
  RowBuilder b;
  b.Add(1, 0, 0.0, 0, 0, {{10, 1.0}});
  b.Add(1, 0, 0.5, 0, 0, {{10, 1.0}});  // the same vertex, elsewhere
  const SeparationResult r = Solve(p, b.Build());
  EXPECT_TRUE(r.regularized);
  EXPECT_TRUE(r.positions.allFinite());
}

TEST(Separation, TheCacheGivesTheSameAnswer) {
  const int n = 81;
  const SeparationProblem p = HeadOn(n);
  mocapedit::SeparationData data;
  mocapedit::SeparationPrecompute(p, data);
  auto cache = mocapedit::SeparationNewCache();
  SeparationSettings settings;
  settings.tolerance = 1e-10;
  for (int round = 0; round < 3; ++round) {
    RowBuilder b;
    for (int k = 0; k <= round; ++k) b.Add(0, -1, 0.7, 0, 1, {{38 + 2 * k, -1.0}, {n + 38 + 2 * k, 1.0}});
    const SeparationRows rows = b.Build();
    SeparationResult cached, fresh;
    mocapedit::SeparationSolve(data, rows, settings, *cache, cached);
    mocapedit::SeparationSolve(data, rows, settings, fresh);
    EXPECT_NEAR((cached.positions - fresh.positions).cwiseAbs().maxCoeff(), 0.0, 1e-12) << "round " << round;
  }
}

TEST(Separation, WarmStartsOfBothStepsResumeTheSolve) {
  // Rows several frames apart along the crossing: the forces of a converged solve, given
  // back as the starting forces of each step, are a solution already (no force changes),
  // and a solve on the same cache with the same rows reuses the blocks and agrees.
  const int n = 81;
  const SeparationProblem p = HeadOn(n);
  RowBuilder b;
  for (int k = 30; k <= 50; k += 4) b.Add(0, -1, 0.7, 0, 1, {{k, -1.0}, {n + k, 1.0}});
  SeparationRows rows = b.Build();
  mocapedit::SeparationData data;
  mocapedit::SeparationPrecompute(p, data);
  auto cache = mocapedit::SeparationNewCache();
  SeparationSettings settings;
  settings.tolerance = 1e-9;
  SeparationResult cold;
  mocapedit::SeparationSolve(data, rows, settings, *cache, cold);
  ASSERT_TRUE(cold.converged);
  EXPECT_GT(cold.updates, 0);
  EXPECT_GT(cold.inverse_columns, 0);
  EXPECT_GT((cold.forces - cold.shape_forces).cwiseAbs().maxCoeff(), 1e-6);  // the steps differ
  rows.initial_forces = cold.forces;
  rows.initial_shape_forces = cold.shape_forces;
  SeparationResult warm;
  mocapedit::SeparationSolve(data, rows, settings, *cache, warm);
  EXPECT_EQ(warm.updates, 0);
  EXPECT_EQ(warm.inverse_columns, 0);
  EXPECT_NEAR((warm.positions - cold.positions).cwiseAbs().maxCoeff(), 0.0, 1e-12);
  // Step 1 started from step 2's forces (the old warm start) has work to do.
  rows.initial_shape_forces.resize(0);
  SeparationResult mixed;
  mocapedit::SeparationSolve(data, rows, settings, *cache, mixed);
  EXPECT_GT(mixed.updates, 0);
  EXPECT_NEAR((mixed.positions - cold.positions).cwiseAbs().maxCoeff(), 0.0, 1e-6);
}

TEST(Separation, ItsEnergyIsThePathEditors) {
  // An agent walks along x, slows to a sway of millimetres (steps much shorter than the
  // baseline), turns in place along an arc (a stationary range) and walks on; frame 45 is
  // pinned 0.5 aside.
  const int n = 70;
  const double baseline = 0.05, anchor = 1e-3;
  Trajectory2 z(n, 2);
  double x = 0.0;
  for (int i = 0; i < n; ++i) {
    const bool slow = i >= 15 && i < 30;
    x += slow ? 0.001 : 0.1;
    z.row(i) << x, slow ? 0.004 * ((i % 2) ? 1.0 : -1.0) : 0.0;
  }
  for (int i = 32; i <= 38; ++i) z.row(i) << x - 1.6 + 0.2 * std::sin(0.2 * (i - 32)), 0.2 - 0.2 * std::cos(0.2 * (i - 32));
  const int pin = 45;
  const double px = z(pin, 0), py = z(pin, 1) + 0.5;

  SeparationProblem sp;
  sp.rest = z;
  sp.starts.resize(2);
  sp.starts << 0, n;
  sp.rigid = {{32, 38}};
  sp.anchor_weight = anchor;
  sp.min_baseline = baseline;
  RowBuilder b;
  b.Add(1, 0, px, 0, 0, {{pin, 1.0}});
  b.Add(0, 1, py, 0, 0, {{pin, 1.0}});
  const SeparationResult sr = Solve(sp, b.Build());

  // The path editor on the same energy: the agent's chain terms at the baseline, a soft
  // handle at every frame's rest position as its anchor, a hard handle for the pin.
  mocapedit::PathEditProblem pp;
  pp.rest = z;
  pp.triangles.resize(0, 3);
  pp.edges.resize(0, 2);
  mocapedit::AppendChainTerms(z, 0, n, baseline, pp.triangles, pp.edges);
  pp.rigid = {{{32, 33, 34, 35, 36, 37, 38}, mocapedit::RigidMode::kRotate}};
  pp.handles.resize(n + 1);
  pp.handle_weights.resize(n + 1);
  Trajectory2 handles(n + 1, 2);
  for (int i = 0; i < n; ++i) {
    pp.handles[i] = i;
    pp.handle_weights[i] = anchor;
    handles.row(i) = z.row(i);
  }
  pp.handles[n] = pin;
  pp.handle_weights[n] = std::numeric_limits<double>::infinity();
  handles.row(n) << px, py;
  mocapedit::PathEditData data;
  mocapedit::PathEditPrecompute(pp, data);
  mocapedit::PathEditResult pr;
  mocapedit::PathEditSolve(data, handles, Trajectory2(0, 2), pr);

  EXPECT_GT((sr.positions - z).rowwise().norm().maxCoeff(), 0.4);
  EXPECT_NEAR((sr.shape - pr.shape).cwiseAbs().maxCoeff(), 0.0, 1e-9);
  EXPECT_NEAR((sr.positions - pr.positions).cwiseAbs().maxCoeff(), 0.0, 1e-9);
  EXPECT_NEAR(sr.rigid_angles[0], pr.rigid_angles[0], 1e-9);
}

TEST(Separation, ABigCrowdSweepsOnTwoThreadsWithTheSameForcesAsOnOne) {
  // 40 walkers side by side along x, 1 apart, each walking along y; one-sided rows push
  // every neighbouring pair 1.2 apart every 10 frames: the rows of each half of the crowd
  // swept on a thread of its own (split_from 0), and the rows between the halves after them.
  const int agents = 40, n = 600;
  SeparationProblem p;
  p.rest.resize(agents * n, 2);
  p.starts.resize(agents + 1);
  for (int a = 0; a < agents; ++a) {
    p.starts[a] = a * n;
    for (int i = 0; i < n; ++i) p.rest.row(a * n + i) << 1.0 * a, -3.0 + 6.0 * i / (n - 1) + 0.01 * a;
  }
  p.starts[agents] = agents * n;
  RowBuilder b;
  for (int a = 0; a + 1 < agents; ++a)
    for (int f = 5 + a % 3; f < n; f += 10) b.Add(1, 0, 1.2, 0, 1, {{(a + 1) * n + f, 1.0}, {a * n + f, -1.0}});
  const SeparationRows rows = b.Build();
  SeparationSettings settings;
  settings.tolerance = 1e-9;
  settings.max_sweeps = 2000;
  settings.split_from = 0;
  const int budget = mocapedit::ThreadBudget();
  mocapedit::SetThreadBudget(2);  // two threads even where the machine or MOCAPEDIT_THREADS says one
  SeparationResult results[2], in_time_order;
  for (int threads : {1, 2}) {
    p.threads = threads;
    mocapedit::SeparationData data;
    mocapedit::SeparationPrecompute(p, data);
    mocapedit::SeparationSolve(data, rows, settings, results[threads - 1]);
    if (threads == 2) {
      SeparationSettings ordered = settings;
      ordered.split_from = -1;
      mocapedit::SeparationSolve(data, rows, ordered, in_time_order);
    }
  }
  mocapedit::SetThreadBudget(budget);
  const SeparationResult& one = results[0];
  const SeparationResult& two = results[1];
  EXPECT_TRUE(one.converged);
  EXPECT_EQ(one.sweeps, two.sweeps);
  EXPECT_EQ(one.updates, two.updates);
  ASSERT_EQ(one.forces.size(), two.forces.size());
  for (Eigen::Index r = 0; r < one.forces.size(); ++r) {
    EXPECT_EQ(one.forces[r], two.forces[r]) << "row " << r;
    EXPECT_EQ(one.shape_forces[r], two.shape_forces[r]) << "row " << r;
  }
  EXPECT_EQ((one.positions - two.positions).cwiseAbs().maxCoeff(), 0.0);
  // Every row is met; a row that pushes sits on its bound.
  for (Eigen::Index r = 0; r < one.forces.size(); ++r) {
    EXPECT_GE(one.forces[r], 0.0);
    EXPECT_GE(one.residuals[r], -1e-6) << "row " << r;
    if (one.forces[r] > 1e-6) EXPECT_NEAR(one.residuals[r], 0.0, 1e-6) << "row " << r;
  }
  EXPECT_GT(one.forces.maxCoeff(), 0.0);
  // The halves are another order than time order (other forces, within the tolerance).
  EXPECT_TRUE(in_time_order.converged);
  EXPECT_GT((in_time_order.forces - one.forces).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_NEAR((in_time_order.positions - one.positions).cwiseAbs().maxCoeff(), 0.0, 1e-6);
}
