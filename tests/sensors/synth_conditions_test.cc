// Recording conditions of the virtual Kinect (sensors/synth_conditions.h,
// sensors/virtual_scene.h): no background frames, camera placement with pitch and roll, the
// depth camera as world frame, subject orientation, upper-body framing, a second person and
// boxes. Coarse subject, small textures and colour images, few frames.
#include "sensors/synth_conditions.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/sensors/small_synth.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

SynthOptions SmallOptions() {
  SynthOptions o = testing_util::SmallSynthOptions(2, 2);
  o.second_person.shape.resolution = 0;
  o.second_person.texture.size = 256;
  return o;
}

fs::path TempDir(const std::string& name) {
  const fs::path dir = testing_util::FreshTempDir("sc_" + name);
  fs::remove_all(dir);  // absent: the writers create it
  return dir;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

Eigen::MatrixX3d Posed(const Template& t, const Pose& pose) {
  Eigen::MatrixX3d v;
  Skinning(t).Apply(pose, &v);
  return v;
}

// Vertices of the given joints.
std::vector<int> VerticesOf(const Template& t, const std::vector<std::string>& joints) {
  std::vector<int> out;
  for (const std::string& name : joints) {
    const int j = t.FindJoint(name);
    EXPECT_GE(j, 0) << name;
    for (int v = 0; v < t.num_vertices(); ++v) {
      if (t.vertex_joint(v) == j) out.push_back(v);
    }
  }
  return out;
}

bool InImage(const PinholeCamera& c, const Eigen::Vector3d& world) {
  double z = 0;
  const Eigen::Vector2d uv = c.Project(world, &z);
  return z > 0 && uv.x() > -0.5 && uv.y() > -0.5 && uv.x() < c.width - 0.5 &&
         uv.y() < c.height - 0.5;
}

TEST(SynthConditionsTest, ZeroBackgroundFramesWriteNoBackgroundFolderAndTheSequenceReads) {
  SynthOptions o = SmallOptions();
  o.background_frames = 0;
  const fs::path dir = TempDir("nobg");
  const SynthSummary summary = SynthesizeSequence(o, dir.string());
  EXPECT_EQ(summary.background_frames, 0);
  EXPECT_FALSE(fs::exists(dir / "background"));
  EXPECT_FALSE(fs::exists(dir / "background.csv"));
  SequenceReader reader(dir.string());
  EXPECT_TRUE(reader.ReadBackgroundFrames().empty());
  ASSERT_EQ(reader.num_frames(), 2);
  Frame frame;
  std::string warning;
  ASSERT_TRUE(reader.ReadFrame(1, &frame, &warning)) << warning;
  EXPECT_GT(cv::countNonZero(frame.depth), frame.depth.rows * frame.depth.cols / 2);
  EXPECT_EQ(reader.ReadGroundTruth(1).vertices.rows(),
            PrepareSynthSubject(o).subject.num_vertices());
  fs::remove_all(dir);
}

// The camera-frame world: identity depth pose, colour = the depth -> colour extrinsic, and
// ground truth whose skinned pose gives the stored vertices, which project onto pixels whose
// measured depth is theirs.
TEST(SynthConditionsTest, CameraWorldFrameGroundTruthProjectsOntoTheRenderedSubject) {
  SynthOptions o = SmallOptions();
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  o.world_frame = WorldFrame::kDepthCamera;
  o.kinect.depth_pitch_deg = 8;  // a camera whose frame differs from the scene's by a lot
  o.kinect.depth_roll_deg = -15;
  const SynthSubject subject = PrepareSynthSubject(o);
  const fs::path dir = TempDir("camframe");
  SynthesizeSequence(o, subject, dir.string());
  SequenceReader reader(dir.string());
  const Calibration& c = reader.calibration();
  EXPECT_TRUE(c.depth.world_to_camera.matrix().isApprox(Eigen::Matrix4d::Identity(), 1e-12));
  const VirtualKinect scene_rig(ResolveKinectOptions(o), subject.subject, subject.texture_bgr);
  EXPECT_TRUE(c.color.world_to_camera.matrix().isApprox(
      scene_rig.calibration().DepthToColor().matrix(), 1e-9));
  EXPECT_FALSE(scene_rig.calibration().depth.world_to_camera.matrix().isApprox(
      Eigen::Matrix4d::Identity(), 0.1));
  const Skinning skinning(subject.subject);
  for (int f = 0; f < reader.num_frames(); ++f) {
    const GroundTruthFrame truth = reader.ReadGroundTruth(f);
    Eigen::MatrixX3d posed;
    skinning.Apply(truth.pose, &posed);
    EXPECT_LT((posed - truth.vertices).cwiseAbs().maxCoeff(), 1e-5) << "frame " << f;
    Frame frame;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(f, &frame, &warning)) << warning;
    DepthDiagnostics diag;
    const Eigen::MatrixX3d scene_vertices = Posed(subject.subject, subject.poses[f]);
    scene_rig.RenderDepth(f, &scene_vertices, &diag);
    // Project with the depth intrinsics only (identity pose): visible vertices land on
    // subject pixels of their depth; scene-frame vertices (the wrong frame) do not.
    // (A few sole vertices touch the floor, whose depth there is theirs too.)
    auto matching = [&](const Eigen::MatrixX3d& v, int* inside) {
      int match = 0, off_subject = 0;
      *inside = 0;
      for (int i = 0; i < v.rows(); ++i) {
        double z = 0;
        const Eigen::Vector2d uv = c.depth.Project(v.row(i).transpose(), &z);
        const int x = static_cast<int>(std::lround(uv.x())),
                  y = static_cast<int>(std::lround(uv.y()));
        if (z <= 0 || x < 0 || y < 0 || x >= c.depth.width || y >= c.depth.height) continue;
        ++*inside;
        const double measured = frame.depth.at<uint16_t>(y, x) / c.depth_scale;
        if (std::abs(measured - z) < 0.015) {
          ++match;
          off_subject += diag.subject_mask.at<uint8_t>(y, x) == 0;
        }
      }
      EXPECT_LE(off_subject, match / 100 + 1);
      return match;
    };
    int inside = 0;
    const int match = matching(truth.vertices, &inside);
    EXPECT_EQ(inside, truth.vertices.rows());                // the whole subject is in view
    EXPECT_GT(match, inside * 35 / 100) << "of " << inside;  // about the front half
    int wrong_inside = 0, wrong_match = 0;
    for (int i = 0; i < scene_vertices.rows(); ++i) {
      double z = 0;
      const Eigen::Vector2d uv = c.depth.Project(scene_vertices.row(i).transpose(), &z);
      const int x = static_cast<int>(std::lround(uv.x())),
                y = static_cast<int>(std::lround(uv.y()));
      if (z <= 0 || x < 0 || y < 0 || x >= c.depth.width || y >= c.depth.height) continue;
      ++wrong_inside;
      wrong_match += std::abs(frame.depth.at<uint16_t>(y, x) / c.depth_scale - z) < 0.015;
    }
    EXPECT_LT(wrong_match, inside / 20);
  }
  fs::remove_all(dir);
}

