// The stream's rest shapes (stream/rest_shape.h, docs/streaming.md): the payload round-trips
// within half its step and rejects other templates and damage; a sender's SetRestShape makes
// that frame's record a keyframe carrying the shape, the player skins the frames from it on with
// the new body (also after joining later), and version 1 streams are still read.
#include "stream/rest_shape.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "models/error.h"
#include "models/template_generator.h"
#include "stream/stream_player.h"
#include "stream/stream_sender.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
constexpr int kFrames = 24;
constexpr int kKeyframeInterval = 8;
constexpr int kShapeFrame = 11;  // not a keyframe of the interval

Template Base() {
  BodyShapeOptions shape;
  shape.resolution = 0;
  return GenerateTemplate(shape);
}

// Another body on the same rig and mesh: 8 % larger, with a smooth bulge (as bone lengths,
// girths and surface detail change only joint centres and vertices).
Template Shaped(const Template& base) {
  Template t = base;
  for (Joint& j : t.joints) j.center *= 1.08;
  for (int v = 0; v < t.num_vertices(); ++v) {
    const Eigen::RowVector3d p = base.vertices.row(v);
    t.vertices.row(v) = 1.08 * p + Eigen::RowVector3d(0.004 * std::sin(9.0 * p.y()), 0.0,
                                                      0.003 * std::cos(7.0 * p.x()));
  }
  return t;
}

double MaxVertexDistance(const Template& a, const Template& b) {
  return (a.vertices - b.vertices).rowwise().norm().maxCoeff();
}

double MaxJointDistance(const Template& a, const Template& b) {
  double worst = 0.0;
  for (int j = 0; j < a.num_joints(); ++j)
    worst = std::max(worst, (a.joints[j].center - b.joints[j].center).norm());
  return worst;
}

// Half a step per coordinate, and the float32 rounding of the header's vertices.
constexpr double kVertexBound = 0.5 * kRestShapeStep * 1.7321 + 1e-6;

TEST(RestShapeTest, RoundTripsWithinHalfAStep) {
  const Template base = Base(), shaped = Shaped(base);
  const std::vector<uint8_t> payload = EncodeRestShape(base, shaped);
  EXPECT_EQ(payload.size(), 14u + 24u * base.num_joints() + 6u * base.num_vertices());
  Template decoded;
  std::string why;
  ASSERT_TRUE(DecodeRestShape(payload, base, &decoded, &why)) << why;
  EXPECT_EQ(MaxJointDistance(decoded, shaped), 0.0);
  EXPECT_LT(MaxVertexDistance(decoded, shaped), kVertexBound);
  EXPECT_GT(MaxVertexDistance(base, shaped), 0.05);  // the shape moved the body
  // The rig, mesh and weights are the header template's.
  EXPECT_EQ(decoded.triangles, base.triangles);
  EXPECT_EQ(decoded.lbs_weight, base.lbs_weight);
  EXPECT_EQ(decoded.joints[3].twist_axis, base.joints[3].twist_axis);
}

TEST(RestShapeTest, RejectsOtherTemplatesAndDamage) {
  const Template base = Base(), shaped = Shaped(base);
  Template fewer = shaped;
  fewer.vertices.conservativeResize(fewer.num_vertices() - 1, 3);
  try {
    EncodeRestShape(base, fewer);
    ADD_FAILURE() << "a template with another vertex count was encoded";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("vertices"), std::string::npos) << e.what();
  }
  Template far = shaped;
  far.vertices(5, 1) += 4.0;  // beyond the int16 range of 0.1 mm steps
  EXPECT_THROW(EncodeRestShape(base, far), Error);

  const std::vector<uint8_t> payload = EncodeRestShape(base, shaped);
  Template out = base;
  std::string why;
  std::vector<uint8_t> truncated(payload.begin(), payload.end() - 2);
  EXPECT_FALSE(DecodeRestShape(truncated, base, &out, &why));
  EXPECT_NE(why.find("bytes"), std::string::npos) << why;
  std::vector<uint8_t> other = payload;
  other[0] ^= 1;  // the joint count
  EXPECT_FALSE(DecodeRestShape(other, base, &out, &why));
  EXPECT_NE(why.find("joints"), std::string::npos) << why;
  EXPECT_FALSE(DecodeRestShape({}, base, &out, &why));
  EXPECT_EQ(MaxVertexDistance(out, base), 0.0);  // unchanged after the failures
}

