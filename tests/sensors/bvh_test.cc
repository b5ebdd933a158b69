#include "sensors/bvh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "models/error.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "tests/sensors/test_skeleton.h"

namespace artex {
namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr double kUnitsPerMetre = 100.0;  // the synthetic BVH files are in centimetres

const Template& Model() {
  static const Template t = testing_skeleton::MakeBoxTemplate();
  return t;
}

int J(const std::string& name) { return Model().FindJoint(name); }

Eigen::Matrix3d RotX(double deg) { return ExpSO3(Eigen::Vector3d::UnitX() * deg * kDeg); }
Eigen::Matrix3d RotY(double deg) { return ExpSO3(Eigen::Vector3d::UnitY() * deg * kDeg); }
Eigen::Matrix3d RotZ(double deg) { return ExpSO3(Eigen::Vector3d::UnitZ() * deg * kDeg); }

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Euler angles (degrees) per joint for one frame, in channel order Z X Y; root position (cm).
struct SyntheticFrame {
  Eigen::Vector3d root_position = Eigen::Vector3d::Zero();
  std::map<std::string, Eigen::Vector3d> zxy_deg;
};

// A BVH (cm) whose hierarchy is the template's joint tree in its rest pose, optionally with
// the arms raised to a T-pose; End Sites at the hand/head tips and under the ankles (y = 0).
std::string TemplateBvh(const std::vector<SyntheticFrame>& frames, double frame_time,
                        bool t_pose = false) {
  const Template& t = Model();
  std::vector<Eigen::Vector3d> rest(t.num_joints());
  for (int j = 0; j < t.num_joints(); ++j) rest[j] = t.joints[j].center;
  if (t_pose) {
    for (const char* side : {"l_", "r_"}) {
      const int s = t.FindJoint(std::string(side) + "shoulder");
      const double sign = side[0] == 'l' ? 1.0 : -1.0;
      for (int k = 1; k <= 2; ++k) {
        const double len = (t.joints[s + k].center - t.joints[s + k - 1].center).norm();
        rest[s + k] = rest[s + k - 1] + Eigen::Vector3d(sign * len, 0, 0);
      }
    }
  }
  std::ostringstream out;
  out.precision(17);
  out << "HIERARCHY\n";
  std::function<void(int, int)> write = [&](int j, int depth) {
    const std::string pad(depth * 2, ' ');
    const int p = t.joints[j].parent;
    const Eigen::Vector3d offset = kUnitsPerMetre * (p < 0 ? rest[j] : rest[j] - rest[p]);
    out << pad << (p < 0 ? "ROOT " : "JOINT ") << t.joints[j].name << "\n" << pad << "{\n";
    out << pad << "  OFFSET " << offset.x() << " " << offset.y() << " " << offset.z() << "\n";
    out << pad << "  CHANNELS " << (p < 0 ? "6 Xposition Yposition Zposition " : "3 ")
        << "Zrotation Xrotation Yrotation\n";
    bool leaf = true;
    for (int c = 0; c < t.num_joints(); ++c) {
      if (t.joints[c].parent == j) {
        write(c, depth + 1);
        leaf = false;
      }
    }
    if (leaf) {
      Eigen::Vector3d end = 0.1 * t.joints[j].twist_axis;
      if (t.joints[j].name.find("ankle") != std::string::npos) end.y() = -rest[j].y();
      if (t_pose && t.joints[j].name.find("wrist") != std::string::npos) {
        end = Eigen::Vector3d(t.joints[j].name[0] == 'l' ? 0.1 : -0.1, 0, 0);
      }
      end *= kUnitsPerMetre;
      out << pad << "  End Site\n"
          << pad << "  {\n"
          << pad << "    OFFSET " << end.x() << " " << end.y() << " " << end.z() << "\n"
          << pad << "  }\n";
    }
    out << pad << "}\n";
  };
  write(0, 0);
  out << "MOTION\nFrames: " << frames.size() << "\nFrame Time: " << frame_time << "\n";
  for (const SyntheticFrame& f : frames) {
    for (int j = 0; j < t.num_joints(); ++j) {
      if (j == 0) {
        const Eigen::Vector3d p = f.root_position + kUnitsPerMetre * rest[0];
        out << p.x() << " " << p.y() << " " << p.z() << " ";
      }
      const auto it = f.zxy_deg.find(t.joints[j].name);
      const Eigen::Vector3d a = it == f.zxy_deg.end() ? Eigen::Vector3d::Zero() : it->second;
      out << a.x() << " " << a.y() << " " << a.z() << (j + 1 < t.num_joints() ? " " : "\n");
    }
  }
  return out.str();
}

BvhClip Parse(const std::string& text, const std::string& source = "test.bvh") {
  std::istringstream in(text);
  return ParseBvh(in, source);
}

const char* kSmallBvh = R"(HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {
    OFFSET 1 2 3
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -4 0
    }
  }
}
MOTION
Frames: 3
Frame Time: .0083333
1 2 3 10 20 30 40 50 60
4 5 6 0 0 0 0 0 90
7 8 9 -1e1 0 0 0 0 0
)";