TEST(SynthConditionsTest, RollTurnsTheFloorInTheImageAndPitchLooksDown) {
  SynthOptions o = SmallOptions();
  o.camera_placement = CameraPlacement();
  o.camera_placement->azimuth_deg = 0;  // square to the wall: the wall/floor line is level
  const SynthSubject s = PrepareSynthSubject(o);
  for (const double roll : {0.0, 20.0, -20.0}) {
    o.kinect.depth_roll_deg = roll;
    const VirtualKinect kinect(ResolveKinectOptions(o), s.subject, s.texture_bgr);
    const PinholeCamera& cam = kinect.calibration().depth;
    // The floor normal in camera coordinates: its image-plane direction makes `roll` with -y,
    // turned anticlockwise on screen (towards -x) for a positive roll.
    const Eigen::Vector3d n = cam.world_to_camera.linear() * Eigen::Vector3d::UnitY();
    EXPECT_NEAR(std::atan2(-n.x(), -n.y()) * 180 / kPi, roll, 1e-9);
    // Rendered: the wall/floor boundary (topmost floor pixel per column) slopes by -tan(roll)
    // in image coordinates (y down).
    DepthDiagnostics diag;
    kinect.RenderBackgroundDepth(0, &diag);
    std::vector<Eigen::Vector2d> boundary;
    for (int x = 40; x < cam.width - 40; x += 8) {
      for (int y = 0; y < cam.height; ++y) {
        const float z = diag.true_depth.at<float>(y, x);
        if (z <= 0) continue;
        const Eigen::Vector3d world = cam.Unproject(x, y, z);
        if (std::abs(world.y()) < 1e-3 && world.z() > o.kinect.scene.wall_z_m + 0.02) {
          boundary.emplace_back(x, y);
          break;
        }
      }
    }
    ASSERT_GT(boundary.size(), 40u);
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const Eigen::Vector2d& p : boundary) {
      sx += p.x();
      sy += p.y();
      sxx += p.x() * p.x();
      sxy += p.x() * p.y();
    }
    const double m = boundary.size();
    const double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
    EXPECT_NEAR(std::atan(-slope) * 180 / kPi, roll, 1.0) << "roll " << roll;
  }
  // Pitch: positive looks further down (the optical axis' world y decreases by the pitch).
  o.kinect.depth_roll_deg = 0;
  auto axis_elevation = [&](double pitch) {
    o.kinect.depth_pitch_deg = pitch;
    const VirtualKinect kinect(ResolveKinectOptions(o), s.subject, s.texture_bgr);
    const Eigen::Vector3d axis =
        kinect.calibration().depth.world_to_camera.linear().transpose() * Eigen::Vector3d::UnitZ();
    return std::asin(axis.y()) * 180 / kPi;
  };
  EXPECT_NEAR(axis_elevation(0) - axis_elevation(15), 15.0, 1e-6);
}

