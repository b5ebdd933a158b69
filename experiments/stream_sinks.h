// Per-frame consumers of the pipeline's poses and texture (experiments/pipeline.h): the
// tele-presence stream (pipeline stream_path, stream/stream_sender.h) and the per-frame atlas
// export (pipeline.export_atlases) that `artex stream encode RUN/` reads back.
#pragma once

#include <memory>
#include <string>

#include "experiments/pipeline.h"
#include "sensors/calibration.h"

namespace artex {

class FrameSinks {
 public:
  // texturer may be null (no texturing); it must outlive the sinks.
  FrameSinks(const PipelineOptions& options, const Template& tmpl, const Calibration& calibration,
             const Texturer* texturer, const std::string& out_dir);
  ~FrameSinks();
  void AddFrame(int frame, const Pose& pose);  // every fitted frame
  void Finish(PipelineResult* result);         // closes the stream, fills result->stream

 private:
  const Texturer* texturer_;
  std::string atlas_dir_;
  std::unique_ptr<StreamSender> sender_;
};

// Reads atlases/NNNNNN.png and atlases/NNNNNN_textured.png of a run (export_atlases); false
// when the atlas is absent. Throws artex::Error for a damaged file.
bool ReadExportedAtlas(const std::string& run_dir, int frame, cv::Mat* atlas,
                       std::vector<int>* triangle_frames);

}  // namespace artex
