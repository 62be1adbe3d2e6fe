#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "mocapedit/additive_clip.h"
#include "mocapedit/layering.h"
#include "job_checks.h"

using mocapedit::AdditiveClipBuilder;
using mocapedit::ConstPoseStreamView;
using mocapedit::LayeringJob;
using mocapedit::LayerMode;
using mocapedit::PoseStreamView;
using mocapedit::Span;

namespace {

// #T * #J transforms owned by the test.
struct Poses {
  std::vector<float> t, r, s;
  Poses(std::size_t n = 0) : t(n * 3, 0.f), r(n * 4, 0.f), s(n * 3, 1.f) {
    for (std::size_t i = 0; i < n; ++i) r[i * 4 + 3] = 1.f;
  }
  PoseStreamView view() { return {Span<float>(t), Span<float>(r), Span<float>(s)}; }
  ConstPoseStreamView cview() const {
    return {Span<const float>(t), Span<const float>(r), Span<const float>(s)};
  }
  void SetRotation(std::size_t i, const Eigen::Quaternionf& q) {
    r[i * 4 + 0] = q.x();
    r[i * 4 + 1] = q.y();
    r[i * 4 + 2] = q.z();
    r[i * 4 + 3] = q.w();
  }
  Eigen::Quaternionf Rotation(std::size_t i) const {
    return Eigen::Quaternionf(r[i * 4 + 3], r[i * 4 + 0], r[i * 4 + 1], r[i * 4 + 2]);
  }
};

Eigen::Quaternionf AxisAngle(float degrees, Eigen::Vector3f axis) {
  return Eigen::Quaternionf(Eigen::AngleAxisf(degrees * float(M_PI) / 180.f, axis.normalized()));
}

// Same rotation (q or -q) to tol.
void ExpectSameRotation(const Eigen::Quaternionf& a, const Eigen::Quaternionf& b, float tol,
                        const std::string& what = "") {
  const float d = std::fabs(a.coeffs().dot(b.coeffs()));
  EXPECT_NEAR(d, 1.f, tol) << what;
  const float sign = a.coeffs().dot(b.coeffs()) < 0.f ? -1.f : 1.f;
  EXPECT_LE((a.coeffs() - sign * b.coeffs()).cwiseAbs().maxCoeff(), tol) << what;
}

Poses RandomPoses(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  Poses p(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) p.t[i * 3 + k] = 10.f * u(rng);
    for (int k = 0; k < 3; ++k) p.s[i * 3 + k] = 1.f + 0.2f * u(rng);
    Eigen::Vector4f v(u(rng), u(rng), u(rng), u(rng));
    v.normalize();
    for (int k = 0; k < 4; ++k) p.r[i * 4 + k] = v[k];
  }
  return p;
}

AdditiveClipBuilder MakeBuilder(std::size_t frames, std::size_t joints, const Poses& reference, const Poses& clip,
                                Poses& out) {
  AdditiveClipBuilder b;
  b.num_frames = frames;
  b.num_joints = joints;
  b.reference = reference.cview();
  b.clip = clip.cview();
  b.output = out.view();
  return b;
}

LayeringJob MakeJob(std::size_t poses, std::size_t joints, const Poses& src, Poses& out,
                    const std::vector<LayeringJob::Layer>& layers) {
  LayeringJob job;
  job.num_poses = poses;
  job.num_joints = joints;
  job.source = src.cview();
  job.output = out.view();
  job.layers = Span<const LayeringJob::Layer>(layers.data(), layers.size());
  return job;
}

}  // namespace

