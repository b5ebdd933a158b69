// Sequence synthesis with the virtual Kinect (sensors/virtual_kinect.h): options, the
// subject and other people, and the pipelined frame loop writing an artex sequence.
#include <tbb/parallel_pipeline.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "models/tsan_annotations.h"
#include "models/skinning.h"
#include "models/template_io.h"
#include "sensors/bvh.h"
#include "sensors/option_text.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace {

using option_text::Fail;
using option_text::Str;

Eigen::Matrix3d Yaw(double degrees) {
  return Eigen::AngleAxisd(degrees * kDegToRad, Eigen::Vector3d::UnitY()).toRotationMatrix();
}

// The pose whose skinned vertices are T applied to `pose`'s (the global similarity is
// x -> s R x' + t, so T composes onto R and t).
Pose TransformedPose(const Pose& pose, const Eigen::Isometry3d& t) {
  Pose out = pose;
  out.rotation = t.linear() * pose.rotation;
  out.translation = t.linear() * pose.translation + t.translation();
  return out;
}

// The second person's poses (sections "Conditions" of docs/synthesis.md).
std::vector<Pose> SecondPersonPoses(const SynthOptions& options, const Template& body, int frames,
                                    const VirtualKinectOptions& kinect) {
  const SecondPersonOptions& o = options.second_person;
  MotionOptions motion = o.motion;
  motion.frames = frames;
  motion.frame_rate = options.motion.frame_rate;
  std::vector<Pose> poses = GenerateMotion(body, motion);
  // Horizontal viewing direction f of the depth camera towards the subject's start, right
  // axis r = f x Y.
  Eigen::Vector3d f = options.subject_position_m - kinect.depth_eye;
  f.y() = 0;
  if (f.norm() < 1e-6) {
    f = kinect.depth_target - kinect.depth_eye;
    f.y() = 0;
  }
  if (f.norm() < 1e-6) throw Error("second_person: the depth camera looks straight down");
  f.normalize();
  const Eigen::Vector3d r = f.cross(Eigen::Vector3d::UnitY());
  Eigen::Vector3d start = options.subject_position_m + o.behind_m * f + o.start_across_m * r;
  start.y() = 0;
  // Facing the direction of travel, or the camera (-f) when standing.
  const Eigen::Vector3d facing = o.speed_m_s > 0 ? r : o.speed_m_s < 0 ? Eigen::Vector3d(-r) : -f;
  const Eigen::Matrix3d yaw = Yaw(std::atan2(facing.x(), facing.z()) / kDegToRad);
  for (int i = 0; i < frames; ++i) {
    Pose& p = poses[i];
    const double t = i / options.motion.frame_rate;
    p.rotation = yaw * p.rotation;
    p.translation = yaw * p.translation + start + o.speed_m_s * t * r;
  }
  return poses;
}

}  // namespace

WorldFrame ParseWorldFrame(const std::string& name) {
  if (name == "scene") return WorldFrame::kScene;
  if (name == "camera") return WorldFrame::kDepthCamera;
  throw Error("world frame: expected one of scene, camera; found '" + name + "'");
}

const char* WorldFrameName(WorldFrame frame) {
  return frame == WorldFrame::kDepthCamera ? "camera" : "scene";
}

BodyShapeOptions DefaultSubjectShape() {
  BodyShapeOptions s;
  s.height = 1.72;
  s.girth = 1.08;
  s.shoulder_width = 1.05;
  s.hip_width = 1.04;
  s.arm_length = 0.98;
  s.leg_length = 1.02;
  return s;
}

