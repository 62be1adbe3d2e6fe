#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <stdexcept>
#include <vector>

#include "mocapedit/path_terms.h"

using mocapedit::IndexPairs;
using mocapedit::IndexTriples;
using mocapedit::Trajectory2;
using IntGrid = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

namespace {

// Agents walking side by side along +y, `frames` each, 1 apart in x.
Trajectory2 Walkers(int agents, int frames) {
  Trajectory2 p(agents * frames, 2);
  for (int a = 0; a < agents; ++a)
    for (int f = 0; f < frames; ++f) p.row(a * frames + f) << a + 0.03 * std::sin(0.5 * f), 0.06 * f;
  return p;
}

Eigen::VectorXi Offsets(int agents, int frames) {
  Eigen::VectorXi o(agents + 1);
  for (int a = 0; a <= agents; ++a) o[a] = a * frames;
  return o;
}

}  // namespace

TEST(PathTerms, ValidityRejectsBadInput) {
  const Trajectory2 rest = Walkers(3, 10);
  IndexTriples t;
  IndexPairs e;
  {
    Eigen::VectorXi bad(3);
    bad << 0, 10, 20;  // does not end at #V
    EXPECT_THROW(mocapedit::ComponentChainTerms(rest, bad, 0.01, t, e), mocapedit::InvalidInput);
  }
  {
    Eigen::VectorXi bad(4);
    bad << 0, 20, 10, 30;  // decreasing
    Eigen::VectorXi partner;
    EXPECT_THROW(mocapedit::FramePartners(rest, bad, 0.01, partner), mocapedit::InvalidInput);
  }
  {
    IntGrid members(3, 1);
    members << 0, 10, 20;
    const Eigen::VectorXi partner = Eigen::VectorXi::Constant(30, -1);
    EXPECT_THROW(mocapedit::GroupMeshTerms(rest, members, 3, partner, t, e), mocapedit::InvalidInput);  // k >= M
    members(2, 0) = 30;
    EXPECT_THROW(mocapedit::GroupMeshTerms(rest, members, 1, partner, t, e), mocapedit::InvalidInput);
  }
  {
    Eigen::VectorXi rows(1), cols(1);
    rows << 0;
    cols << 2;
    Eigen::VectorXcd values(1);
    values << 1.0;
    EXPECT_THROW(mocapedit::NullSpaceSupport(rows, cols, values, 1, 2, 1e-9), mocapedit::InvalidInput);
    cols << 0;
    EXPECT_THROW(mocapedit::NullSpaceSupport(rows, cols, values, 1, 2, 0.0), mocapedit::InvalidInput);
  }
  {
    IndexPairs blocks(1, 2);
    blocks << 0, 31;
    Eigen::VectorXd turns;
    EXPECT_THROW(mocapedit::BlockDeformationTurns(rest, rest, blocks, IndexTriples(0, 3), Eigen::VectorXd(), 2, 0.0, 0.0,
                                                  Eigen::VectorXi(), turns),
                 mocapedit::InvalidInput);
  }
}

TEST(PathTerms, ChainTermsOfAComponentAreEachAgents) {
  Trajectory2 rest = Walkers(3, 12);
  rest.middleRows(15, 4).rowwise() = rest.row(15);  // agent 1 stands still for a while
  const Eigen::VectorXi offsets = Offsets(3, 12);
  IndexTriples t, each_t(0, 3);
  IndexPairs e, each_e(0, 2);
  mocapedit::ComponentChainTerms(rest, offsets, 0.05, t, e);
  for (int a = 0; a < 3; ++a) mocapedit::AppendChainTerms(rest, offsets[a], 12, 0.05, each_t, each_e);
  EXPECT_EQ(t, each_t);
  EXPECT_EQ(e, each_e);
  EXPECT_EQ(e.rows(), 33);
}

