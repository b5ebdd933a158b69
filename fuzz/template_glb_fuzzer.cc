// ReadTemplateGlb and ImportGltfSkinnedMesh (models/template_io.h) on arbitrary bytes: every
// input must give a template or an artex::Error; anything else (crash, other exception, sanitizer
// report, out-of-memory) is a finding.
#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "models/template_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = artex::fuzz::WriteFile(
      "template.glb", std::string(reinterpret_cast<const char*>(data), size));
  try {
    artex::GlbTexture texture;
    artex::ReadTemplateGlb(path, &texture);
  } catch (const artex::Error&) {
  }
  try {
    artex::ImportGltfSkinnedMesh(path, artex::GltfImportOptions());
  } catch (const artex::Error&) {
  }
  return 0;
}