TEST(SynthConditionsTest, CameraPlacementSetsHeightAndDistance) {
  SynthOptions o = SmallOptions();
  o.subject_position_m = Eigen::Vector3d(0.4, 0, -0.2);
  const Template subject = PrepareSynthSubject(SmallOptions()).subject;
  for (const double height : {0.6, 1.5, 2.4}) {
    for (const double distance : {1.5, 3.0}) {
      CameraPlacement c;
      c.height_m = height;
      c.distance_m = distance;
      c.azimuth_deg = 30;
      o.camera_placement = c;
      const VirtualKinectOptions k = ResolveKinectOptions(o);
      const VirtualKinect kinect(k, subject, cv::Mat(4, 4, CV_8UC3, cv::Scalar(0)));
      const Eigen::Vector3d eye = kinect.calibration().depth.Center();
      EXPECT_NEAR(eye.y(), height, 1e-9);
      EXPECT_NEAR(std::hypot(eye.x() - 0.4, eye.z() + 0.2), distance, 1e-9);
      EXPECT_NEAR(std::atan2(eye.x() - 0.4, eye.z() + 0.2) * 180 / kPi, 30, 1e-9);
      // The colour camera keeps its offset and rotation relative to the depth camera.
      const Eigen::Isometry3d d2c = kinect.calibration().DepthToColor();
      EXPECT_NEAR((d2c.inverse().translation() - k.color_offset_m).norm(), 0, 1e-9);
    }
  }
  // The defaults reproduce the default eye.
  EXPECT_LT(
      (CameraPlacement().Eye(Eigen::Vector3d::Zero()) - VirtualKinectOptions().depth_eye).norm(),
      1e-4);
}