TEST(Layering, ValidityRejectsEveryBadSetup) {
  const std::size_t T = 3, J = 2;
  Poses src(T * J), out(T * J), lay(T * J);
  std::vector<float> w(T, 0.5f), jw(J, 1.f);
  LayeringJob::Layer layer{LayerMode::kAdditive, lay.cview(), Span<const float>(w), Span<const float>(jw)};
  std::vector<LayeringJob::Layer> layers{layer};
  std::string why;
  {  // A good job validates, and so does one with nothing to do.
    EXPECT_EQ(Rejection(MakeJob(T, J, src, out, layers)), "");
    Poses none;
    EXPECT_EQ(Rejection(MakeJob(0, J, none, none, {})), "");
  }
  {  // Source of the wrong size.
    Poses small(T * J - 1);
    EXPECT_NE(why = Rejection(MakeJob(T, J, small, out, layers)), "");
    EXPECT_NE(why.find("source"), std::string::npos);
  }
  {  // Rotations alone of the wrong size.
    Poses bad(T * J);
    bad.r.pop_back();
    EXPECT_NE(why = Rejection(MakeJob(T, J, bad, out, layers)), "");
  }
  {  // Output of the wrong size.
    Poses small(T * J + 1);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, small, layers)), "");
    EXPECT_NE(why.find("output"), std::string::npos);
  }
  {  // Output partially overlapping the source; the very same buffers are fine.
    Poses big(T * J + 1);
    LayeringJob job = MakeJob(T, J, src, out, layers);
    job.source = ConstPoseStreamView(Span<const float>(big.t.data(), T * J * 3),
                                     Span<const float>(big.r.data(), T * J * 4),
                                     Span<const float>(big.s.data(), T * J * 3));
    job.output = PoseStreamView{Span<float>(big.t.data() + 3, T * J * 3), Span<float>(big.r.data() + 4, T * J * 4),
                                Span<float>(big.s.data() + 3, T * J * 3)};
    EXPECT_NE(why = Rejection(job), "");
    EXPECT_NE(why.find("overlap"), std::string::npos);
    job.output = PoseStreamView{Span<float>(big.t.data(), T * J * 3), Span<float>(big.r.data(), T * J * 4),
                                Span<float>(big.s.data(), T * J * 3)};
    EXPECT_EQ(Rejection(job), "");
  }
  {  // A mode that is neither blend nor additive.
    auto bad = layers;
    bad[0].mode = static_cast<LayerMode>(7);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "");
    EXPECT_NE(why.find("mode"), std::string::npos);
  }
  {  // Layer transforms of the wrong size.
    Poses small(T * J - 2);
    auto bad = layers;
    bad[0].transforms = small.cview();
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "");
    EXPECT_NE(why.find("layer 0: transforms"), std::string::npos);
  }
  {  // Weights: one per pose.
    std::vector<float> short_w(T - 1, 0.5f);
    auto bad = layers;
    bad[0].weights = Span<const float>(short_w);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "");
    EXPECT_NE(why.find("weights"), std::string::npos);
  }
  for (float value : {-0.01f, 1.01f, std::nanf("")}) {  // Weights in [0, 1].
    std::vector<float> bad_w(T, 0.5f);
    bad_w[1] = value;
    auto bad = layers;
    bad[0].weights = Span<const float>(bad_w);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "") << value;
    EXPECT_NE(why.find("pose 1"), std::string::npos) << why;
  }
  {  // Joint weights: empty or one per joint.
    std::vector<float> long_jw(J + 1, 1.f);
    auto bad = layers;
    bad[0].joint_weights = Span<const float>(long_jw);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "");
    EXPECT_NE(why.find("joint_weights"), std::string::npos);
    bad[0].joint_weights = Span<const float>();
    EXPECT_EQ(Rejection(MakeJob(T, J, src, out, bad)), "");
  }
  {  // Joint weights in [0, 1].
    std::vector<float> bad_jw{1.f, 2.f};
    auto bad = layers;
    bad[0].joint_weights = Span<const float>(bad_jw);
    EXPECT_NE(why = Rejection(MakeJob(T, J, src, out, bad)), "");
    EXPECT_NE(why.find("joint 1"), std::string::npos);
  }
  {  // Run() validates first and leaves the output untouched on failure.
    Poses small(T * J - 1);
    out.t[0] = 42.f;
    EXPECT_THROW(MakeJob(T, J, small, out, layers).Run(), mocapedit::InvalidInput);
    EXPECT_EQ(out.t[0], 42.f);
  }
}

