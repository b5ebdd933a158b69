// The embedded default human template, generated deterministically from body parameters
// (anthropometric ratios of the stature): a smooth, closed, single-component 2-manifold
// of ~10k-15k vertices, 17 joints, skinning constants and a per-body-part UV atlas.
// Rest pose: A-pose (arms ~40 degrees below horizontal), Y up, facing +Z, feet at y = 0.
#pragma once

#include <string>

#include "models/template.h"

namespace artex {

struct BodyShapeOptions {
  double height = 1.75;        // stature (m), sole to top of head; valid range [1.0, 2.3]
  double girth = 1.0;          // multiplies every body circumference; valid range [0.6, 1.6]
  double shoulder_width = 1.0; // multiplies the biacromial breadth; [0.7, 1.3]
  double hip_width = 1.0;      // multiplies the hip breadth; [0.7, 1.3]
  double arm_length = 1.0;     // multiplies upper arm, forearm and hand lengths; [0.8, 1.2]
  double leg_length = 1.0;     // multiplies thigh and shank lengths; [0.8, 1.2]
  double arm_angle_deg = 40.0; // A-pose: arms below horizontal (degrees); [0, 80]
  int resolution = 1;          // 0: coarse (~3k vertices, tests), 1: default (~12.5k)
  int atlas_size = 2048;       // texture atlas side (texels), used for chart padding; >= 256
  double atlas_padding_texels = 4.0;  // gap kept between charts (texels)

  bool IsValid(std::string* error) const;
};

// Throws artex::Error when the options are invalid. The result passes Template::IsValid.
Template GenerateTemplate(const BodyShapeOptions& options = BodyShapeOptions());

// The 17 joint names of generated templates, in index order (root first):
// pelvis, spine, chest, neck, head, l_shoulder, l_elbow, l_wrist, r_shoulder, r_elbow,
// r_wrist, l_hip, l_knee, l_ankle, r_hip, r_knee, r_ankle.
const char* const* DefaultJointNames();
constexpr int kDefaultNumJoints = 17;

}  // namespace artex
