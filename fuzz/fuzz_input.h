// Helpers of the fuzz targets: the readers take paths, so an input is written to a file in a
// per-process scratch folder; multi-file inputs are split on kPartSeparator.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace artex::fuzz {

// Separates the files of one input (e.g. rgb.txt, depth.txt and camera.yaml).
constexpr char kPartSeparator[] = "\n#----\n";

inline std::string Scratch() {
  static const std::string dir = [] {
    const auto d =
        std::filesystem::temp_directory_path() / ("artex_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d.string();
  }();
  return dir;
}

inline std::string WriteFile(const std::string& relative, const std::string& bytes) {
  const std::filesystem::path path = std::filesystem::path(Scratch()) / relative;
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), bytes.size());
  return path.string();
}

inline std::vector<std::string> Parts(const uint8_t* data, size_t size, size_t count) {
  std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<std::string> parts;
  const std::string sep = kPartSeparator;
  size_t at = 0;
  while (parts.size() + 1 < count) {
    const size_t next = text.find(sep, at);
    if (next == std::string::npos) break;
    parts.push_back(text.substr(at, next - at));
    at = next + sep.size();
  }
  parts.push_back(text.substr(at));
  parts.resize(count);
  return parts;
}

}  // namespace artex::fuzz
