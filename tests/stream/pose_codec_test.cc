// Pose stream: bit I/O and adaptive Rice round trips, quantisation bound per parameter, the
// delta frames decoding only after a keyframe, and the rate of a smooth motion.
#include "stream/pose_codec.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "models/error.h"
#include "models/numeric.h"
#include "models/so3.h"
#include "stream/bit_io.h"

namespace artex {
namespace {

TEST(BitIoTest, ExpGolombAndRiceRoundTrip) {
  std::mt19937 rng(7);
  std::vector<int32_t> values;
  std::uniform_int_distribution<int32_t> small(-40, 40), large(-2000000000, 2000000000);
  for (int i = 0; i < 2000; ++i) values.push_back(i % 17 == 0 ? large(rng) : small(rng));
  BitWriter w;
  AdaptiveRice rice;
  for (int32_t v : values) {
    w.PutExpGolomb(ZigZag(v), 3);
    rice.Encode(v, &w);
  }
  const std::vector<uint8_t> bytes = w.Finish();
  BitReader r(bytes.data(), bytes.size());
  AdaptiveRice back;
  for (int32_t v : values) {
    uint32_t u = 0;
    ASSERT_TRUE(r.GetExpGolomb(3, &u));
    EXPECT_EQ(UnZigZag(u), v);
    int32_t d = 0;
    ASSERT_TRUE(back.Decode(&r, &d));
    EXPECT_EQ(d, v);
  }
  // Truncated input fails instead of reading past the end.
  BitReader cut(bytes.data(), bytes.size() / 2);
  AdaptiveRice again;
  bool failed = false;
  for (int32_t v : values) {
    uint32_t u = 0;
    int32_t d = 0;
    if (!cut.GetExpGolomb(3, &u) || !again.Decode(&cut, &d)) {
      failed = true;
      break;
    }
    (void)v;
  }
  EXPECT_TRUE(failed);
}

Pose SmoothPose(int frame, int joints) {
  Pose p = Pose::Identity(joints);
  const double t = frame / 30.0;
  p.scale = 1.02 + 0.001 * std::sin(t);
  p.translation = Eigen::Vector3d(0.6 * t, 0.01 * std::sin(6 * t), 2.5);
  p.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.3 + 0.2 * std::sin(t), 0.0));
  for (int j = 0; j < joints; ++j)
    p.joint_rotations[j] =
        ExpSO3(Eigen::Vector3d(0.4 * std::sin(2 * t + j), 0.2 * std::cos(3 * t + j), 0.05 * j));
  return p;
}

TEST(PoseCodecTest, RoundTripWithinHalfAStep) {
  const int joints = 17;
  PoseCodecOptions o;
  PoseEncoder enc(joints, o);
  PoseDecoder dec(joints, o);
  std::size_t delta_bytes = 0;
  for (int f = 0; f < 90; ++f) {
    const Pose pose = SmoothPose(f, joints);
    const bool key = f % 30 == 0;
    Pose expected;
    const std::vector<uint8_t> bytes = enc.Encode(pose, key, &expected);
    if (!key) delta_bytes += bytes.size();
    Pose decoded;
    std::string why;
    ASSERT_TRUE(dec.Decode(bytes.data(), bytes.size(), key, &decoded, &why)) << why;
    const Eigen::VectorXd a = pose.ToVector(), b = decoded.ToVector(), e = expected.ToVector();
    for (int i = 0; i < a.size(); ++i) {
      EXPECT_LE(std::abs(a[i] - b[i]), 0.5 * PoseParameterStep(i, o) + 1e-12) << "parameter " << i;
      EXPECT_EQ(b[i], e[i]);
    }
  }
  // A smooth motion: constant-velocity residuals take a few bits per parameter.
  const double bits_per_parameter = 8.0 * delta_bytes / (87.0 * (7 + 3 * joints));
  std::printf("delta frames: %.2f bits per parameter\n", bits_per_parameter);
  EXPECT_LT(bits_per_parameter, 6.0);
}

TEST(PoseCodecTest, RotationsNearPiKeepTheirAxis) {
  // An ankle twisted by just under 180 degrees (a tracked pose seen in a test run): rounding
  // each component to the nearest step made the angle exceed pi, and the decoded rotation
  // vector pointed the other way (the same rotation, the other skinning twist branch). The
  // decoded vector must point the sender's way, within a step and a half of it.
  const int joints = 1;
  PoseCodecOptions o;
  PoseEncoder enc(joints, o);
  PoseDecoder dec(joints, o);
  Pose pose = Pose::Identity(joints);
  const Eigen::Vector3d axis = Eigen::Vector3d(-0.17356, 0.71109, -3.05513).normalized();
  int flipped_without = 0;
  for (int k = 1; k <= 200; ++k) {  // k = 0, exactly pi, is ambiguous for the sender too
    const double angle = kPi - 1e-7 * k;
    const Eigen::Vector3d r = angle * axis;
    pose.joint_rotations[0] = ExpSO3(r);
    const Eigen::Vector3d logged = pose.ToVector().segment<3>(JointParameterIndex(0));
    // What plain rounding gives: angle above pi for some k.
    Eigen::Vector3d rounded;
    for (int d = 0; d < 3; ++d) {
      rounded[d] = o.rotation_step * std::round(logged[d] / o.rotation_step);
    }
    flipped_without += rounded.norm() > kPi;
    const std::vector<uint8_t> bytes = enc.Encode(pose, true);
    Pose decoded;
    std::string why;
    ASSERT_TRUE(dec.Decode(bytes.data(), bytes.size(), true, &decoded, &why)) << why;
    const Eigen::Vector3d b = decoded.ToVector().segment<3>(JointParameterIndex(0));
    EXPECT_GT(b.dot(logged), 0.0) << "k " << k << ": the decoded axis flipped";
    EXPECT_LE((b - logged).cwiseAbs().maxCoeff(), 1.5 * o.rotation_step) << "k " << k;
  }
  EXPECT_GT(flipped_without, 0);  // the case the encoder guards against occurs here
}

TEST(PoseCodecTest, DeltaNeedsAKeyframe) {
  const int joints = 3;
  PoseEncoder enc(joints, PoseCodecOptions());
  PoseDecoder dec(joints, PoseCodecOptions());
  enc.Encode(SmoothPose(0, joints), true);
  const std::vector<uint8_t> delta = enc.Encode(SmoothPose(1, joints), false);
  Pose p;
  std::string why;
  EXPECT_FALSE(dec.Decode(delta.data(), delta.size(), false, &p, &why));
  EXPECT_NE(why.find("keyframe"), std::string::npos) << why;
  EXPECT_THROW(PoseEncoder(joints, PoseCodecOptions()).Encode(SmoothPose(0, joints), false), Error);
  // A keyframe payload cut short is an error, not a crash.
  const std::vector<uint8_t> key = enc.Encode(SmoothPose(2, joints), true);
  EXPECT_FALSE(dec.Decode(key.data(), key.size() / 2, true, &p, &why));
  PoseCodecOptions bad;
  bad.rotation_step = 0.0;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("pose_rotation_step"), std::string::npos);
}

}  // namespace
}  // namespace artex
