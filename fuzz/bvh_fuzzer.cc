// ParseBvh (sensors/bvh.h) on arbitrary text; a parsed clip is resampled and retargeted onto
// the default template (the whole path `artex synth --bvh` takes).
#include <sstream>

#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "models/template_generator.h"
#include "sensors/bvh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const artex::Template tmpl = [] {
    artex::BodyShapeOptions shape;
    shape.resolution = 0;
    return artex::GenerateTemplate(shape);
  }();
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const artex::BvhClip clip = artex::ParseBvh(in, "fuzz.bvh");
    if (clip.num_frames() <= 200) artex::RetargetBvh(clip, tmpl, artex::BvhRetargetOptions());
  } catch (const artex::Error&) {
  }
  return 0;
}
