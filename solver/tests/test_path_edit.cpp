#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <limits>
#include <thread>

#include "mocapedit/path_edit.h"

using mocapedit::ContradictionError;
using mocapedit::ConstraintRef;
using mocapedit::PathEditData;
using mocapedit::PathEditProblem;
using mocapedit::PathEditResult;
using mocapedit::RigidMode;
using mocapedit::Trajectory2;

namespace {

constexpr double kHard = std::numeric_limits<double>::infinity();

// A walk along x with a lateral sway: `n` frames, `step` stage units per frame.
Trajectory2 Walk(int n, double step = 5.0, double sway = 3.0) {
  Trajectory2 z(n, 2);
  for (int i = 0; i < n; ++i) z.row(i) << i * step, sway * std::sin(i / 5.0);
  return z;
}

PathEditProblem Chain(const Trajectory2& z) {
  PathEditProblem p;
  p.rest = z;
  p.triangles.resize(0, 3);
  p.edges.resize(0, 2);
  mocapedit::AppendChainTerms(z, 0, static_cast<int>(z.rows()), 1e-6, p.triangles, p.edges);
  return p;
}

void SetHandles(PathEditProblem& p, std::initializer_list<int> vs, double weight = kHard) {
  p.handles.resize(static_cast<Eigen::Index>(vs.size()));
  int k = 0;
  for (int v : vs) p.handles[k++] = v;
  p.handle_weights = Eigen::VectorXd::Constant(p.handles.size(), weight);
}

PathEditResult Solve(const PathEditProblem& p, const Trajectory2& handles, const Trajectory2& links = Trajectory2(0, 2)) {
  PathEditData d;
  mocapedit::PathEditPrecompute(p, d);
  PathEditResult r;
  mocapedit::PathEditSolve(d, handles, links, r);
  return r;
}

Trajectory2 Rows(const Trajectory2& z, const Eigen::VectorXi& idx) {
  Trajectory2 out(idx.size(), 2);
  for (Eigen::Index k = 0; k < idx.size(); ++k) out.row(k) = z.row(idx[k]);
  return out;
}

// Apply the similarity x -> s x + t (complex) to every row.
Trajectory2 Similar(const Trajectory2& z, std::complex<double> s, std::complex<double> t) {
  Trajectory2 out(z.rows(), 2);
  for (Eigen::Index i = 0; i < z.rows(); ++i) {
    const std::complex<double> x = s * std::complex<double>(z(i, 0), z(i, 1)) + t;
    out.row(i) << x.real(), x.imag();
  }
  return out;
}

double Length(const Trajectory2& z) { return mocapedit::PathLength(z); }

}  // namespace

TEST(PathEdit, ValidityRejectsBadProblems) {
  const Trajectory2 z = Walk(10);
  PathEditData d;
  {
    PathEditProblem p = Chain(z);
    p.triangles(0, 1) = 42;
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    p.edge_weights = Eigen::VectorXd::Constant(p.edges.rows(), -1.0);
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    p.triangle_weights = Eigen::VectorXd::Constant(p.triangles.rows(), kHard);  // shape terms cannot be hard
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    SetHandles(p, {0, 9});
    p.handle_weights.resize(1);
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    p.links.resize(1, 2);
    p.links << 3, 3;
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    p.rigid = {{{2, 3, 4}, RigidMode::kRotate}, {{4, 5}, RigidMode::kRotate}};
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    p.rest.row(4) = p.rest.row(2);  // triangle (3; 2, 4) has no frame
    EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  }
  {
    PathEditProblem p = Chain(z);
    SetHandles(p, {0, 9});
    mocapedit::PathEditPrecompute(p, d);
    PathEditResult r;
    EXPECT_THROW(mocapedit::PathEditSolve(d, Trajectory2::Zero(3, 2), Trajectory2(0, 2), r), mocapedit::InvalidInput);
    Trajectory2 nan = Trajectory2::Zero(2, 2);
    nan(1, 0) = std::nan("");
    EXPECT_THROW(mocapedit::PathEditSolve(d, nan, Trajectory2(0, 2), r), mocapedit::InvalidInput);
  }
}