std::string ReplaceLine(const std::string& text, int line, const std::string& replacement) {
  std::istringstream in(text);
  std::ostringstream out;
  std::string l;
  for (int i = 1; std::getline(in, l); ++i) out << (i == line ? replacement : l) << "\n";
  return out.str();
}

// Expects ParseBvh to throw an Error whose message starts with "test.bvh:<line>:" and
// contains `fragment`.
void ExpectParseError(const std::string& text, int line, const std::string& fragment) {
  try {
    Parse(text);
    FAIL() << "expected artex::Error containing '" << fragment << "'";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind("test.bvh:" + std::to_string(line) + ":", 0), 0u) << msg;
    EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
  }
}

TEST(BvhParseTest, ReadsHierarchyChannelsAndFrames) {
  const BvhClip clip = Parse(kSmallBvh);
  ASSERT_EQ(clip.joints.size(), 3u);
  EXPECT_EQ(clip.joints[0].name, "Hips");
  EXPECT_EQ(clip.joints[1].name, "Arm");
  EXPECT_EQ(clip.joints[2].name, "Arm/End Site");
  EXPECT_TRUE(clip.joints[2].end_site);
  EXPECT_EQ(clip.joints[2].parent, 1);
  EXPECT_EQ(clip.joints[1].offset, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(clip.num_channels, 9);
  EXPECT_EQ(clip.joints[1].first_channel, 6);
  ASSERT_EQ(clip.num_frames(), 3);
  EXPECT_DOUBLE_EQ(clip.frame_time, 0.0083333);
  EXPECT_DOUBLE_EQ(clip.duration(), 2 * 0.0083333);
  EXPECT_DOUBLE_EQ(clip.values(2, 3), -10.0);
  EXPECT_EQ(clip.FindJoint("Arm"), 1);
  EXPECT_EQ(clip.FindJoint("arm"), -1);
  EXPECT_EQ(clip.Children(1), std::vector<int>({2}));
}

TEST(BvhParseTest, ChannelOrderDefinesTheRotationProduct) {
  const BvhClip clip = Parse(kSmallBvh);
  const BvhFrame f = BvhFrameAt(clip, 0);
  // Root: "Zrotation Yrotation Xrotation" 10 20 30 -> Rz(10) Ry(20) Rx(30).
  EXPECT_LT((f.rotations[0].toRotationMatrix() - RotZ(10) * RotY(20) * RotX(30)).norm(), 1e-12);
  // Arm: "Xrotation Yrotation Zrotation" 40 50 60 -> Rx(40) Ry(50) Rz(60).
  EXPECT_LT((f.rotations[1].toRotationMatrix() - RotX(40) * RotY(50) * RotZ(60)).norm(), 1e-12);
  // Root position channels replace the root OFFSET; joints keep their OFFSET.
  EXPECT_EQ(f.translations[0], Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(f.translations[1], Eigen::Vector3d(1, 2, 3));
  // Forward kinematics: the End Site hangs 4 units below the Arm, rotated by the chain.
  std::vector<Eigen::Matrix3d> rot;
  Eigen::MatrixX3d pos;
  BvhForwardKinematics(clip, BvhFrameAt(clip, 1), &rot, &pos);
  EXPECT_LT((pos.row(1) - Eigen::RowVector3d(5, 7, 9)).norm(), 1e-12);
  // Arm rotated 90 degrees about Z: (0, -4, 0) -> (4, 0, 0).
  EXPECT_LT((pos.row(2) - Eigen::RowVector3d(9, 7, 9)).norm(), 1e-12);
}

TEST(BvhParseTest, MalformedInputNamesFileAndLine) {
  const std::string good = kSmallBvh;
  // Truncated inside the hierarchy (after line 9, the CHANNELS of Arm) and inside the motion (2 of
  // 3 frames).
  std::string hierarchy_cut = good.substr(0, good.find("    End Site"));
  ExpectParseError(hierarchy_cut, 9, "unexpected end of file");
  std::string motion_cut = good.substr(0, good.find("7 8 9"));
  ExpectParseError(motion_cut, 20, "truncated");
  ExpectParseError(ReplaceLine(good, 20, "4 5 6 0 0 0 0 0"), 20, "expected 9 values");
  ExpectParseError(ReplaceLine(good, 20, "4 5 6 0 0 0 0 0 90 1"), 20, "found 10");
  ExpectParseError(ReplaceLine(good, 9, "    CHANNELS 3 Xrotation Wrotation Zrotation"), 9,
                   "unknown channel 'Wrotation'");
  ExpectParseError(ReplaceLine(good, 21, "7 8 9 -1e1 0 abc 0 0 0"), 21, "found 'abc'");
  ExpectParseError(ReplaceLine(good, 21, "7 8 9 -1e1 0 nan 0 0 0"), 21, "finite number");
  ExpectParseError(ReplaceLine(good, 8, "    OFFSET 1 two 3"), 8, "found 'two'");
  ExpectParseError(ReplaceLine(good, 17, "Frames: many"), 17, "Frames:");
  ExpectParseError(ReplaceLine(good, 18, "Frame Time: 0"), 18, "Frame Time:");
  ExpectParseError(ReplaceLine(good, 9, "    CHANNELS 7 Xrotation"), 9, "count in [0, 6]");
  ExpectParseError(good + "1 2 3 4 5 6 7 8 9\n", 22, "more frame lines");
  ExpectParseError(ReplaceLine(good, 6, "  JOINTX Arm"), 6, "unexpected 'JOINTX'");
  EXPECT_THROW(ReadBvh("/nonexistent/file.bvh"), Error);
  // Blank lines after the frames are fine.
  EXPECT_EQ(Parse(good + "\n\n").num_frames(), 3);
}

// Issue 20: a huge Frame Time or frame count exhausted memory when resampled.
TEST(BvhParseTest, FrameTimeAndCountAreCapped) {
  const std::string good = kSmallBvh;
  ExpectParseError(ReplaceLine(good, 18, "Frame Time: 1e300"), 18, "expected a Frame Time in");
  ExpectParseError(ReplaceLine(good, 18, "Frame Time: 1e-9"), 18, "expected a Frame Time in");
  const char* kNoChannels = R"(HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
}
MOTION
Frames: 2000000000
Frame Time: 1
)";
  ExpectParseError(kNoChannels, 8, "truncated");
  BvhClip clip = Parse(kSmallBvh);
  clip.frame_time = 1.0;
  EXPECT_EQ(ResampledFrameCount(clip, 30.0), 61);
  clip.values.resize(200000, clip.num_channels);  // 200,000 s: 6 million frames at 30 Hz
  EXPECT_THROW(ResampledFrameCount(clip, 30.0), Error);
}

