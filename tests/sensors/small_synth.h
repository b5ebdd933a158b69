// Small, fast synthesis settings shared by the sensors tests: the coarse generated subject, a
// 256-pixel texture, a 200 x 254 colour image and the built-in walk.
#pragma once

#include "sensors/virtual_kinect.h"

namespace artex {
namespace testing_util {

inline SynthOptions SmallSynthOptions(int frames, int background_frames) {
  SynthOptions o;
  o.subject_shape.resolution = 0;
  o.texture.size = 256;
  o.kinect.color_width = 200;
  o.kinect.color_height = 254;
  o.motion.type = MotionType::kWalk;
  o.motion.frames = frames;
  o.background_frames = background_frames;
  return o;
}

}  // namespace testing_util
}  // namespace artex