TEST(Layering, ValidityOfTheAdditiveBuilder) {
  const std::size_t F = 2, J = 2;
  Poses ref(J), clip(F * J), out(F * J);
  const AdditiveClipBuilder b = MakeBuilder(F, J, ref, clip, out);
  std::string why;
  EXPECT_EQ(Rejection(b), "");
  {
    Poses small(J - 1);
    AdditiveClipBuilder bad = b;
    bad.reference = small.cview();
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("reference"), std::string::npos);
  }
  {
    Poses small(F * J - 1);
    AdditiveClipBuilder bad = b;
    bad.clip = small.cview();
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("clip"), std::string::npos);
    bad = b;
    bad.output = small.view();
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("output"), std::string::npos);
  }
  {
    Poses big(F * J + 1);
    AdditiveClipBuilder bad = b;
    bad.clip = ConstPoseStreamView(Span<const float>(big.t.data(), F * J * 3), Span<const float>(big.r.data(), F * J * 4),
                                   Span<const float>(big.s.data(), F * J * 3));
    bad.output = PoseStreamView{Span<float>(big.t.data() + 3, F * J * 3), Span<float>(big.r.data() + 4, F * J * 4),
                                Span<float>(big.s.data() + 3, F * J * 3)};
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("overlap"), std::string::npos);
  }
  {
    Poses zero_rot = ref;
    zero_rot.r[7] = 0.f;  // joint 1: (0, 0, 0, 0)
    AdditiveClipBuilder bad = b;
    bad.reference = zero_rot.cview();
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("rotation of joint 1"), std::string::npos);
  }
  {
    Poses zero_scale = ref;
    zero_scale.s[4] = 0.f;
    AdditiveClipBuilder bad = b;
    bad.reference = zero_scale.cview();
    EXPECT_NE(why = Rejection(bad), "");
    EXPECT_NE(why.find("scale of joint 1"), std::string::npos);
  }
}

TEST(Layering, SubtreeMaskFollowsParents) {
  // 0 Root, 1 Hips, 2 Spine, 3 Head, 4 LeftArm (under Spine), 5 LeftLeg (under Hips)
  const std::vector<int> parents{-1, 0, 1, 2, 2, 1};
  EXPECT_EQ(mocapedit::SubtreeJointWeights(Span<const int>(parents), 2),
            (std::vector<float>{0, 0, 1, 1, 1, 0}));
  EXPECT_EQ(mocapedit::SubtreeJointWeights(Span<const int>(parents), 5),
            (std::vector<float>{0, 0, 0, 0, 0, 1}));
  EXPECT_EQ(mocapedit::SubtreeJointWeights(Span<const int>(parents), -1),
            (std::vector<float>{1, 1, 1, 1, 1, 1}));
  EXPECT_THROW(mocapedit::SubtreeJointWeights(Span<const int>(parents), 6), mocapedit::InvalidInput);
  const std::vector<int> misordered{-1, 2, 0};
  EXPECT_THROW(mocapedit::SubtreeJointWeights(Span<const int>(misordered), 0), mocapedit::InvalidInput);
}