// The subject's front: mean posed normal of the chest's front vertices (rest normal +Z).
Eigen::Vector3d FrontNormalInCamera(const SynthOptions& o) {
  const SynthSubject s = PrepareSynthSubject(o);
  const VirtualKinect kinect(ResolveKinectOptions(o), s.subject, s.texture_bgr);
  Eigen::MatrixX3d rest_normals, posed_normals;
  ComputeVertexNormals(s.subject.vertices, s.subject.triangles, &rest_normals);
  const Eigen::MatrixX3d posed = Posed(s.subject, s.poses[0]);
  ComputeVertexNormals(posed, s.subject.triangles, &posed_normals);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int v : VerticesOf(s.subject, {"chest", "spine"})) {
    if (rest_normals(v, 2) > 0.8) sum += posed_normals.row(v).transpose();
  }
  return (kinect.calibration().depth.world_to_camera.linear() * sum).normalized();
}

TEST(SynthConditionsTest, FacingAwayTurnsTheSubjectsFrontAwayFromTheCamera) {
  SynthOptions o = SmallOptions();
  o.motion.type = MotionType::kStill;
  const Eigen::Vector3d towards = FrontNormalInCamera(o);
  EXPECT_LT(towards.z(), -0.9);  // camera z forward: the front faces the camera
  ApplySynthCondition(SynthCondition::kFacingAway, &o);
  EXPECT_EQ(o.subject_yaw_deg, 180.0);
  const Eigen::Vector3d away = FrontNormalInCamera(o);
  EXPECT_GT(away.z(), 0.9);
  ApplySynthCondition(SynthCondition::kSideways, &o);
  EXPECT_LT(std::abs(FrontNormalInCamera(o).z()), 0.35);  // about side-on (camera yaw ~7 deg)
}

TEST(SynthConditionsTest, UpperBodyFramingKeepsTheLegsOutOfBothImages) {
  SynthOptions o = SmallOptions();
  o.motion.frames = 31;
  ApplySynthCondition(SynthCondition::kUpperBody, &o);
  ASSERT_TRUE(o.camera_placement.has_value());
  EXPECT_GE(o.camera_placement->distance_m, 0.9);
  EXPECT_LE(o.camera_placement->distance_m, 1.2);
  const SynthSubject s = PrepareSynthSubject(o);
  const VirtualKinect kinect(ResolveKinectOptions(o), s.subject, s.texture_bgr);
  // Legs: shanks and feet, and the thighs below the crotch (hip-joint vertices more than
  // 5 cm below the hip centre at rest; those above belong to the hips the border cuts).
  std::vector<int> legs = VerticesOf(s.subject, {"l_knee", "l_ankle", "r_knee", "r_ankle"});
  for (const char* hip : {"l_hip", "r_hip"}) {
    const double below = s.subject.joints[s.subject.FindJoint(hip)].center.y() - 0.05;
    for (int v : VerticesOf(s.subject, {hip})) {
      if (s.subject.vertices(v, 1) < below) legs.push_back(v);
    }
  }
  const std::vector<int> head = VerticesOf(s.subject, {"head"});
  const std::vector<int> chest = VerticesOf(s.subject, {"chest"});
  ASSERT_GT(legs.size(), 100u);
  for (const PinholeCamera* cam : {&kinect.calibration().depth, &kinect.calibration().color}) {
    for (int f = 0; f < 31; f += 5) {
      const Eigen::MatrixX3d v = Posed(s.subject, s.poses[f]);
      int legs_in = 0, head_in = 0, chest_in = 0;
      for (int i : legs) legs_in += InImage(*cam, v.row(i).transpose());
      for (int i : head) head_in += InImage(*cam, v.row(i).transpose());
      for (int i : chest) chest_in += InImage(*cam, v.row(i).transpose());
      EXPECT_EQ(legs_in, 0) << "frame " << f << ", camera " << cam->width;
      EXPECT_GT(head_in, static_cast<int>(head.size()) * 9 / 10);
      EXPECT_EQ(chest_in, static_cast<int>(chest.size()));
    }
  }
  // The rendered subject reaches the bottom border (the cut).
  DepthDiagnostics diag;
  const Eigen::MatrixX3d v = Posed(s.subject, s.poses[10]);
  kinect.RenderDepth(10, &v, &diag);
  EXPECT_GT(cv::countNonZero(diag.subject_mask.row(diag.subject_mask.rows - 1)), 20);
}

