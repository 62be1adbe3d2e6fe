#include <gtest/gtest.h>

#include <cmath>

#include "mocapedit/clip_sampling.h"

using mocapedit::Quatf4Rows;
using mocapedit::Vec3fRows;

namespace {

// Two joints, three frames: joint 0 walks along x and turns about z by 90 degrees per frame;
// joint 1 holds a rotation whose sign flips between frames (the same rotation).
struct Clip {
  Vec3fRows t = Vec3fRows(6, 3);
  Quatf4Rows r = Quatf4Rows(6, 4);
  Vec3fRows s = Vec3fRows::Ones(6, 3);
  Clip() {
    const float h = static_cast<float>(std::sqrt(0.5));
    for (int f = 0; f < 3; ++f) {
      t.row(2 * f) << 10.0f * f, 0.0f, 1.0f;
      t.row(2 * f + 1) << 0.0f, 5.0f, static_cast<float>(f);
      const double a = f * M_PI / 4.0;  // half of 90 degrees per frame
      r.row(2 * f) << 0.0f, 0.0f, static_cast<float>(std::sin(a)), static_cast<float>(std::cos(a));
      const float sign = f % 2 ? -1.0f : 1.0f;
      r.row(2 * f + 1) << sign * h, 0.0f, 0.0f, sign * h;
      s.row(2 * f + 1) << 1.0f + f, 1.0f, 1.0f;
    }
  }
};

struct Sampled {
  Vec3fRows t, s;
  Quatf4Rows r;
};

Sampled Sample(const Clip& c, const Eigen::VectorXd& frames) {
  Sampled out{Vec3fRows(frames.size() * 2, 3), Vec3fRows(frames.size() * 2, 3), Quatf4Rows(frames.size() * 2, 4)};
  mocapedit::SampleClip(c.t, c.r, c.s, 2, frames, out.t, out.r, out.s);
  return out;
}

}  // namespace

TEST(ClipSampling, ValidityRejectsBadInput) {
  const Clip c;
  Vec3fRows ot(2, 3), os(2, 3);
  Quatf4Rows orr(2, 4);
  const Eigen::VectorXd one = Eigen::VectorXd::Zero(1);
  {
    EXPECT_THROW(mocapedit::SampleClip(c.t, c.r, c.s, 0, one, ot, orr, os), mocapedit::InvalidInput);
  }
  {
    EXPECT_THROW(mocapedit::SampleClip(c.t, c.r, c.s, 4, one, ot, orr, os), mocapedit::InvalidInput);
  }
  {
    const Quatf4Rows fewer = c.r.topRows(4);
    EXPECT_THROW(mocapedit::SampleClip(c.t, fewer, c.s, 2, one, ot, orr, os), mocapedit::InvalidInput);
  }
  {
    Vec3fRows small(1, 3);
    EXPECT_THROW(mocapedit::SampleClip(c.t, c.r, c.s, 2, one, small, orr, os), mocapedit::InvalidInput);
  }
  {
    Eigen::VectorXd bad(1);
    bad << std::nan("");
    EXPECT_THROW(mocapedit::SampleClip(c.t, c.r, c.s, 2, bad, ot, orr, os), mocapedit::InvalidInput);
  }
  {
    Eigen::VectorXd map(3);
    map << 0, 1, 1;
    EXPECT_THROW(mocapedit::FramesAtTimes(map, one), mocapedit::InvalidInput);
    EXPECT_THROW(mocapedit::FramesAtTimes(Eigen::VectorXd(0), one), mocapedit::InvalidInput);
  }
}

TEST(ClipSampling, WholeFramesAreCopiedAndOutsideFramesClamp) {
  const Clip c;
  Eigen::VectorXd frames(4);
  frames << 1.0, -3.0, 2.0, 7.5;
  const Sampled s = Sample(c, frames);
  EXPECT_TRUE((s.t.middleRows(0, 2).array() == c.t.middleRows(2, 2).array()).all());
  EXPECT_TRUE((s.r.middleRows(0, 2).array() == c.r.middleRows(2, 2).array()).all());
  EXPECT_TRUE((s.s.middleRows(0, 2).array() == c.s.middleRows(2, 2).array()).all());
  EXPECT_TRUE((s.t.middleRows(2, 2).array() == c.t.middleRows(0, 2).array()).all());
  EXPECT_TRUE((s.r.middleRows(6, 2).array() == c.r.middleRows(4, 2).array()).all());
}

TEST(ClipSampling, TranslationsAndScalesAreLinearRotationsSlerpOnTheShortArc) {
  const Clip c;
  Eigen::VectorXd frames(2);
  frames << 0.25, 1.5;
  const Sampled s = Sample(c, frames);
  EXPECT_NEAR(s.t(0, 0), 2.5f, 1e-6);
  EXPECT_NEAR(s.t(1, 2), 0.25f, 1e-6);
  EXPECT_NEAR(s.s(1, 0), 1.25f, 1e-6);
  // Joint 0 turns 90 degrees per frame about z: a quarter frame is 22.5 degrees.
  EXPECT_NEAR(s.r(0, 2), std::sin(M_PI / 16), 1e-6);
  EXPECT_NEAR(s.r(0, 3), std::cos(M_PI / 16), 1e-6);
  EXPECT_NEAR(s.r(2, 2), std::sin(3 * M_PI / 8), 1e-6);
  // Joint 1 is one rotation stored as q and -q: the short arc stays on it.
  const double h = std::sqrt(0.5);
  EXPECT_NEAR(std::abs(s.r(1, 0)), h, 1e-6);
  EXPECT_NEAR(std::abs(s.r(3, 3)), h, 1e-6);
  EXPECT_NEAR(s.r(3, 0) * s.r(3, 3), 0.5, 1e-6);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(s.r.row(i).cast<double>().norm(), 1.0, 1e-6);
}

TEST(ClipSampling, FramesAtTimesInvertsATimeMap) {
  Eigen::VectorXd map(4);
  map << 10.0, 12.0, 12.5, 20.0;
  Eigen::VectorXd times(6);
  times << 5.0, 10.0, 11.0, 12.5, 16.25, 30.0;
  const Eigen::VectorXd f = mocapedit::FramesAtTimes(map, times);
  EXPECT_EQ(f[0], 0.0);
  EXPECT_EQ(f[1], 0.0);
  EXPECT_DOUBLE_EQ(f[2], 0.5);
  EXPECT_EQ(f[3], 2.0);  // a time of the map gives its frame exactly
  EXPECT_DOUBLE_EQ(f[4], 2.5);
  EXPECT_EQ(f[5], 3.0);
}
