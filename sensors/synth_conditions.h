// Named recording conditions for the virtual Kinect (docs/synthesis.md "Conditions"): presets
// that change SynthOptions the way real Kinect recordings differ from the default synthetic
// world (no background frames, camera frame as world frame, clutter, a second person,
// subject orientation, framing, camera roll or height).
#pragma once

#include <string>
#include <vector>

#include "sensors/virtual_kinect.h"

namespace artex {

enum class SynthCondition {
  kDefault,     // "default": nothing changed
  kRoom,        // "room": a real room recording: background_frames 0, world_frame camera,
                //   3 random boxes, a second person walking across 1.2 m behind the subject,
                //   back wall at z = -3 m and 4 m high (room for the walker)
  kFacingAway,  // "facing_away": subject_yaw_deg 180 (its front faces away from the camera)
  kSideways,    // "sideways": subject_yaw_deg 90 (its front faces +X; the default camera sees
                //   its right side)
  kUpperBody,   // "upper_body": camera_placement = UpperBodyCameraPlacement(stature): the
                //   image borders cut the body above the hips
  kRolled,      // "rolled": kinect.depth_roll_deg 20 (camera turned clockwise about its view)
  kHighCamera,  // "high_camera": camera_placement at 2.2 m, 2.3 m away, looking at 0.9 m
                //   (about 29 degrees down: the floor fills the lower image)
};

// Throws artex::Error listing the valid names for an unknown one.
SynthCondition ParseSynthCondition(const std::string& name);
const char* SynthConditionName(SynthCondition condition);
std::vector<std::string> SynthConditionNames();

// Applies `condition` to *options. Call it after setting the subject's shape, texture
// (size, seed) and kinect.seed: kRoom derives the second person's resolution, texture size
// and seed (texture.seed + 1) from them, kUpperBody the framing from subject_shape.height.
// Conditions compose (e.g. room then facing_away); later settings override earlier ones.
void ApplySynthCondition(SynthCondition condition, SynthOptions* options);

}  // namespace artex