// A 100,000-joint chain: retargeting walked to the root for every candidate (quadratic,
// minutes); joint intervals make each descendant test constant time.
TEST(BvhRetargetTest, LongJointChainsMapInLinearTime) {
  constexpr int kChain = 100000;
  std::string text =
      "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n";
  for (int k = 0; k < kChain; ++k) text += "JOINT j" + std::to_string(k) + "\n{\nOFFSET 0 1 0\n";
  for (int k = 0; k < kChain; ++k) text += "}\n";
  text += "}\nMOTION\nFrames: 1\nFrame Time: 0.0333\n0 0 0\n";
  const BvhClip clip = Parse(text);
  ASSERT_EQ(static_cast<int>(clip.joints.size()), kChain + 1);
  const std::vector<int> map = MapBvhJoints(clip, Model());
  EXPECT_EQ(map[0], 0);  // only the root maps (no other name matches)
  for (size_t k = 1; k < map.size(); ++k) EXPECT_EQ(map[k], -1) << Model().joints[k].name;
}

TEST(BvhResampleTest, FrameCountsTimesAndSlerp) {
  std::vector<SyntheticFrame> frames(13);
  for (int f = 0; f < 13; ++f) {
    frames[f].zxy_deg["l_elbow"] = Eigen::Vector3d(0, 7.5 * f, 0);  // X rotation, linear
    frames[f].root_position = Eigen::Vector3d(2.0 * f, 0, 0);
  }
  const BvhClip clip = Parse(TemplateBvh(frames, 1.0 / 120.0));
  EXPECT_EQ(ResampledFrameCount(clip, 30.0), 4);  // 0.1 s at 30 Hz: 0, 1/30, 2/30, 3/30
  EXPECT_EQ(ResampledFrameCount(clip, 120.0), 13);
  EXPECT_EQ(ResampledFrameCount(clip, 25.0), 3);  // 0, 0.04, 0.08
  const std::vector<BvhFrame> at30 = ResampleBvh(clip, 30.0);
  ASSERT_EQ(at30.size(), 4u);
  const int elbow = clip.FindJoint("l_elbow");
  for (int k = 0; k < 4; ++k) {
    const BvhFrame native = BvhFrameAt(clip, 4 * k);
    EXPECT_LT(at30[k].rotations[elbow].angularDistance(native.rotations[elbow]), 1e-9);
    EXPECT_LT((at30[k].translations[0] - native.translations[0]).norm(), 1e-9);
  }
  // Half-way between frames: SLERP (angle 7.5 * 2.5 degrees) and linear translation.
  const BvhFrame mid = SampleBvh(clip, 2.5 / 120.0);
  EXPECT_NEAR(Eigen::AngleAxisd(mid.rotations[elbow]).angle(), 7.5 * 2.5 * kDeg, 1e-9);
  EXPECT_NEAR(mid.translations[0].x(), 5.0 + kUnitsPerMetre * Model().joints[0].center.x(), 1e-9);
  // Clamped outside the clip.
  EXPECT_LT(
      SampleBvh(clip, 5.0).rotations[elbow].angularDistance(BvhFrameAt(clip, 12).rotations[elbow]),
      1e-12);
  // Rounded frame times (201 frames of 0.0333333 s) still give 201 frames at 30 Hz.
  const BvhClip rounded = Parse(TemplateBvh(std::vector<SyntheticFrame>(201), 0.0333333));
  EXPECT_EQ(ResampledFrameCount(rounded, 30.0), 201);
  EXPECT_EQ(ResampledFrameCount(rounded, 15.0), 101);
}