TEST(PathTerms, SampleFramesAndPartners) {
  Eigen::VectorXd times(7);
  times << 0, 1, 2, 3, 10.5, 11.5, 12.5;  // two members
  Eigen::VectorXi offsets(3);
  offsets << 0, 4, 7;
  Eigen::VectorXd sampled(3);
  sampled << 1.0, 11.5 - 1e-8, 3.0;
  IntGrid frames;
  mocapedit::GroupSampleFrames(times, offsets, sampled, frames);
  EXPECT_EQ(frames(0, 0), 1);
  EXPECT_EQ(frames(0, 1), -1);  // after its last frame
  EXPECT_EQ(frames(0, 2), 3);
  EXPECT_EQ(frames(1, 0), -1);  // before its first
  EXPECT_EQ(frames(1, 1), 1);   // within 1e-6

  Trajectory2 rest(5, 2);
  rest << 0, 0, 0.5, 0, 1.0, 0, 1.0, 0, 3.0, 0;  // frame 3 stands on frame 2
  Eigen::VectorXi two(2);
  two << 0, 5;
  Eigen::VectorXi partner;
  mocapedit::FramePartners(rest, two, 0.9, partner);
  EXPECT_EQ(partner[0], 2);  // the first frame at least 0.9 along
  EXPECT_EQ(partner[1], 4);
  EXPECT_EQ(partner[3], 4);
  EXPECT_EQ(partner[4], 3);  // none later: the nearest earlier one 0.9 back along the path
}

TEST(PathTerms, GroupMeshJoinsNearestNeighboursOnce) {
  // Four members in a row at one sampled time: each joined to its nearest, ties to the
  // earlier member; every pair once.
  Trajectory2 rest(8, 2);
  rest << 0, 0, 0, 1, 1, 0, 1, 1, 2, 0, 2, 1, 3.5, 0, 3.5, 1;
  IntGrid members(4, 1);
  members << 0, 2, 4, 6;
  Eigen::VectorXi partner(8);
  partner << 1, -1, 3, -1, 5, -1, 7, -1;
  IndexTriples t;
  IndexPairs e;
  mocapedit::GroupMeshTerms(rest, members, 1, partner, t, e);
  // 0 -> 2; 2 -> 0 (ties 4, earlier wins); 4 -> 2; 6 -> 4.
  IndexPairs expected(3, 2);
  expected << 0, 2, 2, 4, 4, 6;
  EXPECT_EQ(e, expected);
  // Both orientations, the first of every edge before the second.
  IndexTriples tri(6, 3);
  tri << 0, 2, 3, 2, 4, 5, 4, 6, 7, 2, 0, 1, 4, 2, 3, 6, 4, 5;
  EXPECT_EQ(t, tri);
}

TEST(PathTerms, NullSpaceSupportOfSmallSystems) {
  // Body 0: translation t0 and similarity s0; body 1: translation t1 only.
  // Rows: t0 + s0 (1) = 0; t0 + s0 (-1) - t1 = 0. Three unknowns, two rows: s0 and t0
  // follow t1 (t0 = -s0, t1 = -2 s0), so every column is reached.
  Eigen::VectorXi rows(5), cols(5);
  rows << 0, 0, 1, 1, 1;
  cols << 0, 1, 0, 1, 2;
  Eigen::VectorXcd values(5);
  values << 1.0, 1.0, 1.0, -1.0, -1.0;
  EXPECT_EQ(mocapedit::NullSpaceSupport(rows, cols, values, 2, 3, 1e-9), std::vector<char>({1, 1, 1}));
  // A third row t1 = 0 fixes everything.
  Eigen::VectorXi rows3(6), cols3(6);
  rows3 << 0, 0, 1, 1, 1, 2;
  cols3 << 0, 1, 0, 1, 2, 2;
  Eigen::VectorXcd values3(6);
  values3 << 1.0, 1.0, 1.0, -1.0, -1.0, 1.0;
  EXPECT_EQ(mocapedit::NullSpaceSupport(rows3, cols3, values3, 3, 3, 1e-9), std::vector<char>({0, 0, 0}));
  // Two handles at coinciding points leave the similarity free: only t0 + s0 d = 0, twice.
  Eigen::VectorXi rows2(4), cols2(4);
  rows2 << 0, 0, 1, 1;
  cols2 << 0, 1, 0, 1;
  Eigen::VectorXcd same(4);
  same << 1.0, std::complex<double>(0.3, 0.4), 1.0, std::complex<double>(0.3, 0.4);
  EXPECT_EQ(mocapedit::NullSpaceSupport(rows2, cols2, same, 2, 2, 1e-9), std::vector<char>({1, 1}));
  // A column that no row holds is free; with no rows at all, every column is.
  EXPECT_EQ(mocapedit::NullSpaceSupport(rows3, cols3, values3, 3, 4, 1e-9), std::vector<char>({0, 0, 0, 1}));
  EXPECT_EQ(mocapedit::NullSpaceSupport(Eigen::VectorXi(), Eigen::VectorXi(), Eigen::VectorXcd(), 0, 2, 1e-9),
            std::vector<char>({1, 1}));
}

