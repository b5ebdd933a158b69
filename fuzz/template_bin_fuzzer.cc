// ReadTemplateBinary (models/template_cache.h: the default template's cache and the runs'
// templates of `artex experiment`) on arbitrary bytes: every input must give a template or an
// artex::Error; anything else (crash, other exception, sanitizer report, out-of-memory) is a
// finding. Each input is read twice: as it is (the checksum rejects nearly every mutation) and
// with its last 8 bytes replaced by the checksum of the rest, so that the fields behind the
// checksum (counts, sizes, the template's validity) are reached too.
#include <cstring>
#include <string>

#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "models/fnv1a.h"
#include "models/template_cache.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string bytes(reinterpret_cast<const char*>(data), size);
  for (int pass = 0; pass < 2; ++pass) {
    if (pass == 1) {
      if (bytes.size() < 8) break;
      const std::uint64_t h = artex::Fnv1a(bytes.data(), bytes.size() - 8);  // as the writer's
      std::memcpy(&bytes[bytes.size() - 8], &h, 8);
    }
    const std::string path = artex::fuzz::WriteFile("template.bin", bytes);
    try {
      artex::ReadTemplateBinary(path);
    } catch (const artex::Error&) {
    }
  }
  return 0;
}
