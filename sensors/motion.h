// Motions for synthesis: smooth, physically plausible joint-angle curves on the default
// 17-joint skeleton (models/template_generator.h), sampled at a frame rate, or imported
// from BVH motion capture and retargeted (sensors/bvh.h).
#pragma once

#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

enum class MotionType { kWalk, kArmRaise, kTurn, kBend, kStill, kPunchKick };

// How the global translation's y is chosen from the lowest foot point (see LowestFootHeight):
// kKeep leaves it, kPerFrame puts the lowest foot point on y = 0 in every frame,
// kClipMinimum shifts all frames by one offset so the minimum over the clip is at y = 0.
enum class FloorMode { kKeep, kPerFrame, kClipMinimum };

// Shape of each built-in motion (angles in degrees at amplitude 1). Axes come from the
// template: x (left-right) for hips, knees, ankles, spine, chest, neck and head flexion;
// y (up) for yaw; the upper arm and forearm rest directions d for the arms (abduction about
// d x Y, flexion about d x Z, twist about the elbow's twist axis).
struct WalkShape {
  double hip_flexion_deg = 25.0;     // peak hip flexion = peak extension (sinusoid)
  double knee_flexion_deg = 45.0;    // peak knee flexion, reached in mid swing
  double ankle_compensation = 0.35;  // fraction of the shank's pitch undone at the ankle
  double arm_swing_deg = 15.0;       // shoulder flexion/extension, opposite to the hip
  double elbow_flexion_deg = 15.0;   // mean elbow flexion
  double elbow_swing_deg = 8.0;      // elbow flexion oscillation, in phase with the arm swing
  double pelvis_yaw_deg = 5.0;       // pelvis rotation about Y (leg side forward)
  double thorax_counter_yaw = 1.6;   // spine + chest yaw as a multiple of the pelvis yaw,
                                     // opposite sign (> 1: shoulders counter-rotate)
};
struct ArmRaiseShape {
  double abduction_deg = 75.0;  // from the A-pose (about 35 degrees above horizontal)
  double elbow_flexion_deg = 45.0;
  double forearm_twist_deg = 40.0;  // mirror-symmetric left/right
};
struct TurnShape {
  double yaw_deg = 40.0;     // peak global rotation about Y (about the pelvis' vertical line)
  double head_follow = 0.3;  // extra head yaw (neck + head, relative) as a fraction of the yaw
};
struct BendShape {
  double pelvis_tilt_deg = 25.0;  // pelvis forward; the hips flex by the same angle
  double spine_flexion_deg = 20.0;
  double chest_flexion_deg = 15.0;
  double arm_hang = 0.9;             // fraction of the trunk pitch undone at the shoulders
  double arm_adduction_deg = 30.0;   // arms towards the vertical while hanging
  double neck_extension_deg = 10.0;  // head lifted against the trunk's flexion
};

// Fast moves, one after the other, each lasting move_s (the cycle of four is 4 move_s; period_s
// is not used): a right punch, a left punch (shoulder flexion out and back, the elbow bending
// on the way out and back), a right kick (hip flexion, the knee chambering and extending) and
// a squat jump (crouch, flight of jump_height, crouch on landing). Each move starts and ends
// at rest with zero velocity.
struct PunchKickShape {
  double move_s = 1.0;                 // s per move
  double punch_shoulder_deg = 80.0;    // peak shoulder flexion (arm forward)
  double punch_elbow_deg = 90.0;       // peak elbow flexion while chambering
  double kick_hip_deg = 70.0;          // peak hip flexion
  double kick_knee_deg = 80.0;         // peak knee flexion while chambering
  double jump_crouch_knee_deg = 60.0;  // knee flexion of the crouches (hips and ankles follow)
  double jump_height_m = 0.15;         // peak lift of the whole body (m)
};

struct MotionOptions {
  MotionType type = MotionType::kWalk;
  int frames = 60;           // number of frames; >= 1
  double frame_rate = 30.0;  // Hz
  double amplitude = 1.0;    // scales every joint angle of the motion; [0, 1.5]
  double period_s = 2.0;     // duration of one cycle (s); > 0
  // Minimum-jerk fade-in (s) of the periodic motions (walk, turn), so frame 0 is the rest
  // pose and the first frames stay slow; >= 0. Arm raise and bend start at rest by design.
  double ramp_s = 1.0;
  // Vertical placement of the body (see FloorMode); default: feet on the floor every frame.
  FloorMode floor = FloorMode::kPerFrame;
  WalkShape walk;
  ArmRaiseShape arm_raise;
  TurnShape turn;
  BendShape bend;
  PunchKickShape punch_kick;
  // Playback: frame f shows the motion at time f * frame_step * speed / frame_rate (speed 2:
  // twice as fast; frame_step 2: every second frame of the sequence dropped). speed in
  // (0, 8], frame_step >= 1; BVH clips are resampled alike (sensors/synthesis.cc).
  double speed = 1.0;
  int frame_step = 1;

  // False (and a message naming the field, expected range and value) on invalid options.
  bool IsValid(std::string* error) const;
};

// Built-in names: "walk", "arm_raise", "turn", "bend", "still", "punch_kick". Throws artex::Error
// listing the valid names for an unknown one.
MotionType ParseMotionType(const std::string& name);
const char* MotionTypeName(MotionType type);

// One pose per frame for a template with the default joint names (joints are looked up by
// name; a template lacking one throws artex::Error). Global scale 1, the global translation
// keeps the feet near the floor; frame 0 starts close to the rest pose.
// Throws artex::Error for invalid options.
std::vector<Pose> GenerateMotion(const Template& tmpl, const MotionOptions& options);

// Lowest y (m) of the template's foot vertices (vertex_joint = l_ankle or r_ankle, or every
// vertex when the template has no such joints) posed rigidly with their joint's chain,
// s0 R0 T_root o ... o T_k (v) + t0; the LBS/SLERP blend near the ankle is not applied
// (sub-centimetre for sole vertices). A template without vertices uses the ankle centres.
double LowestFootHeight(const Template& tmpl, const Pose& pose);

// Adjusts pose.translation.y() of every pose according to `mode` (no-op for kKeep).
void PlaceOnFloor(const Template& tmpl, FloorMode mode, std::vector<Pose>* poses);

}  // namespace artex