TEST(Layering, SlerpMatchesExactSlerpOnTheShortArc) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  float worst = 0.f;
  for (int i = 0; i < 20000; ++i) {
    Eigen::Quaternionf a = Eigen::Quaternionf::UnitRandom(), b = Eigen::Quaternionf::UnitRandom();
    if (i % 4 == 0) b = Eigen::Quaternionf(b.coeffs() * 1e-3f + a.coeffs()).normalized();  // near
    const float t = 0.5f + 0.5f * u(rng);
    float out[4];
    mocapedit::Slerp(a.coeffs().data(), b.coeffs().data(), t, out);  // Eigen stores (x, y, z, w)
    // Exact shortest-arc slerp in double.
    Eigen::Quaterniond ad = a.cast<double>(), bd = b.cast<double>();
    if (ad.coeffs().dot(bd.coeffs()) < 0) bd.coeffs() *= -1.0;
    const double theta = std::acos(std::min(1.0, ad.coeffs().dot(bd.coeffs())));
    Eigen::Vector4d e = theta < 1e-9 ? Eigen::Vector4d((1 - t) * ad.coeffs() + t * bd.coeffs())
                                     : Eigen::Vector4d((std::sin((1 - t) * theta) * ad.coeffs() +
                                                        std::sin(t * theta) * bd.coeffs()) / std::sin(theta));
    e.normalize();
    for (int k = 0; k < 4; ++k) worst = std::max(worst, float(std::fabs(out[k] - e[k])));
  }
  EXPECT_LT(worst, 5e-7f);
  // The ends: a at 0, b at 1 (b's sign may flip onto a's hemisphere).
  const Eigen::Quaternionf a = AxisAngle(30, {1, 2, 3}), b = AxisAngle(-170, {0, 1, 0});
  float out[4];
  mocapedit::Slerp(a.coeffs().data(), b.coeffs().data(), 0.f, out);
  ExpectSameRotation(Eigen::Quaternionf(out[3], out[0], out[1], out[2]), a, 2.5e-7f);
  mocapedit::Slerp(a.coeffs().data(), b.coeffs().data(), 1.f, out);
  ExpectSameRotation(Eigen::Quaternionf(out[3], out[0], out[1], out[2]), b, 2.5e-7f);
  // Shortest arc: 170 and -170 degrees about y are 20 degrees apart; half way is 180.
  const Eigen::Quaternionf p = AxisAngle(170, {0, 1, 0}), q = AxisAngle(-170, {0, 1, 0});
  mocapedit::Slerp(p.coeffs().data(), q.coeffs().data(), 0.5f, out);
  ExpectSameRotation(Eigen::Quaternionf(out[3], out[0], out[1], out[2]), AxisAngle(180, {0, 1, 0}), 1e-6f);
}

TEST(Layering, WeightZeroLeavesTheSourceBitForBit) {
  const std::size_t T = 4, J = 5;
  const Poses src = RandomPoses(T * J, 1), lay = RandomPoses(T * J, 2);
  std::vector<float> w(T, 0.f), jw{1, 1, 0.5f, 1, 1};
  Poses out(T * J);
  for (LayerMode mode : {LayerMode::kBlend, LayerMode::kAdditive}) {
    std::vector<LayeringJob::Layer> layers{{mode, lay.cview(), Span<const float>(w), Span<const float>(jw)}};
    ASSERT_NO_THROW(MakeJob(T, J, src, out, layers).Run());
    EXPECT_EQ(std::memcmp(out.t.data(), src.t.data(), out.t.size() * 4), 0);
    EXPECT_EQ(std::memcmp(out.r.data(), src.r.data(), out.r.size() * 4), 0);
    EXPECT_EQ(std::memcmp(out.s.data(), src.s.data(), out.s.size() * 4), 0);
  }
}

TEST(Layering, BlendAtWeightOneCopiesTheLayerOnTheMaskOnly) {
  const std::size_t T = 3, J = 4;
  const Poses src = RandomPoses(T * J, 3), lay = RandomPoses(T * J, 4);
  std::vector<float> w(T, 1.f), jw{0, 1, 1, 0};
  Poses out(T * J);
  std::vector<LayeringJob::Layer> layers{{LayerMode::kBlend, lay.cview(), Span<const float>(w), Span<const float>(jw)}};
  ASSERT_NO_THROW(MakeJob(T, J, src, out, layers).Run());
  for (std::size_t i = 0; i < T * J; ++i) {
    const Poses& expect = jw[i % J] == 1.f ? lay : src;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(out.t[i * 3 + k], expect.t[i * 3 + k]);
    for (int k = 0; k < 4; ++k) EXPECT_EQ(out.r[i * 4 + k], expect.r[i * 4 + k]);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(out.s[i * 3 + k], expect.s[i * 3 + k]);
  }
}

