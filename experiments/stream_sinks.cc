#include "experiments/stream_sinks.h"

#include <chrono>
#include <cstdio>
#include <filesystem>

#include "experiments/pipeline_stages.h"  // WritePngFile
#include "models/error.h"
#include "models/mesh_export.h"
#include "sensors/image_io.h"

namespace artex {
namespace {

std::string AtlasName(const std::string& dir, int frame, const char* suffix) {
  char name[64];
  std::snprintf(name, sizeof(name), "/%06d%s.png", frame, suffix);
  return dir + name;
}

StreamTap* g_stream_tap = nullptr;

}  // namespace

void SetStreamTap(StreamTap* tap) { g_stream_tap = tap; }

FrameSinks::FrameSinks(const PipelineOptions& options, const Template& tmpl,
                       const Calibration& calibration, const Texturer* texturer,
                       const std::string& out_dir)
    : texturer_(texturer) {
  if (options.export_atlases && texturer) {
    atlas_dir_ = out_dir + "/atlases";
    std::error_code ec;
    std::filesystem::create_directories(atlas_dir_, ec);
    if (ec) throw Error(atlas_dir_ + ": cannot create the folder: " + ec.message());
  }
  if (!options.stream_path.empty()) {
    sender_ = std::make_unique<StreamSender>(options.stream_path, tmpl, calibration.color,
                                             calibration.frame_rate, options.texturing.atlas_size,
                                             texturer != nullptr, options.stream);
    tap_ = g_stream_tap;
    if (tap_) tap_->OnHeader(sender_->header_bytes());
  }
}

FrameSinks::~FrameSinks() = default;

void FrameSinks::AddFrame(int frame, const Pose& pose, const Template* rest_shape) {
  if (atlas_dir_.empty() && !sender_) return;
  if (sender_ && rest_shape) sender_->SetRestShape(*rest_shape);
  const auto wall_ms = [] {
    return std::chrono::duration<double, std::milli>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  };
  const double stamp_ms = wall_ms();
  cv::Mat atlas;
  if (texturer_) atlas = texturer_->Atlas();
  const double atlas_ms = wall_ms();  // the atlas picture composed
  if (!atlas_dir_.empty()) {
    WritePngFile(AtlasName(atlas_dir_, frame, ""), atlas);
    const std::vector<int>& frames = texturer_->triangle_frames();
    cv::Mat row(1, static_cast<int>(frames.size()), CV_8UC1);
    for (std::size_t f = 0; f < frames.size(); ++f)
      row.at<uint8_t>(0, static_cast<int>(f)) = frames[f] >= 0 ? 255 : 0;
    WritePngFile(AtlasName(atlas_dir_, frame, "_textured"), row);
  }
  if (sender_) {
    const StreamFrameStats s =
        sender_->AddFrame(frame, pose, atlas, texturer_ ? &texturer_->triangle_frames() : nullptr,
                          atlas_ms - stamp_ms);
    if (tap_) tap_->OnRecord(sender_->last_record(), s.keyframe, stamp_ms, atlas_ms);
  }
}

void FrameSinks::Finish(PipelineResult* result) {
  if (!sender_) return;
  result->stream = sender_->Finish();
  result->has_stream = true;
}

bool ReadExportedAtlas(const std::string& run_dir, int frame, cv::Mat* atlas,
                       std::vector<int>* triangle_frames) {
  const std::string dir = run_dir + "/atlases";
  const std::string path = AtlasName(dir, frame, "");
  if (!std::filesystem::exists(path)) return false;
  *atlas = ReadImageFile(path, ImageRead::kColor);
  const std::string mask_path = AtlasName(dir, frame, "_textured");
  const cv::Mat row = ReadImageFile(mask_path, ImageRead::kGrayscale);
  if (row.rows != 1) throw Error(mask_path + ": expected a one-row textured mask");
  triangle_frames->resize(row.cols);
  for (int f = 0; f < row.cols; ++f) (*triangle_frames)[f] = row.at<uint8_t>(0, f) ? 0 : -1;
  return true;
}

}  // namespace artex