BvhRetargetOptions RawOptions() {
  BvhRetargetOptions options;
  options.center_first_frame = false;
  options.floor = FloorMode::kKeep;
  options.skip_frames = 0;
  return options;
}

TEST(BvhRetargetTest, RestMotionGivesTheRestPose) {
  const BvhClip clip = Parse(TemplateBvh(std::vector<SyntheticFrame>(3), 1.0 / 30.0));
  const std::vector<int> map = MapBvhJoints(clip, Model());
  for (int k = 0; k < Model().num_joints(); ++k) {
    EXPECT_EQ(clip.joints[map[k]].name, Model().joints[k].name);
  }
  const std::vector<Pose> poses = RetargetBvh(clip, Model(), RawOptions());
  ASSERT_EQ(poses.size(), 3u);
  for (const Pose& p : poses) {
    EXPECT_LT(Pose::Identity(17).LocalCoordinates(p).norm(), 1e-9);
  }
}

TEST(BvhRetargetTest, KnownJointRotationsAreRecovered) {
  std::vector<SyntheticFrame> frames(2);
  frames[1].zxy_deg["l_elbow"] = Eigen::Vector3d(0, 30, 0);     // flex about X
  frames[1].zxy_deg["l_shoulder"] = Eigen::Vector3d(20, 0, 0);  // raise about Z
  frames[1].zxy_deg["r_knee"] = Eigen::Vector3d(0, 45, 0);
  frames[1].zxy_deg["pelvis"] = Eigen::Vector3d(0, 0, 90);  // turn about Y
  frames[1].zxy_deg["neck"] = Eigen::Vector3d(10, 20, 30);
  frames[1].root_position = Eigen::Vector3d(50, 0, 0);
  const BvhClip clip = Parse(TemplateBvh(frames, 1.0 / 30.0));
  const std::vector<Pose> poses = RetargetBvh(clip, Model(), RawOptions());
  ASSERT_EQ(poses.size(), 2u);
  const Pose& p = poses[1];
  EXPECT_LT((p.rotation - RotY(90)).norm(), 1e-9);
  EXPECT_LT((p.joint_rotations[0] - Eigen::Matrix3d::Identity()).norm(), 1e-9);
  EXPECT_LT((p.joint_rotations[J("l_shoulder")] - RotZ(20)).norm(), 1e-9);
  EXPECT_LT((p.joint_rotations[J("l_elbow")] - RotX(30)).norm(), 1e-9);
  EXPECT_LT((p.joint_rotations[J("r_knee")] - RotX(45)).norm(), 1e-9);
  EXPECT_LT((p.joint_rotations[J("neck")] - RotZ(10) * RotX(20) * RotY(30)).norm(), 1e-9);
  // Translation: automatic scale (cm -> m, 0.01) and the pelvis centre on the BVH root.
  const Eigen::Vector3d pelvis = Model().joints[0].center;
  EXPECT_LT((p.rotation * pelvis + p.translation - pelvis - Eigen::Vector3d(0.5, 0, 0)).norm(),
            1e-9);
  // Posed bone directions equal the BVH's world bone directions.
  std::vector<Eigen::Matrix3d> rot;
  Eigen::MatrixX3d pos;
  BvhForwardKinematics(clip, BvhFrameAt(clip, 1), &rot, &pos);
  Eigen::MatrixX3d centers;
  Skinning(Model()).PosedJointCenters(p, &centers);
  for (const auto& [a, b] :
       std::vector<std::pair<std::string, std::string>>{{"l_shoulder", "l_elbow"},
                                                        {"l_elbow", "l_wrist"},
                                                        {"r_knee", "r_ankle"},
                                                        {"chest", "neck"},
                                                        {"neck", "head"}}) {
    const Eigen::Vector3d posed = (centers.row(J(b)) - centers.row(J(a))).transpose();
    const Eigen::Vector3d bvh =
        (pos.row(clip.FindJoint(b)) - pos.row(clip.FindJoint(a))).transpose();
    EXPECT_LT(AngleBetween(posed, bvh), 1e-9) << a << " -> " << b;
  }
}