TEST(Layering, BlendInterpolatesTranslationsLinearlyAndRotationsOnTheShortArc) {
  Poses src(1), lay(1), out(1);
  src.t = {0, 0, 0};
  lay.t = {2, -4, 6};
  src.s = {1, 1, 1};
  lay.s = {3, 1, 2};
  src.SetRotation(0, AxisAngle(170, {0, 0, 1}));
  lay.SetRotation(0, AxisAngle(-150, {0, 0, 1}));  // 40 degrees away, across 180
  std::vector<float> w{0.25f};
  std::vector<LayeringJob::Layer> layers{{LayerMode::kBlend, lay.cview(), Span<const float>(w), {}}};
  ASSERT_NO_THROW(MakeJob(1, 1, src, out, layers).Run());
  EXPECT_FLOAT_EQ(out.t[0], 0.5f);
  EXPECT_FLOAT_EQ(out.t[1], -1.f);
  EXPECT_FLOAT_EQ(out.s[0], 1.5f);
  EXPECT_FLOAT_EQ(out.s[2], 1.25f);
  ExpectSameRotation(out.Rotation(0), AxisAngle(180, {0, 0, 1}), 1e-6f);
}

TEST(Layering, AdditiveComposesAKnownDeltaOnTheLeftInJointLocalSpace) {
  // The layer clip is its reference pose turned by D: the delta is D, and on any source S the
  // result is D * S (rotate by S, then by D in the parent's space), not S * D.
  const Eigen::Quaternionf ref = AxisAngle(35, {1, 0.3f, -0.2f});
  const Eigen::Quaternionf D = AxisAngle(90, {0, 0, 1});
  const Eigen::Quaternionf S = AxisAngle(90, {1, 0, 0});
  Poses reference(1), clip(1), delta(1), src(1), out(1);
  reference.SetRotation(0, ref);
  reference.t = {1, 2, 3};
  reference.s = {2, 2, 2};
  clip.SetRotation(0, D * ref);
  clip.t = {1.5f, 2, 2};
  clip.s = {3, 2, 1};
  ASSERT_NO_THROW(MakeBuilder(1, 1, reference, clip, delta).Run());
  ExpectSameRotation(delta.Rotation(0), D, 1e-6f, "delta");
  EXPECT_FLOAT_EQ(delta.t[0], 0.5f);
  EXPECT_FLOAT_EQ(delta.t[2], -1.f);
  EXPECT_FLOAT_EQ(delta.s[0], 1.5f);
  EXPECT_FLOAT_EQ(delta.s[2], 0.5f);

  src.SetRotation(0, S);
  src.t = {10, 20, 30};
  src.s = {1, 2, 4};
  for (float weight : {1.f, 0.5f, 0.25f}) {
    std::vector<float> w{weight};
    std::vector<LayeringJob::Layer> layers{{LayerMode::kAdditive, delta.cview(), Span<const float>(w), {}}};
    ASSERT_NO_THROW(MakeJob(1, 1, src, out, layers).Run());
    const Eigen::Quaternionf expect = AxisAngle(90 * weight, {0, 0, 1}) * S;
    ExpectSameRotation(out.Rotation(0), expect, 1e-6f, "weight " + std::to_string(weight));
    EXPECT_NEAR(out.t[0], 10 + 0.5f * weight, 1e-5f);
    EXPECT_NEAR(out.t[2], 30 - weight, 1e-5f);
    EXPECT_NEAR(out.s[0], 1 * (1 + weight * 0.5f), 1e-6f);
    EXPECT_NEAR(out.s[2], 4 * (1 - weight * 0.5f), 1e-6f);
  }
  // The operand order, seen on a vector: S takes y to z; D leaves z alone. D * S takes y to z,
  // S * D would take y to -x.
  const Eigen::Vector3f y = out.Rotation(0).normalized() * Eigen::Vector3f::UnitY();  // weight 0.25
  const Eigen::Vector3f expect_y = (AxisAngle(22.5f, {0, 0, 1}) * S) * Eigen::Vector3f::UnitY();
  EXPECT_LT((y - expect_y).norm(), 1e-6f);
  std::vector<float> one{1.f};
  std::vector<LayeringJob::Layer> layers{{LayerMode::kAdditive, delta.cview(), Span<const float>(one), {}}};
  ASSERT_NO_THROW(MakeJob(1, 1, src, out, layers).Run());
  EXPECT_LT((out.Rotation(0) * Eigen::Vector3f::UnitY() - Eigen::Vector3f::UnitZ()).norm(), 1e-6f);
}

