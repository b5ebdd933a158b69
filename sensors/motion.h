// Motions for synthesis: smooth, physically plausible joint-angle curves on the default
// 17-joint skeleton (models/template_generator.h), sampled at a frame rate, or imported
// from BVH motion capture and retargeted (sensors/bvh.h).
#pragma once

#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

enum class MotionType { kWalk, kArmRaise, kTurn, kBend, kStill };

struct MotionOptions {
  MotionType type = MotionType::kWalk;
  int frames = 60;             // number of frames; >= 1
  double frame_rate = 30.0;    // Hz
  double amplitude = 1.0;      // scales every joint angle of the motion; [0, 1.5]
  double period_s = 2.0;       // duration of one cycle (s)
};

// Built-in names: "walk", "arm_raise", "turn", "bend", "still". Throws artex::Error listing
// the valid names for an unknown one.
MotionType ParseMotionType(const std::string& name);
const char* MotionTypeName(MotionType type);

// One pose per frame for a template with the default joint names (joints are looked up by
// name; a template lacking one throws artex::Error). Global scale 1, the global translation
// keeps the feet near the floor; frame 0 starts close to the rest pose.
std::vector<Pose> GenerateMotion(const Template& tmpl, const MotionOptions& options);

}  // namespace artex
