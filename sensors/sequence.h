// The artex sequence format (docs/formats.md): a folder with calibration.yaml, frames.csv
// (index, timestamps, file names), depth/ (16-bit PNG), color/ (PNG or JPEG), optional
// background/ (empty-scene 16-bit depth PNGs) and optional groundtruth/ (poses.csv with one
// pose vector per frame, vertices/NNNNNN.bin posed vertices, texture.png the true atlas,
// subject.glb the true subject). Frames are streamed: a reader holds one frame at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "models/pose.h"
#include "sensors/calibration.h"

namespace artex {

struct Frame {
  int index = 0;
  double depth_timestamp = 0.0;  // s
  double color_timestamp = 0.0;  // s
  cv::Mat depth;                 // CV_16UC1, depth units (see Calibration::depth_scale); 0 = missing
  cv::Mat color;                 // CV_8UC3, BGR (OpenCV order)
};

struct GroundTruthFrame {
  Pose pose;                   // the subject's pose parameters
  Eigen::MatrixX3d vertices;   // V x 3 posed subject vertices (m, world)
};

// Abstract stream of RGB-D frames (artex format, TUM RGB-D ...).
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  virtual const Calibration& calibration() const = 0;
  virtual int num_frames() const = 0;
  // Reads frame i (0-based). Returns false and fills *warning when the frame is unusable
  // (missing or unreadable file, wrong bit depth or size): callers skip it and count it.
  virtual bool ReadFrame(int i, Frame* frame, std::string* warning) = 0;
  // Empty-scene depth frames for the background model (may be empty).
  virtual std::vector<cv::Mat> ReadBackgroundFrames() = 0;
  // Unit "up" direction (against gravity) in the depth camera frame when the recording holds
  // one (e.g. an accelerometer); none by default.
  virtual std::optional<Eigen::Vector3d> gravity() const { return std::nullopt; }
  // One line for users: what kind of input this is and what was inferred from it.
  virtual std::string Description() const { return ""; }
};

class SequenceReader : public FrameSource {
 public:
  // Throws artex::Error for a missing folder, calibration.yaml or frames.csv, a malformed
  // row, or timestamps out of order (file, line, expected, found).
  explicit SequenceReader(const std::string& folder);
  ~SequenceReader() override;

  const Calibration& calibration() const override;
  int num_frames() const override;
  bool ReadFrame(int i, Frame* frame, std::string* warning) override;
  std::vector<cv::Mat> ReadBackgroundFrames() override;
  std::string Description() const override;

  bool has_ground_truth() const;
  // Ground truth of frame i, given the number of joints of the subject's skeleton;
  // throws artex::Error when absent or malformed.
  GroundTruthFrame ReadGroundTruth(int i) const;
  std::string GroundTruthTexturePath() const;  // "" when absent
  std::string GroundTruthSubjectPath() const;  // "" when absent
  const std::string& folder() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Writes a sequence folder frame by frame. Files are written to temporaries and renamed;
// frames.csv and poses.csv are completed by Finish() (an unfinished folder has no frames.csv).
class SequenceWriter {
 public:
  SequenceWriter(const std::string& folder, const Calibration& calibration);
  ~SequenceWriter();
  void AddFrame(const Frame& frame);  // depth CV_16UC1, color CV_8UC3
  void AddBackgroundFrame(const cv::Mat& depth);
  void AddGroundTruth(int frame_index, const GroundTruthFrame& truth);
  void SetGroundTruthTexture(const cv::Mat& texture_bgr);
  std::string subject_path() const;  // where the caller should write groundtruth/subject.glb
  void Finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Writes `contents` to `path` through a temporary file in the same folder and a rename.
void WriteFileAtomic(const std::string& path, const std::string& contents);
// Writes an image atomically as PNG (.png) or JPEG (.jpg, .jpeg; quality kJpegQuality) by its
// extension (sensors/image_codec.h); throws artex::Error naming the file on failure.
constexpr int kJpegQuality = 95;
void WriteImageAtomic(const std::string& path, const cv::Mat& image);

}  // namespace artex