TEST(PathTerms, BlockTurnsAreEachBlocksDeformationTurns) {
  const Trajectory2 rest = Walkers(3, 20);
  Trajectory2 edited = rest;
  for (Eigen::Index i = 0; i < edited.rows(); ++i) edited.row(i) << -rest(i, 1), rest(i, 0) + 0.01 * i;
  IndexPairs blocks(2, 2);
  blocks << 20, 40, 0, 20;
  IndexTriples fixed(1, 3);
  fixed << 1, 5, 9;
  Eigen::VectorXd fixed_turn(1);
  fixed_turn << 0.25;
  Eigen::VectorXd t;
  mocapedit::BlockDeformationTurns(rest, edited, blocks, fixed, fixed_turn, 2, 0.01, 0.0, Eigen::VectorXi(), t);
  const Eigen::VectorXd first = mocapedit::DeformationTurns(rest.middleRows(20, 20), edited.middleRows(20, 20), {},
                                                            Eigen::VectorXd(), 2, 0.01);
  const Eigen::VectorXd second = mocapedit::DeformationTurns(rest.middleRows(0, 20), edited.middleRows(0, 20),
                                                             {{5, 9}}, fixed_turn, 2, 0.01);
  EXPECT_EQ(t.segment(20, 20), first);
  EXPECT_EQ(t.segment(0, 20), second);
  // Each block's own keep_spot.
  Eigen::VectorXi keep(2);
  keep << 0, 1;
  mocapedit::BlockDeformationTurns(rest, edited, blocks, fixed, fixed_turn, 2, 0.01, 0.0, keep, t);
  EXPECT_EQ(t.segment(20, 20), mocapedit::DeformationTurns(rest.middleRows(20, 20), edited.middleRows(20, 20), {},
                                                           Eigen::VectorXd(), 2, 0.01, 0.0, false));
  EXPECT_EQ(t.segment(0, 20), second);
  Eigen::VectorXi wrong(3);
  wrong << 1, 1, 1;
  EXPECT_THROW(mocapedit::BlockDeformationTurns(rest, edited, blocks, fixed, fixed_turn, 2, 0.01, 0.0, wrong, t),
               mocapedit::InvalidInput);
  EXPECT_TRUE((t.segment(40, 20).array() == 0).all());
  EXPECT_TRUE((t.segment(5, 5).array() == 0.25).all());
}

