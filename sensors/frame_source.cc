#include "sensors/frame_source.h"

#include <filesystem>
#include <system_error>

#include "models/error.h"

namespace artex {
namespace fs = std::filesystem;

std::string FrameSourceKindName(FrameSourceKind kind) {
  switch (kind) {
    case FrameSourceKind::kArtexSequence:
      return "artex sequence";
    case FrameSourceKind::kTumRgbd:
      return "TUM RGB-D folder";
  }
  return "?";
}

bool FrameSourceOptions::IsValid(std::string* error) const { return tum.IsValid(error); }

FrameSourceKind DetectFrameSource(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw Error(path +
                ": expected a recording folder (artex sequence or TUM RGB-D), found nothing");
  }
  if (!fs::is_directory(path, ec)) {
    throw Error(path + ": expected a recording folder (artex sequence or TUM RGB-D), found a file");
  }
  const auto has = [&](const char* name) { return fs::exists(fs::path(path) / name, ec); };
  if (has("calibration.yaml") || has("frames.csv")) return FrameSourceKind::kArtexSequence;
  if (has("rgb.txt") || has("depth.txt")) return FrameSourceKind::kTumRgbd;
  throw Error(path +
              ": not a recording folder: expected an artex sequence (calibration.yaml and "
              "frames.csv) or a TUM RGB-D folder (rgb.txt and depth.txt), found none of these "
              "files");
}

std::unique_ptr<FrameSource> OpenFrameSource(const std::string& path,
                                             const FrameSourceOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  switch (DetectFrameSource(path)) {
    case FrameSourceKind::kArtexSequence:
      return std::make_unique<SequenceReader>(path);
    case FrameSourceKind::kTumRgbd:
      return std::make_unique<TumReader>(path, options.tum);
  }
  throw Error(path + ": unknown recording kind");
}

}  // namespace artex