Pose MotionPose(int frame, int joints) {
  Pose p = Pose::Identity(joints);
  p.translation = Eigen::Vector3d(0.01 * frame, 0.0, 2.5);
  return p;
}

// A poses-only stream of kFrames frames; the shape is set before frame kShapeFrame.
std::vector<uint8_t> WriteStream(const Template& base, const Template* shaped,
                                 StreamSummary* summary) {
  const fs::path path =
      fs::temp_directory_path() / ("artex_rest_shape_" + std::to_string(::getpid()) + ".artx");
  StreamOptions o;
  o.keyframe_interval = kKeyframeInterval;
  StreamSender sender(path.string(), base, PinholeCamera(), 30.0, 0, false, o);
  for (int f = 0; f < kFrames; ++f) {
    if (shaped && f == kShapeFrame) sender.SetRestShape(*shaped);
    sender.AddFrame(f, MotionPose(f, base.num_joints()), cv::Mat(), nullptr);
  }
  *summary = sender.Finish();
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>{}};
  fs::remove(path);
  return bytes;
}

TEST(RestShapeTest, ThePlayerSkinsEachFrameWithItsShape) {
  const Template base = Base(), shaped = Shaped(base);
  StreamSummary summary;
  const std::vector<uint8_t> bytes = WriteStream(base, &shaped, &summary);
  EXPECT_EQ(summary.shapes, 1);
  EXPECT_EQ(summary.shape_bytes, EncodeRestShape(base, shaped).size());
  EXPECT_EQ(summary.keyframes, kFrames / kKeyframeInterval + 1);  // the shape's record too

  StreamPlayer player(std::make_unique<StreamReader>(bytes, "shaped"));
  PlayedFrame f;
  int frames = 0;
  while (player.Next(&f)) {
    EXPECT_EQ(f.frame, frames++);
    EXPECT_EQ(f.shape_changed, f.frame == kShapeFrame) << f.frame;
    EXPECT_EQ(f.keyframe, f.frame % kKeyframeInterval == 0 || f.frame == kShapeFrame);
    if (f.frame == kShapeFrame - 1) EXPECT_LT(MaxVertexDistance(player.model(), base), 1e-6);
    if (f.frame == kShapeFrame) {
      EXPECT_LT(MaxVertexDistance(player.model(), shaped), kVertexBound);
      EXPECT_EQ(MaxJointDistance(player.model(), shaped), 0.0);
    }
  }
  EXPECT_EQ(frames, kFrames);
  EXPECT_TRUE(player.issues().empty());

  // Joining after the shape's record: the shape comes from the skipped record.
  StreamPlayer joined(std::make_unique<StreamReader>(bytes, "joined"), kShapeFrame + 2);
  ASSERT_TRUE(joined.Next(&f));
  EXPECT_EQ(f.frame, 2 * kKeyframeInterval);
  EXPECT_TRUE(f.shape_changed);
  EXPECT_LT(MaxVertexDistance(joined.model(), shaped), kVertexBound);
}

TEST(RestShapeTest, VersionOneStreamsAreStillRead) {
  const Template base = Base();
  StreamSummary summary;
  const std::vector<uint8_t> bytes = WriteStream(base, nullptr, &summary);
  const StreamReader reader(bytes, "v2");
  EXPECT_EQ(reader.header().version, kStreamVersion);
  StreamHeader h = reader.header();
  h.version = 1;
  std::vector<uint8_t> old = EncodeStreamHeader(h);
  old.insert(old.end(), bytes.begin() + reader.header_size(), bytes.end());
  StreamPlayer player(std::make_unique<StreamReader>(old, "v1"));
  EXPECT_EQ(player.header().version, 1);
  PlayedFrame f;
  int frames = 0;
  while (player.Next(&f)) ++frames;
  EXPECT_EQ(frames, kFrames);
  EXPECT_TRUE(player.issues().empty());
  // Version 3 is not understood.
  h.version = kStreamVersion + 1;
  std::vector<uint8_t> future = EncodeStreamHeader(h);
  try {
    StreamReader r(future, "v3");
    ADD_FAILURE() << "a version 3 header was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("version"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace artex
