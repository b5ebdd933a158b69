// ImportMakeHuman (models/makehuman_import.h) on arbitrary files: an input is the OBJ mesh,
// the rig JSON and the weights JSON, separated by kPartSeparator. Imported with joint
// positions from the rig's joint cubes (the default) and from its default positions. Every
// input must give a template or an artex::Error; anything else (crash, other exception,
// sanitizer report, out-of-memory, hang) is a finding.
#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "models/makehuman_import.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::vector<std::string> parts = artex::fuzz::Parts(data, size, 3);
  artex::MakeHumanImportOptions options;
  artex::fuzz::WriteFile("makehuman/" + options.obj_file, parts[0]);
  artex::fuzz::WriteFile("makehuman/" + options.rig_file, parts[1]);
  artex::fuzz::WriteFile("makehuman/" + options.weights_file, parts[2]);
  const std::string folder = artex::fuzz::Scratch() + "/makehuman";
  for (const auto source : {artex::RigPositionSource::kJointCubes,
                            artex::RigPositionSource::kDefaultPositions}) {
    options.joint_positions = source;
    try {
      artex::ImportMakeHuman(folder, options);
    } catch (const artex::Error&) {
    }
  }
  return 0;
}
