// Opening recorded input by folder layout: an artex sequence (calibration.yaml + frames.csv,
// sensors/sequence.h), a TUM RGB-D folder (rgb.txt + depth.txt, sensors/tum_reader.h) or a
// Matroska file (.mkv, e.g. Azure Kinect, sensors/mkv_reader.h).
// Every command that reads a recording goes through OpenFrameSource (docs/formats.md).
#pragma once

#include <memory>
#include <string>

#include "sensors/mkv_reader.h"
#include "sensors/sequence.h"
#include "sensors/tum_reader.h"

namespace artex {

enum class FrameSourceKind { kArtexSequence, kTumRgbd, kMatroska };
// "artex sequence", "TUM RGB-D folder", "Matroska file"
std::string FrameSourceKindName(FrameSourceKind kind);

struct FrameSourceOptions {
  TumReaderOptions tum;  // association window, clock offset, intrinsics, accelerometer
  MkvReaderOptions mkv;  // calibration file, association window

  bool IsValid(std::string* error) const;
};

// The layout of `path`: an artex sequence when it holds calibration.yaml or frames.csv (an
// incomplete one then fails in SequenceReader with the missing file), else TUM RGB-D when it
// holds rgb.txt or depth.txt; a regular file ending in .mkv is Matroska. Throws artex::Error
// naming the path and the files looked for when it is none of these, or does not exist.
FrameSourceKind DetectFrameSource(const std::string& path);

// Opens `path` with the reader of its layout. Throws artex::Error as DetectFrameSource and the
// reader's constructor do (invalid options, malformed files).
std::unique_ptr<FrameSource> OpenFrameSource(const std::string& path,
                                             const FrameSourceOptions& options = {});

}  // namespace artex