TEST(SynthConditionsTest, SecondPersonAndBoxesAppearInDepthButNotInTheGroundTruth) {
  SynthOptions o = SmallOptions();
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  o.motion.frames = 40;
  ApplySynthCondition(SynthCondition::kRoom, &o);
  o.second_person.shape.resolution = 0;
  o.second_person.texture.size = 256;
  EXPECT_EQ(o.background_frames, 0);
  EXPECT_EQ(o.world_frame, WorldFrame::kDepthCamera);
  const SynthSubject s = PrepareSynthSubject(o);
  ASSERT_EQ(s.others.size(), 1u);
  ASSERT_EQ(s.other_poses[0].size(), s.poses.size());
  EXPECT_NE(s.others[0].body.num_vertices(), s.subject.num_vertices());  // another body
  const VirtualKinectOptions k = ResolveKinectOptions(o);
  ASSERT_EQ(k.scene.boxes.size(), 3u);
  const VirtualKinect kinect(k, s.subject, s.texture_bgr, s.others);
  std::vector<double> person_columns;
  for (int f : {0, 39}) {
    const Eigen::MatrixX3d subject = Posed(s.subject, s.poses[f]);
    const std::vector<Eigen::MatrixX3d> others = {Posed(s.others[0].body, s.other_poses[0][f])};
    DepthDiagnostics diag;
    const cv::Mat depth = kinect.RenderDepth(f, &subject, others, &diag);
    const int person = cv::countNonZero(diag.surface == static_cast<uint8_t>(SurfaceKind::kPerson));
    const int boxes = cv::countNonZero(diag.surface == static_cast<uint8_t>(SurfaceKind::kBox));
    EXPECT_GT(person, 1500) << "frame " << f;
    EXPECT_GT(boxes, 3000) << "frame " << f;
    // The ground-truth subject mask is exactly the subject's pixels.
    EXPECT_EQ(cv::countNonZero(diag.subject_mask !=
                               (diag.surface == static_cast<uint8_t>(SurfaceKind::kSubject))),
              0);
    // Person and box pixels carry measured depth; the person is behind the subject.
    double subject_depth = 0, person_depth = 0, column = 0;
    int n_subject = 0, n_person = 0, valid = 0, n_box = 0;
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        const auto kind = static_cast<SurfaceKind>(diag.surface.at<uint8_t>(y, x));
        const double z = diag.true_depth.at<float>(y, x);
        if (kind == SurfaceKind::kSubject) {
          subject_depth += z;
          ++n_subject;
        } else if (kind == SurfaceKind::kPerson) {
          person_depth += z;
          column += x;
          ++n_person;
          valid += std::abs(depth.at<uint16_t>(y, x) / 1000.0 - z) < 0.002;
        } else if (kind == SurfaceKind::kBox) {
          n_box += std::abs(depth.at<uint16_t>(y, x) / 1000.0 - z) < 0.002;
        }
      }
    }
    EXPECT_GT(valid, n_person * 9 / 10);
    EXPECT_GT(n_box, boxes * 9 / 10);
    EXPECT_GT(person_depth / n_person - subject_depth / n_subject, 0.8);
    person_columns.push_back(column / n_person);
    // Without the others nothing is labelled a person; the static boxes remain.
    DepthDiagnostics alone;
    kinect.RenderDepth(f, &subject, &alone);
    EXPECT_EQ(cv::countNonZero(alone.surface == static_cast<uint8_t>(SurfaceKind::kPerson)), 0);
  }
  EXPECT_GT(person_columns[1] - person_columns[0], 40);  // walks to the right in the image
  // The ground truth holds the subject only.
  const fs::path dir = TempDir("room");
  o.motion.frames = 2;
  const SynthSubject two = PrepareSynthSubject(o);
  SynthesizeSequence(o, two, dir.string());
  SequenceReader reader(dir.string());
  EXPECT_FALSE(fs::exists(dir / "background"));
  const GroundTruthFrame truth = reader.ReadGroundTruth(1);
  EXPECT_EQ(truth.vertices.rows(), two.subject.num_vertices());
  EXPECT_LT((Posed(two.subject, truth.pose) - truth.vertices).cwiseAbs().maxCoeff(), 1e-5);
  fs::remove_all(dir);
}