TEST(Layering, AdditiveOnItsReferenceGivesTheClipAndAReferenceFrameChangesNothing) {
  const std::size_t F = 6, J = 3;
  Poses clip = RandomPoses(F * J, 5), delta(F * J), out(F * J);
  // Frame 0 is the reference (firstFrame).
  Poses reference(J);
  std::copy(clip.t.begin(), clip.t.begin() + J * 3, reference.t.begin());
  std::copy(clip.r.begin(), clip.r.begin() + J * 4, reference.r.begin());
  std::copy(clip.s.begin(), clip.s.begin() + J * 3, reference.s.begin());
  ASSERT_NO_THROW(MakeBuilder(F, J, reference, clip, delta).Run());
  for (std::size_t j = 0; j < J; ++j) {  // frame 0's delta is exactly identity
    for (int k = 0; k < 3; ++k) EXPECT_EQ(delta.t[j * 3 + k], 0.f);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(delta.s[j * 3 + k], 1.f);
    EXPECT_EQ(delta.r[j * 4 + 3], 1.f);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(delta.r[j * 4 + k], 0.f);
  }
  // Source = the reference pose in every frame: at weight 1 the result is the clip.
  Poses src(F * J);
  for (std::size_t f = 0; f < F; ++f) {
    std::copy(reference.t.begin(), reference.t.end(), src.t.begin() + f * J * 3);
    std::copy(reference.r.begin(), reference.r.end(), src.r.begin() + f * J * 4);
    std::copy(reference.s.begin(), reference.s.end(), src.s.begin() + f * J * 3);
  }
  std::vector<float> w(F, 1.f);
  std::vector<LayeringJob::Layer> layers{{LayerMode::kAdditive, delta.cview(), Span<const float>(w), {}}};
  ASSERT_NO_THROW(MakeJob(F, J, src, out, layers).Run());
  for (std::size_t i = 0; i < F * J; ++i) {
    ExpectSameRotation(out.Rotation(i), clip.Rotation(i), 1e-6f);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(out.t[i * 3 + k], clip.t[i * 3 + k], 1e-5f);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(out.s[i * 3 + k], clip.s[i * 3 + k], 1e-6f);
  }
  // A delta of exactly identity leaves any source bit for bit, whatever the weight.
  const std::size_t P = 4001;
  const Poses other = RandomPoses(P * J, 6);
  Poses identity(P * J), out1(P * J);
  std::vector<float> weights(P);
  for (std::size_t p = 0; p < P; ++p) weights[p] = float(p) / float(P - 1);
  std::vector<LayeringJob::Layer> first{{LayerMode::kAdditive, identity.cview(), Span<const float>(weights), {}}};
  ASSERT_NO_THROW(MakeJob(P, J, other, out1, first).Run());
  EXPECT_EQ(out1.t, other.t);
  EXPECT_EQ(out1.r, other.r);
  EXPECT_EQ(out1.s, other.s);
}