bool SynthOptions::IsValid(std::string* error) const {
  if (!kinect.IsValid(error)) return false;
  std::string why;
  if (!subject_shape.IsValid(&why)) return Fail(error, "subject shape: " + why);
  if (!texture.IsValid(&why)) return Fail(error, "subject texture: " + why);
  if (bvh_path.empty() ? motion.frames < 1 : motion.frames < 0)
    return Fail(error,
                "motion.frames must be >= 1 (>= 0 with a BVH file), found " + Str(motion.frames));
  if (!(motion.frame_rate > 0))
    return Fail(error, "motion.frame_rate must be > 0, found " + Str(motion.frame_rate));
  if (!(motion.speed > 0.0 && motion.speed <= 8.0))
    return Fail(error, "motion.speed (--speed) must be in (0, 8], found " + Str(motion.speed));
  if (motion.frame_step < 1)
    return Fail(error,
                "motion.frame_step (--frame-step) must be >= 1, found " + Str(motion.frame_step));
  if (background_frames < 0)
    return Fail(error, "background_frames must be >= 0, found " + Str(background_frames));
  if (!subject_position_m.allFinite() || !std::isfinite(subject_yaw_deg))
    return Fail(error, "subject placement must be finite");
  if (camera_placement && !camera_placement->IsValid(error)) return false;
  if (random_boxes < 0 || random_boxes > 32)
    return Fail(error, "random_boxes (--boxes) must be in [0, 32], found " + Str(random_boxes));
  if (random_boxes > 0 && !box_layout.IsValid(error)) return false;
  if (static_cast<size_t>(random_boxes) + kinect.scene.boxes.size() > 32)
    return Fail(error, "random_boxes + kinect.scene.boxes: expected at most 32 boxes, found " +
                           Str(random_boxes + kinect.scene.boxes.size()));
  if (!second_person.IsValid(error)) return false;
  return true;
}

VirtualKinectOptions ResolveKinectOptions(const SynthOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("synthesis options: " + why);
  VirtualKinectOptions k = options.kinect;
  k.frame_rate = options.motion.frame_rate;
  if (options.camera_placement) {
    k.depth_eye = options.camera_placement->Eye(options.subject_position_m);
    k.depth_target = options.camera_placement->Target(options.subject_position_m);
  }
  const std::vector<SceneBox> boxes = GenerateSceneBoxes(
      k.scene, options.box_layout, options.random_boxes, k.seed, options.subject_position_m);
  k.scene.boxes.insert(k.scene.boxes.end(), boxes.begin(), boxes.end());
  if (!k.IsValid(&why)) throw Error("synthesis options: " + why);
  return k;
}

// ---------------------------------------------------------------------------------------------
// Sequence synthesis

Template LoadSubjectTemplate(const std::string& path) {
  const std::string what = "subject template '" + path + "': ";
  Template t;
  try {
    t = ReadTemplateGlb(path);
  } catch (const Error& e) {
    throw Error(what + e.what());
  }
  if (!t.has_uvs()) {
    throw Error(what + "expected a UV atlas (the true texture is generated over it), found " +
                Str(t.uv_triangles.rows()) + " UV triangles for " + Str(t.num_triangles()) +
                " triangles");
  }
  std::string missing;
  for (int j = 0; j < kDefaultNumJoints; ++j) {
    const std::string name = DefaultJointNames()[j];
    if (t.FindJoint(name) < 0) missing += (missing.empty() ? "" : ", ") + name;
  }
  if (!missing.empty()) {
    std::string found;
    for (const Joint& j : t.joints) found += (found.empty() ? "" : ", ") + j.name;
    throw Error(what + "expected the joints of the default rig (the motions drive them), missing " +
                missing + "; found " + found);
  }
  return t;
}

SynthSubject PrepareSynthSubject(const SynthOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("synthesis options: " + why);
  SynthSubject s;
  s.subject = options.subject_template.empty() ? GenerateTemplate(options.subject_shape)
                                               : LoadSubjectTemplate(options.subject_template);
  s.texture_bgr = GenerateSubjectTexture(s.subject, options.texture);
  if (!options.bvh_path.empty()) {
    BvhRetargetOptions retarget;
    // Playback speed and frame step as for the built-in motions (frame f at clip time
    // f * frame_step * speed / frame_rate).
    retarget.frame_rate =
        options.motion.frame_rate / (options.motion.speed * options.motion.frame_step);
    s.poses = LoadBvhMotion(options.bvh_path, s.subject, retarget);
    if (options.motion.frames > 0 && static_cast<int>(s.poses.size()) > options.motion.frames) {
      s.poses.resize(options.motion.frames);
    }
    if (s.poses.empty()) throw Error("BVH file '" + options.bvh_path + "': no frames");
  } else {
    s.poses = GenerateMotion(s.subject, options.motion);
  }
  const Eigen::Matrix3d yaw = Yaw(options.subject_yaw_deg);
  for (Pose& p : s.poses) {
    p.rotation = yaw * p.rotation;
    p.translation = yaw * p.translation + options.subject_position_m;
  }
  if (options.second_person.enabled) {
    ScenePerson person;
    person.body = GenerateTemplate(options.second_person.shape);
    person.texture_bgr = GenerateSubjectTexture(person.body, options.second_person.texture);
    s.other_poses.push_back(SecondPersonPoses(
        options, person.body, static_cast<int>(s.poses.size()), ResolveKinectOptions(options)));
    s.others.push_back(std::move(person));
  }
  return s;
}

