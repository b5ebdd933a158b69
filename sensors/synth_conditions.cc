#include "sensors/synth_conditions.h"

#include <array>

#include "models/error.h"

namespace artex {
namespace {

struct ConditionName {
  SynthCondition condition;
  const char* name;
};
constexpr std::array<ConditionName, 7> kConditionNames = {{
    {SynthCondition::kDefault, "default"},
    {SynthCondition::kRoom, "room"},
    {SynthCondition::kFacingAway, "facing_away"},
    {SynthCondition::kSideways, "sideways"},
    {SynthCondition::kUpperBody, "upper_body"},
    {SynthCondition::kRolled, "rolled"},
    {SynthCondition::kHighCamera, "high_camera"},
}};

}  // namespace

SynthCondition ParseSynthCondition(const std::string& name) {
  for (const ConditionName& c : kConditionNames) {
    if (name == c.name) return c.condition;
  }
  std::string valid;
  for (const ConditionName& c : kConditionNames)
    valid += (valid.empty() ? "" : ", ") + std::string(c.name);
  throw Error("synthesis condition: expected one of " + valid + "; found '" + name + "'");
}

const char* SynthConditionName(SynthCondition condition) {
  for (const ConditionName& c : kConditionNames) {
    if (condition == c.condition) return c.name;
  }
  return "default";
}

std::vector<std::string> SynthConditionNames() {
  std::vector<std::string> names;
  for (const ConditionName& c : kConditionNames) names.push_back(c.name);
  return names;
}

void ApplySynthCondition(SynthCondition condition, SynthOptions* o) {
  switch (condition) {
    case SynthCondition::kDefault:
      break;
    case SynthCondition::kRoom:
      o->background_frames = 0;
      o->world_frame = WorldFrame::kDepthCamera;
      o->random_boxes = 3;
      o->kinect.scene.wall_z_m = -3.0;
      o->kinect.scene.wall_height_m = 4.0;
      o->second_person.enabled = true;
      o->second_person.shape.resolution = o->subject_shape.resolution;
      o->second_person.texture.size = o->texture.size;
      o->second_person.texture.seed = o->texture.seed + 1;
      break;
    case SynthCondition::kFacingAway:
      o->subject_yaw_deg = 180.0;
      break;
    case SynthCondition::kSideways:
      o->subject_yaw_deg = 90.0;
      break;
    case SynthCondition::kUpperBody:
      o->camera_placement = UpperBodyCameraPlacement(o->subject_shape.height);
      break;
    case SynthCondition::kRolled:
      o->kinect.depth_roll_deg = 20.0;
      break;
    case SynthCondition::kHighCamera: {
      CameraPlacement c;
      c.height_m = 2.2;
      c.distance_m = 2.3;
      c.azimuth_deg = 0.0;
      c.target_height_m = 0.9;
      o->camera_placement = c;
      break;
    }
  }
}

}  // namespace artex
