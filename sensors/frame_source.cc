#include "sensors/frame_source.h"

#include <cctype>
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
    case FrameSourceKind::kMatroska:
      return "Matroska file";
  }
  return "?";
}

bool FrameSourceOptions::IsValid(std::string* error) const {
  return tum.IsValid(error) && mkv.IsValid(error);
}

FrameSourceKind DetectFrameSource(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw Error(path +
                ": expected a recording (artex sequence or TUM RGB-D folder, .mkv file), found "
                "nothing");
  }
  if (!fs::is_directory(path, ec)) {
    std::string ext = fs::path(path).extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".mkv") return FrameSourceKind::kMatroska;
    throw Error(path +
                ": expected a recording (artex sequence or TUM RGB-D folder, .mkv file), found a "
                "file with extension '" +
                ext + "'");
  }
  const auto has = [&](const char* name) { return fs::exists(fs::path(path) / name, ec); };
  if (has("calibration.yaml") || has("frames.csv")) return FrameSourceKind::kArtexSequence;
  if (has("rgb.txt") || has("depth.txt")) return FrameSourceKind::kTumRgbd;
  throw Error(path +
              ": not a recording folder: expected an artex sequence (calibration.yaml and "
              "frames.csv) or a TUM RGB-D folder (rgb.txt and depth.txt), found none of these "
              "files (a Matroska recording is a .mkv file)");
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
    case FrameSourceKind::kMatroska:
      return std::make_unique<MkvReader>(path, options.mkv);
  }
  throw Error(path + ": unknown recording kind");
}

}  // namespace artex