SynthSummary SynthesizeSequence(const SynthOptions& options, const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress) {
  if (progress) {
    SynthProgress p;
    progress(p);  // kSetup, 0 of 1: the subject is being generated
  }
  const auto start = std::chrono::steady_clock::now();
  const SynthSubject subject = PrepareSynthSubject(options);
  SynthSummary summary = SynthesizeSequence(options, subject, out_folder, progress);
  const double setup =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() -
      summary.total_seconds;
  summary.setup_seconds += setup;
  summary.total_seconds += setup;
  return summary;
}

SynthSummary SynthesizeSequence(const SynthOptions& options, const SynthSubject& s,
                                const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress) {
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  };
  auto report = [&](SynthProgress::Stage stage, int done, int total) {
    if (!progress) return;
    SynthProgress p;
    p.stage = stage;
    p.done = done;
    p.total = total;
    progress(p);
  };
  const Clock::time_point start = Clock::now();
  SynthSummary summary;
  std::string why;
  if (!options.IsValid(&why)) throw Error("synthesis options: " + why);
  if (s.poses.empty()) throw Error("SynthesizeSequence: the prepared subject has no poses");
  const int frames = static_cast<int>(s.poses.size());
  if (s.other_poses.size() != s.others.size()) {
    throw Error("SynthesizeSequence: the prepared subject has " + Str(s.others.size()) +
                " other people but " + Str(s.other_poses.size()) + " pose lists");
  }
  for (size_t k = 0; k < s.other_poses.size(); ++k) {
    if (static_cast<int>(s.other_poses[k].size()) != frames) {
      throw Error("SynthesizeSequence: person " + Str(k) + ": expected " + Str(frames) +
                  " poses (one per frame), found " + Str(s.other_poses[k].size()));
    }
  }
  const VirtualKinectOptions kinect_options = ResolveKinectOptions(options);
  const VirtualKinect kinect(kinect_options, s.subject, s.texture_bgr, s.others);
  const Skinning skinning(s.subject);
  std::vector<Skinning> other_skinning;
  for (const ScenePerson& person : s.others) other_skinning.emplace_back(person.body);
  const std::vector<ColorConditions> conditions =
      GenerateColorConditions(kinect_options.color_model, kinect_options.seed, frames);
  // Output frame: the scene's, or the depth camera's (out = T scene).
  Eigen::Isometry3d out_from_scene = Eigen::Isometry3d::Identity();
  if (options.world_frame == WorldFrame::kDepthCamera) {
    out_from_scene = kinect.calibration().depth.world_to_camera;
  }
  Calibration out_calibration = kinect.calibration();
  out_calibration.depth.world_to_camera =
      kinect.calibration().depth.world_to_camera * out_from_scene.inverse();
  out_calibration.color.world_to_camera =
      kinect.calibration().color.world_to_camera * out_from_scene.inverse();
  if (options.world_frame == WorldFrame::kDepthCamera) {
    out_calibration.depth.world_to_camera = Eigen::Isometry3d::Identity();  // exactly
  }
  SequenceWriter writer(out_folder, out_calibration);
  summary.setup_seconds = seconds(start, Clock::now());
  report(SynthProgress::Stage::kSetup, 1, 1);

  for (int b = 0; b < options.background_frames; ++b) {
    const Clock::time_point t0 = Clock::now();
    const cv::Mat depth = kinect.RenderBackgroundDepth(b);
    const Clock::time_point t1 = Clock::now();
    writer.AddBackgroundFrame(depth);
    summary.render_seconds += seconds(t0, t1);
    summary.write_seconds += seconds(t1, Clock::now());
    report(SynthProgress::Stage::kBackground, b + 1, options.background_frames);
  }
  summary.background_frames = options.background_frames;

  // Rendering frame f + 1 overlaps writing frame f (two serial, in-order stages: the files
  // are the same as a sequential loop's).
  struct Item {
    int index = 0;
    Frame frame;
    GroundTruthFrame truth;
  };
  const Clock::time_point frames_start = Clock::now();
  int next = 0;
  // libtbb's own ordering of the stages, the tokens and the end, stated for ThreadSanitizer.
  const char render_stage = 0, write_stage = 0;
  tbb::parallel_pipeline(
      /*max_number_of_live_tokens=*/2,
      tbb::make_filter<void, std::shared_ptr<Item>>(
          tbb::filter_mode::serial_in_order,
          [&](tbb::flow_control& control) -> std::shared_ptr<Item> {
            const TsanSerialStage stage(&render_stage);
            if (next >= frames) {
              control.stop();
              return nullptr;
            }
            const Clock::time_point t0 = Clock::now();
            auto item = std::make_shared<Item>();
            item->index = next++;
            Eigen::MatrixX3d posed;
            skinning.Apply(s.poses[item->index], &posed);
            std::vector<Eigen::MatrixX3d> others(s.others.size());
            for (size_t k = 0; k < others.size(); ++k) {
              other_skinning[k].Apply(s.other_poses[k][item->index], &others[k]);
            }
            kinect.RenderFrame(item->index, &posed, others, conditions[item->index], &item->frame);
            if (options.world_frame == WorldFrame::kScene) {
              item->truth.pose = s.poses[item->index];
              item->truth.vertices = std::move(posed);
            } else {
              item->truth.pose = TransformedPose(s.poses[item->index], out_from_scene);
              item->truth.vertices = (posed * out_from_scene.linear().transpose()).rowwise() +
                                     out_from_scene.translation().transpose();
            }
            summary.render_seconds += seconds(t0, Clock::now());
            TsanRelease(item.get());
            return item;
          }) &
          tbb::make_filter<std::shared_ptr<Item>, void>(
              tbb::filter_mode::serial_in_order, [&](const std::shared_ptr<Item>& item) {
                const TsanSerialStage stage(&write_stage);
                TsanAcquire(item.get());
                const Clock::time_point t0 = Clock::now();
                writer.AddFrame(item->frame);
                writer.AddGroundTruth(item->index, item->truth);
                summary.write_seconds += seconds(t0, Clock::now());
                report(SynthProgress::Stage::kFrames, item->index + 1, frames);
              }));
  TsanAcquire(&render_stage);
  TsanAcquire(&write_stage);
  summary.frames_seconds = seconds(frames_start, Clock::now());
  summary.frames = frames;

  report(SynthProgress::Stage::kFinish, 0, 1);
  const Clock::time_point t0 = Clock::now();
  writer.SetGroundTruthTexture(s.texture_bgr);
  if (options.write_subject_glb) {
    GlbTexture texture;
    texture.width = s.texture_bgr.cols;
    texture.height = s.texture_bgr.rows;
    texture.rgb.resize(static_cast<size_t>(texture.width) * texture.height * 3);
    for (int y = 0; y < texture.height; ++y) {
      const auto* row = s.texture_bgr.ptr<cv::Vec3b>(y);
      for (int x = 0; x < texture.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          texture.rgb[(static_cast<size_t>(y) * texture.width + x) * 3 + c] = row[x][2 - c];
        }
      }
    }
    WriteTemplateGlb(writer.subject_path(), s.subject, &texture);
  }
  writer.Finish();
  summary.write_seconds += seconds(t0, Clock::now());
  summary.total_seconds = seconds(start, Clock::now());
  report(SynthProgress::Stage::kFinish, 1, 1);
  return summary;
}

}  // namespace artex