TEST(BvhRetargetTest, TPoseRestMapsTheArmsToHorizontal) {
  const BvhClip clip = Parse(TemplateBvh(std::vector<SyntheticFrame>(1), 1.0 / 30.0, true));
  const std::vector<Pose> poses = RetargetBvh(clip, Model(), RawOptions());
  ASSERT_EQ(poses.size(), 1u);
  Eigen::MatrixX3d centers;
  Skinning(Model()).PosedJointCenters(poses[0], &centers);
  for (const auto& [a, b, sign] :
       std::vector<std::tuple<std::string, std::string, double>>{{"l_shoulder", "l_elbow", 1.0},
                                                                 {"l_elbow", "l_wrist", 1.0},
                                                                 {"r_shoulder", "r_elbow", -1.0},
                                                                 {"r_elbow", "r_wrist", -1.0}}) {
    const Eigen::Vector3d d = (centers.row(J(b)) - centers.row(J(a))).transpose();
    EXPECT_LT(AngleBetween(d, Eigen::Vector3d(sign, 0, 0)), 1e-9) << a;
  }
  // The shoulders rotate by the A-pose angle (40 degrees) about the forward axis; hands
  // keep their rest orientation relative to the forearm.
  EXPECT_NEAR(LogSO3(poses[0].joint_rotations[J("l_shoulder")]).z(), 40 * kDeg, 1e-9);
  EXPECT_NEAR(LogSO3(poses[0].joint_rotations[J("r_shoulder")]).z(), -40 * kDeg, 1e-9);
  EXPECT_LT(LogSO3(poses[0].joint_rotations[J("l_wrist")]).norm(), 1e-9);
  EXPECT_LT(LogSO3(poses[0].joint_rotations[J("l_hip")]).norm(), 1e-9);
}