TEST(Layering, LayersStackInOrder) {
  // Blend to L at weight 1, then add D: D * L. Add D, then blend to L: L (the blend hides it).
  const Eigen::Quaternionf S = AxisAngle(20, {1, 0, 0}), L = AxisAngle(50, {0, 1, 0}),
                           D = AxisAngle(30, {0, 0, 1});
  Poses src(1), lay(1), delta(1), out(1);
  src.SetRotation(0, S);
  lay.SetRotation(0, L);
  delta.SetRotation(0, D);
  std::vector<float> one{1.f};
  const LayeringJob::Layer blend{LayerMode::kBlend, lay.cview(), Span<const float>(one), {}};
  const LayeringJob::Layer add{LayerMode::kAdditive, delta.cview(), Span<const float>(one), {}};
  std::vector<LayeringJob::Layer> blend_then_add{blend, add}, add_then_blend{add, blend};
  ASSERT_NO_THROW(MakeJob(1, 1, src, out, blend_then_add).Run());
  ExpectSameRotation(out.Rotation(0), D * L, 1e-6f);
  ASSERT_NO_THROW(MakeJob(1, 1, src, out, add_then_blend).Run());
  EXPECT_EQ(out.r, lay.r);
  // Two additive layers: D2 * (D1 * S).
  const Eigen::Quaternionf D2 = AxisAngle(-45, {1, 1, 0});
  Poses delta2(1);
  delta2.SetRotation(0, D2);
  const LayeringJob::Layer add2{LayerMode::kAdditive, delta2.cview(), Span<const float>(one), {}};
  std::vector<LayeringJob::Layer> two{add, add2};
  ASSERT_NO_THROW(MakeJob(1, 1, src, out, two).Run());
  ExpectSameRotation(out.Rotation(0), D2 * (D * S), 1e-6f);
}

TEST(Layering, AFractionalJointWeightActsAsThatWeight) {
  const std::size_t T = 2, J = 3;
  const Poses src = RandomPoses(T * J, 8), lay = RandomPoses(T * J, 9);
  for (LayerMode mode : {LayerMode::kBlend, LayerMode::kAdditive}) {
    std::vector<float> w{0.8f, 0.5f}, jw{1.f, 0.5f, 0.f};
    Poses masked(T * J), plain(T * J);
    std::vector<LayeringJob::Layer> a{{mode, lay.cview(), Span<const float>(w), Span<const float>(jw)}};
    ASSERT_NO_THROW(MakeJob(T, J, src, masked, a).Run());
    std::vector<float> w2{0.4f, 0.25f};
    std::vector<LayeringJob::Layer> b{{mode, lay.cview(), Span<const float>(w2), {}}};
    ASSERT_NO_THROW(MakeJob(T, J, src, plain, b).Run());
    for (std::size_t t = 0; t < T; ++t) {
      const std::size_t i = t * J + 1;
      ExpectSameRotation(masked.Rotation(i), plain.Rotation(i), 1e-6f);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(masked.t[i * 3 + k], plain.t[i * 3 + k], 1e-5f);
      EXPECT_EQ(masked.r[(t * J + 2) * 4], src.r[(t * J + 2) * 4]);  // joint weight 0
    }
  }
}

TEST(Layering, RunsInPlace) {
  const std::size_t T = 3, J = 4;
  const Poses src = RandomPoses(T * J, 10), lay = RandomPoses(T * J, 11);
  std::vector<float> w{0.2f, 0.6f, 1.f};
  for (LayerMode mode : {LayerMode::kBlend, LayerMode::kAdditive}) {
    std::vector<LayeringJob::Layer> layers{{mode, lay.cview(), Span<const float>(w), {}}};
    Poses out(T * J), inplace = src;
    ASSERT_NO_THROW(MakeJob(T, J, src, out, layers).Run());
    LayeringJob job = MakeJob(T, J, inplace, inplace, layers);
    job.source = ConstPoseStreamView(inplace.view());
    ASSERT_NO_THROW(job.Run());
    EXPECT_EQ(inplace.t, out.t);
    EXPECT_EQ(inplace.r, out.r);
    EXPECT_EQ(inplace.s, out.s);
  }
}