TEST(SynthConditionsTest, BoxesAndConditionsAreDeterministic) {
  const SceneOptions scene;
  const BoxLayoutOptions layout;
  const std::vector<SceneBox> a = GenerateSceneBoxes(scene, layout, 5, 3, Eigen::Vector3d::Zero());
  const std::vector<SceneBox> b = GenerateSceneBoxes(scene, layout, 5, 3, Eigen::Vector3d::Zero());
  const std::vector<SceneBox> c = GenerateSceneBoxes(scene, layout, 5, 4, Eigen::Vector3d::Zero());
  ASSERT_EQ(a.size(), 5u);
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].center_xz, b[k].center_xz);
    EXPECT_EQ(a[k].size_m, b[k].size_m);
    // Beside the subject, clear of it, in front of the wall.
    const double radius = 0.5 * std::hypot(a[k].size_m.x(), a[k].size_m.z());
    EXPECT_GE(a[k].center_xz.norm(), layout.clear_radius_m + radius - 1e-9);
    EXPECT_GT(a[k].center_xz.y() - radius, scene.wall_z_m);
  }
  EXPECT_NE(a[0].center_xz, c[0].center_xz);
  // Two room sequences with the same seed are byte-identical.
  SynthOptions o = SmallOptions();
  ApplySynthCondition(SynthCondition::kRoom, &o);
  o.second_person.shape.resolution = 0;
  o.second_person.texture.size = 256;
  const fs::path d1 = TempDir("det1"), d2 = TempDir("det2");
  SynthesizeSequence(o, d1.string());
  SynthesizeSequence(o, d2.string());
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(d1)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), d1);
    ASSERT_EQ(ReadAll(entry.path()), ReadAll(d2 / rel)) << rel;
    ++files;
  }
  EXPECT_GT(files, 6);
  fs::remove_all(d1);
  fs::remove_all(d2);
}

TEST(SynthConditionsTest, InvalidValuesNameTheFieldAndConditionsParse) {
  auto message = [](const SynthOptions& o) {
    std::string why;
    EXPECT_FALSE(o.IsValid(&why));
    return why;
  };
  SynthOptions o = SmallOptions();
  o.kinect.depth_roll_deg = 200;
  EXPECT_NE(message(o).find("depth_roll_deg"), std::string::npos) << message(o);
  o = SmallOptions();
  o.kinect.depth_pitch_deg = 95;
  EXPECT_NE(message(o).find("depth_pitch_deg"), std::string::npos);
  o = SmallOptions();
  o.camera_placement = CameraPlacement();
  o.camera_placement->height_m = -1;
  EXPECT_NE(message(o).find("camera_placement.height_m"), std::string::npos);
  EXPECT_NE(message(o).find("-1"), std::string::npos);
  o = SmallOptions();
  o.random_boxes = 40;
  EXPECT_NE(message(o).find("random_boxes"), std::string::npos);
  o = SmallOptions();
  o.second_person.enabled = true;
  o.second_person.speed_m_s = 9;
  EXPECT_NE(message(o).find("second_person.speed_m_s"), std::string::npos);
  o = SmallOptions();
  o.kinect.scene.boxes.push_back(SceneBox());
  o.kinect.scene.boxes.back().size_m.y() = 0;
  EXPECT_NE(message(o).find("scene.boxes[0]"), std::string::npos);
  try {
    ParseSynthCondition("kitchen");
    FAIL() << "expected artex::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("upper_body"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("kitchen"), std::string::npos) << e.what();
  }
  for (const std::string& name : SynthConditionNames()) {
    EXPECT_EQ(SynthConditionName(ParseSynthCondition(name)), name);
  }
  EXPECT_EQ(ParseWorldFrame("camera"), WorldFrame::kDepthCamera);
  EXPECT_THROW(ParseWorldFrame("world"), Error);
}