TEST(PathEdit, ChainTermsWidenAroundFramesThatStandStill) {
  Trajectory2 z(7, 2);
  z << 0, 0, 1, 0, 2, 0, 2, 0, 2, 0, 3, 0, 4, 0;  // stands still on frames 2..4
  mocapedit::IndexTriples t(0, 3);
  mocapedit::IndexPairs e(0, 2);
  mocapedit::AppendChainTerms(z, 0, 7, 0.5, t, e);
  EXPECT_EQ(e.rows(), 6);
  for (Eigen::Index k = 0; k < t.rows(); ++k) {
    EXPECT_LT(t(k, 1), t(k, 0));
    EXPECT_GT(t(k, 2), t(k, 0));
    EXPECT_GE((z.row(t(k, 2)) - z.row(t(k, 1))).norm(), 0.5) << "triangle " << k;
  }
  EXPECT_EQ(t.rows(), 5);
}

TEST(PathEdit, ConstraintsARigidMotionMeetsGiveExactlyThatMotion) {
  const Trajectory2 z = Walk(200);
  PathEditProblem p = Chain(z);
  p.rigid = {{{80, 81, 82, 83, 84, 85}, RigidMode::kRotate}};
  SetHandles(p, {0, 120, 199});
  const std::complex<double> rot = std::polar(1.0, 0.7), shift(250.0, -40.0);
  const Trajectory2 moved = Similar(z, rot, shift);
  const PathEditResult r = Solve(p, Rows(moved, p.handles));
  EXPECT_TRUE(r.rigid_motion);
  EXPECT_EQ(r.step1.solver, "rigid");
  EXPECT_NEAR(r.rigid_angle, 0.7, 1e-15);
  EXPECT_NEAR(r.rigid_angles[0], 0.7, 1e-15);
  EXPECT_LE((r.positions - moved).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(PathEdit, OneHandleTranslates) {
  const Trajectory2 z = Walk(50);
  PathEditProblem p = Chain(z);
  SetHandles(p, {20});
  Trajectory2 h(1, 2);
  h << z(20, 0) + 7, z(20, 1) - 3;
  const PathEditResult r = Solve(p, h);
  EXPECT_TRUE(r.rigid_motion);
  EXPECT_LE((r.positions.rowwise() - Eigen::RowVector2d(7, -3) - z).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(PathEdit, StepOneKeepsASimilarityAndStepTwoRestoresLengths) {
  const Trajectory2 z = Walk(300);
  {
    // Two handles a similarity meets: step 1 is exactly that similarity; step 2 has to
    // stretch the path to reach the handles, and stretches it evenly.
    PathEditProblem p = Chain(z);
    SetHandles(p, {0, 299});
    const std::complex<double> s = std::polar(1.25, -0.4), t(30.0, 12.0);
    const Trajectory2 target = Similar(z, s, t);
    const PathEditResult r = Solve(p, Rows(target, p.handles));
    EXPECT_FALSE(r.rigid_motion);
    EXPECT_LE((r.shape - target).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_LE((Rows(r.positions, p.handles) - Rows(target, p.handles)).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_NEAR(Length(r.shape) / Length(z), 1.25, 1e-9);
  }
  {
    // A bend with a free end: step 1 scales the bent half, step 2 gives the length back.
    PathEditProblem p = Chain(z);
    SetHandles(p, {0, 150});
    Trajectory2 h = Rows(z, p.handles);
    h(1, 1) += 300.0;
    const PathEditResult r = Solve(p, h);
    const double shape = Length(r.shape) / Length(z), edited = Length(r.positions) / Length(z);
    EXPECT_GT(shape - 1.0, 0.05);
    EXPECT_LT(edited - 1.0, 0.5 * (shape - 1.0));
  }
}

TEST(PathEdit, MovingTheMiddleOfATenMetreWalkKeepsItsLength) {
  const Trajectory2 z = Walk(301, 3.33, 2.0);  // ~10 m in cm, 2 cm sway
  for (bool pin_end : {false, true}) {
    PathEditProblem p = Chain(z);
    if (pin_end)
      SetHandles(p, {0, 150, 300});
    else
      SetHandles(p, {0, 150});
    Trajectory2 h = Rows(z, p.handles);
    h(1, 1) += 100.0;  // 1 m sideways
    const PathEditResult r = Solve(p, h);
    EXPECT_LE((Rows(r.positions, p.handles) - h).cwiseAbs().maxCoeff(), 1e-9);
    const double change = std::abs(Length(r.positions) / Length(z) - 1.0);
    // With both ends pinned any path through the three points is at least 1.98% longer
    // (two straight 5.1 m legs); the solve stays close to that bound.
    EXPECT_LT(change, pin_end ? 0.025 : 0.02) << (pin_end ? "ends pinned" : "start pinned");
    if (pin_end) {  // no overshoot: nothing moves further sideways than the handle, or back
      EXPECT_LE((r.positions.col(1) - z.col(1)).maxCoeff(), 100.0 + 1e-6);
      EXPECT_GE((r.positions.col(1) - z.col(1)).minCoeff(), -1e-6);
    }
  }
}

TEST(PathEdit, RotatingRangesMoveRigidlyAndReportTheirTurn) {
  const Trajectory2 z = Walk(120);
  PathEditProblem p = Chain(z);
  std::vector<int> range;
  for (int i = 40; i <= 70; ++i) range.push_back(i);
  p.rigid = {{range, RigidMode::kRotate}};
  SetHandles(p, {0, 119});
  Trajectory2 h = Rows(z, p.handles);
  h.row(1) << 300.0, 350.0;  // a strong bend
  const PathEditResult r = Solve(p, h);
  const double a = r.rigid_angles[0];
  const std::complex<double> rot = std::polar(1.0, a);
  const std::complex<double> x40(r.positions(40, 0), r.positions(40, 1)), z40(z(40, 0), z(40, 1));
  for (int i : range) {
    const std::complex<double> expect = x40 + rot * (std::complex<double>(z(i, 0), z(i, 1)) - z40);
    EXPECT_NEAR(r.positions(i, 0), expect.real(), 1e-9);
    EXPECT_NEAR(r.positions(i, 1), expect.imag(), 1e-9);
  }
  EXPECT_GT(std::abs(a), 0.1);
}

TEST(PathEdit, TranslatingRangesNeverTurn) {
  const Trajectory2 z = Walk(60);
  PathEditProblem p = Chain(z);
  std::vector<int> all(60);
  for (int i = 0; i < 60; ++i) all[i] = i;
  p.rigid = {{all, RigidMode::kTranslate}};
  p.links.resize(1, 2);
  p.links << 10, 50;
  p.link_weights = Eigen::VectorXd::Constant(1, 1.0);  // soft: wants a turn it cannot make
  SetHandles(p, {10});
  Trajectory2 link(1, 2);
  link << 0.0, -200.0;
  const PathEditResult r = Solve(p, Rows(z, p.handles), link);
  EXPECT_LE((r.positions - z).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(r.rigid_angles[0], 0.0);
}

TEST(PathEdit, HardLinksHoldExactlyAndSoftLinksPull) {
  // Two agents side by side: vertices 0..99 and 100..199.
  Trajectory2 z(200, 2);
  z.topRows(100) = Walk(100);
  z.bottomRows(100) = Walk(100);
  z.bottomRows(100).col(1).array() += 200.0;
  PathEditProblem p;
  p.rest = z;
  p.triangles.resize(0, 3);
  p.edges.resize(0, 2);
  mocapedit::AppendChainTerms(z, 0, 100, 1e-6, p.triangles, p.edges);
  mocapedit::AppendChainTerms(z, 100, 100, 1e-6, p.triangles, p.edges);
  SetHandles(p, {0, 99, 100, 199});
  p.links.resize(1, 2);
  p.links << 150, 50;  // B at frame 50 sits 60 left of A at frame 50
  p.link_weights = Eigen::VectorXd::Constant(1, kHard);
  Trajectory2 offset(1, 2);
  offset << 0.0, 60.0;
  const PathEditResult r = Solve(p, Rows(z, p.handles), offset);
  EXPECT_LE(((r.positions.row(150) - r.positions.row(50)) - offset.row(0)).norm(), 1e-9);
  EXPECT_LE((Rows(r.positions, p.handles) - Rows(z, p.handles)).cwiseAbs().maxCoeff(), 1e-9);
  p.link_weights[0] = 1.0;
  const PathEditResult soft = Solve(p, Rows(z, p.handles), offset);
  const double before = ((z.row(150) - z.row(50)) - offset.row(0)).norm();
  const double after = ((soft.positions.row(150) - soft.positions.row(50)) - offset.row(0)).norm();
  EXPECT_GT(after, 1e-6);
  EXPECT_LT(after, 0.5 * before);
}

TEST(PathEdit, ContradictionsNameEveryConstraintInvolved) {
  const Trajectory2 z = Walk(40);
  {
    PathEditProblem p = Chain(z);
    SetHandles(p, {5, 20, 5});
    Trajectory2 h = Rows(z, p.handles);
    h(2, 0) += 1.0;
    try {
      Solve(p, h);
      FAIL() << "expected a contradiction";
    } catch (const ContradictionError& e) {
      ASSERT_EQ(e.constraints.size(), 2u);
      EXPECT_EQ(e.constraints[0].kind, ConstraintRef::kHandle);
      EXPECT_EQ(e.constraints[0].index, 0);
      EXPECT_EQ(e.constraints[1].index, 2);
      EXPECT_NEAR(e.mismatch, 1.0, 1e-12);
    }
    h(2, 0) -= 1.0;  // the same place twice is fine
    EXPECT_NO_THROW(Solve(p, h));
  }
  {
    // A cycle of three hard links whose offsets do not add up.
    PathEditProblem p = Chain(z);
    p.links.resize(4, 2);
    p.links << 1, 10, 10, 20, 20, 1, 30, 35;
    p.link_weights = Eigen::VectorXd::Constant(4, kHard);
    SetHandles(p, {0, 39});
    Trajectory2 o(4, 2);
    o << 1, 0, 1, 0, -1.5, 0, 0, 0;
    try {
      Solve(p, Rows(z, p.handles), o);
      FAIL() << "expected a contradiction";
    } catch (const ContradictionError& e) {
      std::vector<int> links;
      for (const auto& c : e.constraints) {
        EXPECT_EQ(c.kind, ConstraintRef::kLink);
        links.push_back(c.index);
      }
      std::sort(links.begin(), links.end());
      EXPECT_EQ(links, (std::vector<int>{0, 1, 2}));
      EXPECT_NEAR(e.mismatch, 0.5, 1e-12);
    }
  }
  {
    // A rotating range cannot hold two hard handles further apart than its rest shape.
    PathEditProblem p = Chain(z);
    p.rigid = {{{10, 11, 12, 13, 14}, RigidMode::kRotate}};
    SetHandles(p, {10, 14});
    Trajectory2 h = Rows(z, p.handles);
    h(1, 0) += 5.0;
    try {
      Solve(p, h);
      FAIL() << "expected a contradiction";
    } catch (const ContradictionError& e) {
      bool range = false;
      for (const auto& c : e.constraints) range |= c.kind == ConstraintRef::kRigid;
      EXPECT_TRUE(range);
      EXPECT_EQ(e.constraints.size(), 3u);
    }
  }
}

TEST(PathEdit, LongClipsAreAsAccurateAsShortOnes) {
  // Handles that a similarity meets: the exact step-1 answer is that similarity, so the
  // error is measurable. Relative to the clip's extent it must not grow with the length.
  const std::complex<double> s = std::polar(1.1, 0.3), t(100.0, 50.0);
  double worst_short = 0, worst_long = 0;
  for (int n : {200, 20000}) {
    const Trajectory2 z = Walk(n);
    PathEditProblem p = Chain(z);
    SetHandles(p, {0, n / 3, n - 1});
    const Trajectory2 target = Similar(z, s, t);
    const PathEditResult r = Solve(p, Rows(target, p.handles));
    const double err = (r.shape - target).cwiseAbs().maxCoeff() / (5.0 * n);
    (n == 200 ? worst_short : worst_long) = err;
    EXPECT_LE(err, 1e-12) << n << " frames, solver " << r.step1.solver;
  }
  EXPECT_GT(worst_long, 0.0);
  EXPECT_GT(worst_short, 0.0);
}

TEST(PathEdit, QRAndResponsesAgreeWithTheDirectSolve) {
  const Trajectory2 z = Walk(400);
  PathEditProblem p = Chain(z);
  p.rigid = {{{100, 101, 102, 103, 104, 105, 106}, RigidMode::kRotate}};
  SetHandles(p, {0, 200, 399});
  p.handle_weights[1] = 2.0;  // one soft handle
  Trajectory2 h = Rows(z, p.handles);
  h(1, 1) += 150.0;
  h(2, 0) -= 80.0;
  const PathEditResult direct = Solve(p, h);
  EXPECT_EQ(direct.step1.solver, "LDLT");
  PathEditProblem q = p;
  q.force_qr = true;
  const PathEditResult qr = Solve(q, h);
  EXPECT_EQ(qr.step1.solver, "SPQR");
  EXPECT_LE((qr.positions - direct.positions).cwiseAbs().maxCoeff(), 1e-8);
  PathEditProblem i = p;
  i.precompute_responses = true;
  PathEditData d;
  mocapedit::PathEditPrecompute(i, d);
  PathEditResult r;
  Trajectory2 other = h;
  other(1, 0) += 30.0;
  mocapedit::PathEditSolve(d, other, Trajectory2(0, 2), r);  // a drag, then back
  mocapedit::PathEditSolve(d, h, Trajectory2(0, 2), r);
  EXPECT_LE((r.positions - direct.positions).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE((r.shape - direct.shape).cwiseAbs().maxCoeff(), 1e-8);
}

TEST(PathEdit, ChainsOfAgentsWithLongRangeTermsUseTheEnvelopeFactorAndAgreeWithQR) {
  // Six agents of 60 frames, each handing over to the next at its last frame (hard links),
  // each with a soft link between its own first and last frames: the bandwidth is a whole
  // agent, the envelope stays narrow, so both steps take the envelope LDLT.
  const int agents = 6, frames = 60;
  Trajectory2 z(agents * frames, 2);
  for (int a = 0; a < agents; ++a)
    for (int f = 0; f < frames; ++f)
      z.row(a * frames + f) << 0.5 * std::sin(0.7 * a) + 3.0 * std::sin(f / 5.0), (a * (frames - 1) + f) * 5.0 + a;
  PathEditProblem p;
  p.rest = z;
  p.triangles.resize(0, 3);
  p.edges.resize(0, 2);
  for (int a = 0; a < agents; ++a) mocapedit::AppendChainTerms(z, a * frames, frames, 1e-6, p.triangles, p.edges);
  p.links.resize(2 * agents - 1, 2);
  p.link_weights.resize(2 * agents - 1);
  Trajectory2 offsets(2 * agents - 1, 2);
  for (int a = 0; a + 1 < agents; ++a) {
    p.links.row(a) << a * frames + frames - 1, (a + 1) * frames;
    p.link_weights[a] = kHard;
    offsets.row(a) << 0.4, -1.0;
  }
  for (int a = 0; a < agents; ++a) {
    const int l = agents - 1 + a, first = a * frames, last = first + frames - 1;
    p.links.row(l) << first, last;
    p.link_weights[l] = 0.01;
    offsets.row(l) = z.row(first) - z.row(last);
  }
  SetHandles(p, {0, agents * frames - 1, 3 * frames + 20});
  Trajectory2 h = Rows(z, p.handles);
  h.row(1) += Eigen::RowVector2d(30.0, -20.0);
  h.row(2) += Eigen::RowVector2d(15.0, 0.0);
  const PathEditResult r = Solve(p, h, offsets);
  EXPECT_EQ(r.step1.solver, "LDLT");
  EXPECT_EQ(r.step2.solver, "LDLT");
  // An exact factor converges in two passes (one from the start, one to confirm); a
  // slightly wrong one still converges to the same answer, in more passes.
  EXPECT_LE(r.step1.refinements, 2);
  EXPECT_LE(r.step2.refinements, 2);
  PathEditProblem q = p;
  q.force_qr = true;
  const PathEditResult qr = Solve(q, h, offsets);
  EXPECT_LE((r.positions - qr.positions).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE((r.shape - qr.shape).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE((Rows(r.positions, p.handles) - h).cwiseAbs().maxCoeff(), 1e-9);
  for (int a = 0; a + 1 < agents; ++a) {
    const Eigen::RowVector2d gap = r.positions.row(a * frames + frames - 1) - r.positions.row((a + 1) * frames);
    EXPECT_LE((gap - offsets.row(a)).cwiseAbs().maxCoeff(), 1e-9);
  }
}

TEST(PathEdit, SolvesFromSeveralThreadsAgree) {
  const Trajectory2 z = Walk(500);
  PathEditProblem p = Chain(z);
  SetHandles(p, {0, 250, 499});
  PathEditData d;
  mocapedit::PathEditPrecompute(p, d);
  std::vector<PathEditResult> out(4);
  std::vector<std::thread> threads;
  for (int k = 0; k < 4; ++k)
    threads.emplace_back([&, k] {
      Trajectory2 h = Rows(z, p.handles);
      h(1, 1) += 10.0 * (k % 2);
      mocapedit::PathEditSolve(d, h, Trajectory2(0, 2), out[k]);
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(out[0].positions, out[2].positions);
  EXPECT_EQ(out[1].positions, out[3].positions);
  EXPECT_GT((out[0].positions - out[1].positions).cwiseAbs().maxCoeff(), 1.0);
}

// A block of rows x cols walkers joined at every frame to their grid neighbours, as a group
// mesh is: a 3D-like structure whose factor has dense fronts. `h` gets the handle positions.
PathEditProblem WideMesh(Trajectory2& h, int rows = 8, int cols = 5, int frames = 80, bool diagonals = false) {
  const int n = rows * cols * frames;
  Trajectory2 z(n, 2);
  PathEditProblem p;
  p.triangles.resize(0, 3);
  p.edges.resize(0, 2);
  auto vertex = [&](int r, int c, int f) { return (r * cols + c) * frames + f; };
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      for (int f = 0; f < frames; ++f) z.row(vertex(r, c, f)) << 1.0 * c + 0.03 * std::sin(f / 4.0), 0.06 * f - 1.2 * r;
  p.rest = z;
  for (int a = 0; a < rows * cols; ++a) mocapedit::AppendChainTerms(z, a * frames, frames, 1e-3, p.triangles, p.edges);
  std::vector<std::array<int, 3>> tri;
  std::vector<std::array<int, 2>> edg;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      for (int f = 0; f + 1 < frames; ++f)
        for (auto [dr, dc] : {std::pair{1, 0}, std::pair{0, 1}, std::pair{1, 1}, std::pair{1, -1}}) {
          if (r + dr >= rows || c + dc >= cols || c + dc < 0 || (dr && dc && !diagonals)) continue;
          const int a = vertex(r, c, f), b = vertex(r + dr, c + dc, f);
          tri.push_back({a, b, b + 1});
          tri.push_back({b, a, a + 1});
          edg.push_back({a, b});
        }
  const Eigen::Index t0 = p.triangles.rows(), e0 = p.edges.rows();
  p.triangles.conservativeResize(t0 + static_cast<Eigen::Index>(tri.size()), 3);
  p.edges.conservativeResize(e0 + static_cast<Eigen::Index>(edg.size()), 2);
  for (size_t k = 0; k < tri.size(); ++k) p.triangles.row(t0 + k) << tri[k][0], tri[k][1], tri[k][2];
  for (size_t k = 0; k < edg.size(); ++k) p.edges.row(e0 + k) << edg[k][0], edg[k][1];
  SetHandles(p, {vertex(0, 0, 0), vertex(0, 0, frames / 2), vertex(0, 0, frames - 1)});
  h = Rows(z, p.handles);
  h.row(2) << 2.5, h(1, 1);   // turn the second half of the leader's walk
  return p;
}

TEST(PathEdit, WideMeshesUseTheSupernodalFactorAndAgreeWithQR) {
  Trajectory2 h;
  const PathEditProblem p = WideMesh(h);
  const PathEditResult r = Solve(p, h);
  EXPECT_EQ(r.step1.solver, "CHOLMOD supernodal");
  PathEditProblem q = p;
  q.force_qr = true;
  const PathEditResult qr = Solve(q, h);
  EXPECT_LE((r.positions - qr.positions).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE((Rows(r.positions, p.handles) - h).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(PathEdit, WideMeshesWithTimesAreOrderedByDissectionAndAgree) {
  Trajectory2 h;
  const int rows = 8, cols = 5, frames = 80;
  const PathEditProblem p = WideMesh(h, rows, cols, frames);
  PathEditProblem timed = p;
  timed.vertex_times.resize(p.rest.rows());
  for (Eigen::Index v = 0; v < p.rest.rows(); ++v) timed.vertex_times[v] = 100.0 + static_cast<double>(v % frames);
  const PathEditResult amd = Solve(p, h), nd = Solve(timed, h);
  EXPECT_EQ(nd.step1.solver, "CHOLMOD supernodal (nested dissection)");
  EXPECT_LE((nd.positions - amd.positions).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LE((Rows(nd.positions, p.handles) - h).cwiseAbs().maxCoeff(), 1e-9);
  // Times on other vertices than the grid's (one agent's constrained frame) change the
  // order, not the answer.
  timed.vertex_times[frames / 3] += 0.5;
  EXPECT_LE((Solve(timed, h).positions - amd.positions).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(PathEdit, WideMeshesKeepMinimumDegreeWhenTheDissectionFillsMore) {
  // 5 x 5 walkers of 120 frames: a long thin mesh, where AMD's order costs fewer flops than
  // the dissection's; the solver keeps it (and the answer does not depend on it).
  Trajectory2 h;
  const int frames = 120;
  const PathEditProblem p = WideMesh(h, 5, 5, frames);
  PathEditProblem timed = p;
  timed.vertex_times.resize(p.rest.rows());
  for (Eigen::Index v = 0; v < p.rest.rows(); ++v) timed.vertex_times[v] = static_cast<double>(v % frames);
  const PathEditResult amd = Solve(p, h), kept = Solve(timed, h);
  EXPECT_EQ(kept.step1.solver, "CHOLMOD supernodal");
  EXPECT_LE((kept.positions - amd.positions).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(PathEdit, SingularWideMeshesFallBackToQR) {
  // A vertex in no term: its column of the normal matrix is zero, CHOLMOD's factorization
  // fails, and QR takes over, in either order; the mesh is still solved.
  Trajectory2 h;
  PathEditProblem p = WideMesh(h);
  const Eigen::Index n = p.rest.rows();
  p.rest.conservativeResize(n + 1, 2);
  p.rest.row(n) << -50.0, -50.0;
  for (bool times : {false, true}) {
    if (times) p.vertex_times = Eigen::VectorXd::LinSpaced(n + 1, 0, 1);
    const PathEditResult r = Solve(p, h);
    EXPECT_EQ(r.step1.solver, "SPQR (singular)");
    EXPECT_LE((Rows(r.positions, p.handles) - h).cwiseAbs().maxCoeff(), 1e-9);
  }
}

TEST(PathEdit, RejectsBadVertexTimes) {
  Trajectory2 h;
  PathEditProblem p = WideMesh(h, 2, 2, 10);
  PathEditData d;
  p.vertex_times = Eigen::VectorXd::Zero(p.rest.rows() - 1);
  EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
  p.vertex_times = Eigen::VectorXd::Zero(p.rest.rows());
  p.vertex_times[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(mocapedit::PathEditPrecompute(p, d), mocapedit::InvalidInput);
}

TEST(PathEdit, WideMeshesFactoredOnSeveralThreadsAtOnceAgree) {
  // Components are solved on threads of their own: their BLAS calls must not interfere
  // (Debian's serial OpenBLAS is not thread-safe; see mocapedit/blas_lock.h). A race: without
  // the lock this failed in about half the runs, with diagonal links making fronts large
  // enough for OpenBLAS to use its shared buffers.
  Trajectory2 h;
  const PathEditProblem p = WideMesh(h, 10, 10, 24, true);
  const PathEditResult alone = Solve(p, h);
  constexpr int kEach = 5;
  std::vector<PathEditResult> out(2 * kEach);
  std::vector<std::thread> threads;
  for (int k = 0; k < 2; ++k)
    threads.emplace_back([&, k] {
      for (int i = 0; i < kEach; ++i) out[kEach * k + i] = Solve(p, h);
    });
  for (auto& t : threads) t.join();
  for (const PathEditResult& r : out) {
    EXPECT_EQ(r.step1.solver, "CHOLMOD supernodal");
    EXPECT_EQ(r.step2.solver, alone.step2.solver);
    EXPECT_LE((r.positions - alone.positions).cwiseAbs().maxCoeff(), 1e-12);
  }
}