TEST(BvhRetargetTest, AutomaticSkipDropsALeadingReferencePose) {
  // Frame 0: rest; frames 1..9: a slow elbow flexion starting at 60 degrees (a jump of
  // 60 degrees in 1/30 s = 1800 degrees/s, above the 1500 degrees/s threshold).
  std::vector<SyntheticFrame> frames(10);
  for (int f = 1; f < 10; ++f) frames[f].zxy_deg["l_elbow"] = Eigen::Vector3d(0, 60 + f, 0);
  const BvhClip clip = Parse(TemplateBvh(frames, 1.0 / 30.0));
  EXPECT_EQ(CountLeadingJumpFrames(clip, 1500.0), 1);
  EXPECT_EQ(CountLeadingJumpFrames(clip, 2000.0), 0);
  BvhRetargetOptions automatic = RawOptions();
  automatic.skip_frames = -1;
  const std::vector<Pose> poses = RetargetBvh(clip, Model(), automatic);
  ASSERT_EQ(poses.size(), 9u);
  EXPECT_LT((poses[0].joint_rotations[J("l_elbow")] - RotX(61)).norm(), 1e-9);
  EXPECT_EQ(RetargetBvh(clip, Model(), RawOptions()).size(), 10u);
  // Every step a jump: at least one frame is kept.
  std::vector<SyntheticFrame> jumpy(4);
  for (int f = 0; f < 4; ++f) jumpy[f].zxy_deg["l_elbow"] = Eigen::Vector3d(0, 80 * (f % 2), 0);
  EXPECT_EQ(CountLeadingJumpFrames(Parse(TemplateBvh(jumpy, 1.0 / 30.0)), 1500.0), 3);
}

TEST(BvhRetargetTest, FloorCentringAndOptions) {
  std::vector<SyntheticFrame> frames(3);
  for (int f = 0; f < 3; ++f) frames[f].root_position = Eigen::Vector3d(100 + 10 * f, 20, 30);
  const BvhClip clip = Parse(TemplateBvh(frames, 1.0 / 30.0));
  BvhRetargetOptions options;  // centring and clip-minimum floor
  const std::vector<Pose> poses = RetargetBvh(clip, Model(), options);
  EXPECT_LT((poses[0].translation - Eigen::Vector3d::Zero()).norm(), 1e-9);
  EXPECT_LT((poses[2].translation - Eigen::Vector3d(0.2, 0, 0)).norm(), 1e-9);
  options.floor = FloorMode::kKeep;
  EXPECT_NEAR(RetargetBvh(clip, Model(), options)[0].translation.y(), 0.2, 1e-9);
  options.translation_scale = 0.02;
  EXPECT_NEAR(RetargetBvh(clip, Model(), options)[2].translation.x(), 0.4, 1e-9);

  options = BvhRetargetOptions();
  options.frame_rate = 0.0;
  EXPECT_THROW(RetargetBvh(clip, Model(), options), Error);
  options = BvhRetargetOptions();
  options.skip_frames = -2;
  EXPECT_THROW(RetargetBvh(clip, Model(), options), Error);
  options.skip_frames = 3;  // all frames
  EXPECT_THROW(RetargetBvh(clip, Model(), options), Error);
  options.skip_frames = 2;
  EXPECT_EQ(RetargetBvh(clip, Model(), options).size(), 1u);
  options = BvhRetargetOptions();
  options.bvh_to_template = 2.0 * Eigen::Matrix3d::Identity();
  EXPECT_THROW(RetargetBvh(clip, Model(), options), Error);
  options = BvhRetargetOptions();
  options.joint_map = {{"l_elbow", "NoSuchJoint"}};
  EXPECT_THROW(MapBvhJoints(clip, Model(), options), Error);
  options.joint_map = {{"l_elbow", ""}};
  EXPECT_EQ(MapBvhJoints(clip, Model(), options)[J("l_elbow")], -1);
  options.joint_map = {{"l_elbow", "r_elbow"}};  // not below l_shoulder
  EXPECT_THROW(MapBvhJoints(clip, Model(), options), Error);

  // A BVH axis convention with Z up: the retargeted translation is rotated into Y up.
  options = BvhRetargetOptions();
  options.floor = FloorMode::kKeep;
  options.center_first_frame = false;
  options.translation_scale = 0.01;
  options.bvh_to_template = RotX(-90);  // BVH +Z -> template +Y
  const Pose p = RetargetBvh(clip, Model(), options)[0];
  const Eigen::Vector3d root =
      RotX(-90) *
      (0.01 * (Eigen::Vector3d(100, 20, 30) + kUnitsPerMetre * Model().joints[0].center));
  EXPECT_LT((p.rotation * Model().joints[0].center + p.translation - root).norm(), 1e-9);
}

