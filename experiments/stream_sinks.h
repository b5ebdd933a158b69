// Per-frame consumers of the pipeline's poses and texture (experiments/pipeline.h): the
// tele-presence stream (pipeline stream_path, stream/stream_sender.h) and the per-frame atlas
// export (pipeline.export_atlases) that `artex stream encode RUN/` reads back.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "experiments/pipeline.h"
#include "sensors/calibration.h"

namespace artex {

// A live consumer of the stream's bytes (the viewer's server, experiments/stream_server.h):
// the header once, then every record as it is encoded, with the wall-clock times (ms since the
// epoch) at which the pipeline handed the frame to the sinks (its processing time) and at
// which the sink had composed its atlas picture (before encoding).
class StreamTap {
 public:
  virtual ~StreamTap() = default;
  virtual void OnHeader(const std::vector<uint8_t>& header) = 0;
  virtual void OnRecord(const std::vector<uint8_t>& record, bool keyframe, double stamp_ms,
                        double atlas_ms) = 0;
};

// The tap that FrameSinks created from now on feed when they write a stream (nullptr: none);
// set by `artex track --serve` around its pipeline run. Not owned; must outlive the sinks.
void SetStreamTap(StreamTap* tap);

class FrameSinks {
 public:
  // texturer may be null (no texturing); it must outlive the sinks.
  FrameSinks(const PipelineOptions& options, const Template& tmpl, const Calibration& calibration,
             const Texturer* texturer, const std::string& out_dir);
  ~FrameSinks();
  // Every fitted frame; rest_shape: the template changed after the previous frame (shape
  // estimation) and `pose` is of this one (null: unchanged).
  void AddFrame(int frame, const Pose& pose, const Template* rest_shape = nullptr);
  void Finish(PipelineResult* result);         // closes the stream, fills result->stream

 private:
  const Texturer* texturer_;
  std::string atlas_dir_;
  std::unique_ptr<StreamSender> sender_;
  StreamTap* tap_ = nullptr;
};

// Reads atlases/NNNNNN.png and atlases/NNNNNN_textured.png of a run (export_atlases); false
// when the atlas is absent. Throws artex::Error for a damaged file.
bool ReadExportedAtlas(const std::string& run_dir, int frame, cv::Mat* atlas,
                       std::vector<int>* triangle_frames);

}  // namespace artex