TEST(PathTerms, KeyFramesKeepShortStretchesAndUnkeyedAgents) {
  Trajectory2 rest(10, 2);
  // Agent 0 (frames 0-6) walks, then stands from frame 3 to 5; agent 1 (frames 7-9).
  rest << 0, 0, 1, 0, 2, 0, 3, 0, 3, 0, 3.005, 0, 4, 0, 9, 9, 9, 9, 9, 9;
  Eigen::VectorXi offsets(3), keyed(2), forced(4);
  offsets << 0, 7, 10;
  keyed << 1, 0;
  forced << 6, 0, 3, 5;  // any order
  Eigen::VectorXi keys, before;
  mocapedit::KeyFrames(rest, offsets, keyed, forced, 0.01, keys, before);
  // 3 -> 5 is 0.005 apart: frame 4 between them is kept; 0 -> 3 and 5 -> 6 are not short.
  Eigen::VectorXi expected_keys(8), expected_before(10);
  expected_keys << 0, 3, 4, 5, 6, 7, 8, 9;
  expected_before << 0, 1, 1, 1, 2, 3, 4, 5, 6, 7;
  EXPECT_EQ(keys, expected_keys);
  EXPECT_EQ(before, expected_before);
  forced[0] = 10;
  EXPECT_THROW(mocapedit::KeyFrames(rest, offsets, keyed, forced, 0.01, keys, before), mocapedit::InvalidInput);
}

TEST(PathTerms, ExpandedFramesTurnSmoothlyThroughKeys) {
  // A straight walk whose keys (every 4th frame) were solved on a quarter circle, equal
  // chords apart. One similarity per interval would put every frame on a chord: no turn
  // between keys and a turn of a whole chord angle at each key. Blended, the frames away
  // from the ends turn by about a quarter of it at every frame, keys included.
  const int n = 17;
  Trajectory2 rest(n, 2);
  for (int f = 0; f < n; ++f) rest.row(f) << f, 0.0;
  Eigen::VectorXi keys(5);
  keys << 0, 4, 8, 12, 16;
  const double chord = M_PI / 8, radius = 4 / (2 * std::sin(chord / 2));
  Trajectory2 positions(5, 2);
  for (int j = 0; j < 5; ++j) positions.row(j) << radius * std::sin(j * chord), radius * (1 - std::cos(j * chord));
  Trajectory2 out;
  mocapedit::ExpandKeyFrames(rest, keys, positions, out);
  for (int j = 0; j < 5; ++j) EXPECT_EQ(out.row(keys[j]), positions.row(j)) << "key " << j;
  const auto step = [&](int f) { return std::complex<double>(out(f + 1, 0) - out(f, 0), out(f + 1, 1) - out(f, 1)); };
  for (int f = 5; f <= 11; ++f) {  // the turn between the steps into and out of frame f
    const double turn = std::arg(step(f) / step(f - 1));
    EXPECT_NEAR(turn, chord / 4, 0.25 * chord / 4) << "frame " << f;
    EXPECT_NEAR(std::abs(step(f)), 1.0, 0.03) << "frame " << f;  // speed kept within 3%
  }
}

TEST(PathTerms, ExpandedFramesFollowTheSimilarityOfTheirKeys) {
  Trajectory2 rest(6, 2);
  rest << 0, 0, 1, 0.2, 2, -0.1, 3, 0, 4, 0.3, 5, 0;
  Eigen::VectorXi keys(3);
  keys << 0, 3, 5;
  // Keys moved by one similarity (turned by 0.5 rad, scaled by 1.2, moved): so is every frame.
  const std::complex<double> s = std::polar(1.2, 0.5), t(2.0, -1.0);
  const auto move = [&](int f) { return s * std::complex<double>(rest(f, 0), rest(f, 1)) + t; };
  Trajectory2 positions(3, 2);
  for (int j = 0; j < 3; ++j) positions.row(j) << move(keys[j]).real(), move(keys[j]).imag();
  Trajectory2 out;
  mocapedit::ExpandKeyFrames(rest, keys, positions, out);
  for (int f = 0; f < 6; ++f) {
    EXPECT_NEAR(out(f, 0), move(f).real(), 1e-12) << "frame " << f;
    EXPECT_NEAR(out(f, 1), move(f).imag(), 1e-12) << "frame " << f;
  }
  keys[2] = 4;  // the last frame must be a key
  EXPECT_THROW(mocapedit::ExpandKeyFrames(rest, keys, positions, out), mocapedit::InvalidInput);
}
