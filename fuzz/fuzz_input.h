// Helpers of the fuzz targets: the readers take paths, so an input is written to a file in a
// per-process scratch folder; multi-file inputs are split on kPartSeparator.
//
// The scratch folder is on /dev/shm (a RAM file system) when the machine has one: on a disk
// file system such as ext4, rewriting a file with O_TRUNC makes close() start its write-back
// (ext4's auto_da_alloc), and a fuzzer that writes its input to a file then spends most of its
// time waiting for the disk (measured: 5,000 calibration inputs in 19.8 s of wall time for 3.0 s
// of CPU time in /tmp on ext4, 3.8 s in /dev/shm).
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

// The folder, removed at exit (a crash leaves it behind).
class ScratchFolder {
 public:
  ScratchFolder() {
    std::error_code error;
    const std::filesystem::path shm = "/dev/shm";
    const std::filesystem::path base =
        std::filesystem::is_directory(shm, error) && ::access(shm.c_str(), W_OK) == 0
            ? shm
            : std::filesystem::temp_directory_path();
    path_ = (base / ("artex_fuzz_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(path_);
  }
  ~ScratchFolder() {
    std::error_code error;
    std::filesystem::remove_all(path_, error);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

inline std::string Scratch() {
  static const ScratchFolder folder;
  return folder.path();
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