// ---------------------------------------------------------------------------------------
// CMU clips from the shared data folder (skipped when absent).

std::string SharedClip(const std::string& name) {
  return std::string(ARTEX_SHARED_DATA) + "/cmu-mocap/" + name;
}

TEST(BvhCmuTest, JointNamesMapForEverySkeleton) {
  if (!std::filesystem::exists(SharedClip("12_03.bvh"))) GTEST_SKIP() << "no shared data";
  const std::map<std::string, std::map<std::string, std::string>> expected = {
      {"12_03.bvh",
       {{"pelvis", "Hips"},
        {"spine", "LowerBack"},
        {"chest", "Spine1"},
        {"neck", "Neck"},
        {"l_shoulder", "LeftArm"},
        {"r_wrist", "RightHand"},
        {"l_hip", "LeftUpLeg"},
        {"r_ankle", "RightFoot"}}},
      {"10_01.bvh",
       {{"pelvis", "Hips"},
        {"spine", "Chest"},
        {"chest", "CS_BVH"},
        {"head", "Head"},
        {"l_shoulder", "LeftShoulder"},
        {"l_elbow", "LeftElbow"},
        {"r_knee", "RightKnee"}}},
      {"02_02.bvh",
       {{"pelvis", "hip"},
        {"spine", "abdomen"},
        {"chest", "chest"},
        {"l_shoulder", "lShldr"},
        {"r_elbow", "rForeArm"},
        {"l_hip", "lThigh"},
        {"r_knee", "rShin"},
        {"l_ankle", "lFoot"}}},
  };
  for (const auto& [file, pairs] : expected) {
    SCOPED_TRACE(file);
    const BvhClip clip = ReadBvh(SharedClip(file));
    const std::vector<int> map = MapBvhJoints(clip, Model());
    for (int k = 0; k < Model().num_joints(); ++k) EXPECT_GE(map[k], 0) << k;
    for (const auto& [joint, bvh] : pairs) {
      ASSERT_GE(map[J(joint)], 0) << joint;
      EXPECT_EQ(clip.joints[map[J(joint)]].name, bvh) << joint;
    }
  }
}

TEST(BvhCmuTest, ClipsRetargetWithMatchingBoneDirections) {
  if (!std::filesystem::exists(SharedClip("12_03.bvh"))) GTEST_SKIP() << "no shared data";
  const Skinning skinning(Model());
  const std::vector<std::pair<std::string, std::string>> bones = {
      {"l_shoulder", "l_elbow"}, {"l_elbow", "l_wrist"}, {"r_shoulder", "r_elbow"},
      {"r_elbow", "r_wrist"},    {"l_hip", "l_knee"},    {"l_knee", "l_ankle"},
      {"r_hip", "r_knee"},       {"r_knee", "r_ankle"},  {"spine", "chest"},
      {"chest", "neck"},         {"neck", "head"}};
  // These clips start with a reference pose; 02_02 and 03_03 then blend into the motion
  // within 4 frames at 120 Hz (up to 25 degrees per frame): the automatic skip drops them.
  for (const auto& [file, skip] : std::vector<std::pair<std::string, int>>{
           {"12_03.bvh", 1}, {"02_02.bvh", 4}, {"03_03.bvh", 4}, {"10_01.bvh", 1}}) {
    SCOPED_TRACE(file);
    BvhClip clip = ReadBvh(SharedClip(file));
    EXPECT_EQ(CountLeadingJumpFrames(clip, BvhRetargetOptions().leading_jump_deg_per_s), skip);
    const std::vector<Pose> poses = LoadBvhMotion(SharedClip(file), Model());
    clip.values = clip.values.bottomRows(clip.num_frames() - skip).eval();
    const int expected_frames = static_cast<int>(std::floor(clip.duration() * 30.0 + 1e-3)) + 1;
    ASSERT_EQ(static_cast<int>(poses.size()), expected_frames);
    EXPECT_NEAR((poses.size() - 1) / 30.0, clip.duration(), 1.0 / 30.0);
    const std::vector<int> map = MapBvhJoints(clip, Model());
    const std::vector<BvhFrame> frames = ResampleBvh(clip, 30.0);
    double worst = 0.0, lowest = 1e9;
    for (size_t f = 0; f < poses.size(); ++f) {
      ASSERT_TRUE(poses[f].AllFinite()) << "frame " << f;
      std::vector<Eigen::Matrix3d> rot;
      Eigen::MatrixX3d pos, centers;
      BvhForwardKinematics(clip, frames[f], &rot, &pos);
      skinning.PosedJointCenters(poses[f], &centers);
      for (const auto& [a, b] : bones) {
        const Eigen::Vector3d posed = (centers.row(J(b)) - centers.row(J(a))).transpose();
        const Eigen::Vector3d bvh = (pos.row(map[J(b)]) - pos.row(map[J(a)])).transpose();
        worst = std::max(worst, AngleBetween(posed, bvh));
      }
      lowest = std::min(lowest, LowestFootHeight(Model(), poses[f]));
      if (f > 0) {  // no flips between consecutive frames
        const Eigen::VectorXd d = poses[f - 1].LocalCoordinates(poses[f]);
        EXPECT_LT(d.segment(kGlobalRotationIndex, 3 * 18).cwiseAbs().maxCoeff(), 30 * kDeg)
            << "frame " << f;
      }
    }
    EXPECT_LT(worst, 2.0 * kDeg);
    EXPECT_NEAR(lowest, 0.0, 1e-9);  // clip-minimum floor placement
    // First frame centred above the template's rest pelvis.
    const Eigen::Vector3d pelvis = Model().joints[0].center;
    const Eigen::Vector3d p0 = poses[0].rotation * pelvis + poses[0].translation;
    EXPECT_NEAR(p0.x(), pelvis.x(), 1e-9);
    EXPECT_NEAR(p0.z(), pelvis.z(), 1e-9);
    EXPECT_GT(p0.y(), 0.5 * pelvis.y());
    EXPECT_LT(p0.y(), 1.5 * pelvis.y());
  }
}