// The `artex synth` flags reach the options.
TEST(SynthConditionsTest, CommandLineFlagsSetTheConditions) {
  ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << "build the artex target first: " << ARTEX_BINARY;
  const fs::path dir = TempDir("cli");
  const std::string command = std::string(ARTEX_BINARY) +
                              " synth --frames 2 --subject-resolution 0 --texture-size 256 "
                              "--color-width 200 --color-height 254 --noise off "
                              "--condition rolled --background-frames 0 --world-frame camera "
                              "--camera-height 1.6 --camera-distance 2.0 --camera-pitch 5 -o " +
                              dir.string() + " 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  EXPECT_FALSE(fs::exists(dir / "background"));
  SequenceReader reader(dir.string());
  EXPECT_TRUE(reader.calibration().depth.world_to_camera.matrix().isApprox(
      Eigen::Matrix4d::Identity(), 1e-12));
  // Expected camera: placement (1.6 m high, 2 m away, default azimuth) with pitch 5, roll 20;
  // the first pose's translation in camera coordinates is then T * scene translation.
  SynthOptions o = SmallOptions();
  o.kinect.depth_roll_deg = 20;
  o.kinect.depth_pitch_deg = 5;
  o.camera_placement = CameraPlacement();
  o.camera_placement->height_m = 1.6;
  o.camera_placement->distance_m = 2.0;
  const SynthSubject s = PrepareSynthSubject(o);
  const VirtualKinect kinect(ResolveKinectOptions(o), s.subject, s.texture_bgr);
  const Eigen::Vector3d expected =
      kinect.calibration().depth.world_to_camera * s.poses[1].translation;
  EXPECT_LT((reader.ReadGroundTruth(1).pose.translation - expected).norm(), 1e-9);
  const std::string bad = std::string(ARTEX_BINARY) + " synth --frames 2 --condition kitchen -o " +
                          dir.string() + "_bad 2>/dev/null";
  EXPECT_NE(std::system(bad.c_str()), 0);
  fs::remove_all(dir);
}

// The depth effects' flags override the --noise preset both ways: the default preset without its
// disparity noise, quantisation and shadow is the "off" preset with the default's drop-outs at
// discontinuities and grazing angles, depth image for depth image; and those drop-outs remove
// pixels.
TEST(SynthConditionsTest, DepthEffectFlagsOverrideThePreset) {
  ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << "build the artex target first: " << ARTEX_BINARY;
  const std::string base = std::string(ARTEX_BINARY) +
                           " synth --frames 2 --subject-resolution 0 --texture-size 256 "
                           "--color-width 200 --color-height 254 --background-frames 0 ";
  const auto synth = [&](const std::string& name, const std::string& flags) {
    const fs::path dir = TempDir(name);
    const std::string command = base + flags + " -o " + dir.string() + " 2>/dev/null";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return dir;
  };
  const fs::path from_default = synth("fx_default", "--noise default --disparity-noise 0 "
                                                    "--disparity-step 0 --projector-shadow false");
  const fs::path from_off = synth("fx_off", "--noise off --edge-drop 0.6 --grazing-angle 78");
  const fs::path off = synth("fx_plain", "--noise off");
  const auto read = [](const fs::path& dir) {
    std::ifstream in(dir / "depth" / "000001.png", std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  EXPECT_FALSE(read(from_off).empty());
  EXPECT_EQ(read(from_default), read(from_off));
  const auto valid = [](const fs::path& dir) {
    SequenceReader reader(dir.string());
    Frame frame;
    std::string warning;
    EXPECT_TRUE(reader.ReadFrame(1, &frame, &warning)) << warning;
    return frame.depth.empty() ? 0 : cv::countNonZero(frame.depth);
  };
  EXPECT_LT(valid(from_off), valid(off) - 50) << "the drop-outs remove pixels";
  const std::string bad =
      base + "--grazing-angle 0 -o " + (from_off.string() + "_bad") + " 2>/dev/null";
  EXPECT_NE(std::system(bad.c_str()), 0);
  for (const fs::path& dir : {from_default, from_off, off}) fs::remove_all(dir);
}

}  // namespace
}  // namespace artex