TEST(BvhCmuTest, GeneratedTemplateFollowsTheBvhBones) {
  if (!std::filesystem::exists(SharedClip("12_03.bvh"))) GTEST_SKIP() << "no shared data";
  BodyShapeOptions shape;
  shape.resolution = 0;
  const Template body = GenerateTemplate(shape);
  const Skinning skinning(body);
  const BvhClip clip = ReadBvh(SharedClip("12_03.bvh"));
  const std::vector<Pose> poses = RetargetBvh(clip, body);
  BvhClip trimmed = clip;
  const int skip = CountLeadingJumpFrames(clip, BvhRetargetOptions().leading_jump_deg_per_s);
  trimmed.values = clip.values.bottomRows(clip.num_frames() - skip).eval();
  const std::vector<BvhFrame> frames = ResampleBvh(trimmed, 30.0);
  ASSERT_EQ(poses.size(), frames.size());
  const std::vector<int> map = MapBvhJoints(clip, body);
  auto b = [&](const char* name) { return body.FindJoint(name); };
  double worst = 0.0, lowest = 1e9;
  for (size_t f = 0; f < poses.size(); ++f) {
    std::vector<Eigen::Matrix3d> rot;
    Eigen::MatrixX3d pos, centers, posed;
    BvhForwardKinematics(trimmed, frames[f], &rot, &pos);
    skinning.PosedJointCenters(poses[f], &centers);
    for (const auto& [from, to] :
         std::vector<std::pair<const char*, const char*>>{{"l_shoulder", "l_elbow"},
                                                          {"r_elbow", "r_wrist"},
                                                          {"l_hip", "l_knee"},
                                                          {"r_knee", "r_ankle"},
                                                          {"spine", "chest"},
                                                          {"neck", "head"}}) {
      const Eigen::Vector3d t = (centers.row(b(to)) - centers.row(b(from))).transpose();
      const Eigen::Vector3d m = (pos.row(map[b(to)]) - pos.row(map[b(from)])).transpose();
      worst = std::max(worst, AngleBetween(t, m));
    }
    skinning.Apply(poses[f], &posed);
    lowest = std::min(lowest, posed.col(1).minCoeff());
  }
  EXPECT_LT(worst, 2.0 * kDeg);
  EXPECT_NEAR(lowest, 0.0, 0.02);  // skinned feet touch the floor somewhere in the clip
}

}  // namespace
}  // namespace artex
