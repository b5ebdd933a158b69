// RGB-D preprocessing of one frame (paper sec. 2): background subtraction on the depth image,
// back-projection of the foreground to world points, depth mesh with vertex normals, and a
// colour per vertex from the separate colour camera. Output: a Scan (sensors/scan.h), the v_s,
// n(v_s), rgb(v_s) of the fitting energy (eq. 4).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "sensors/background_model.h"
#include "sensors/calibration.h"
#include "sensors/depth_mesh.h"
#include "sensors/scan.h"
#include "sensors/sequence.h"

namespace artex {

struct PreprocessOptions {
  BackgroundModelOptions background;
  DepthMeshOptions mesh;
  bool IsValid(std::string* error) const;
};

struct PreprocessStats {
  int valid_depth_pixels = 0;  // depth != 0
  int foreground_pixels = 0;   // after morphology / component selection
  DepthMeshStats mesh;
  int color_invalid = 0;  // vertices projecting outside the colour image
  double background_seconds = 0, mesh_seconds = 0, color_seconds = 0, total_seconds = 0;
};

// Projects scan->points (world) into the colour camera (through its world pose, i.e. the
// depth -> colour extrinsic, and its distortion) and samples `color_bgr` (CV_8UC3) bilinearly:
// scan->colors = RGB / 255 in [0, 1] (no gamma conversion), color_valid = 1 where the sample
// lies inside the image (all four bilinear taps) and in front of the camera, else 0 with colour 0.
// Returns the number of invalid vertices. Throws artex::Error for a wrong image type or size.
int SampleScanColors(const PinholeCamera& color_camera, const Distortion& distortion,
                     const cv::Mat& color_bgr, Scan* scan);

class Preprocessor {
 public:
  // Throws artex::Error for invalid options or calibration.
  Preprocessor(const Calibration& calibration,
               const PreprocessOptions& options = PreprocessOptions());

  // Trains the background model on empty-scene depth frames (CV_16UC1, depth camera size).
  void Train(const std::vector<cv::Mat>& background_depth);
  // No background frames: every valid depth within [min_depth, max_depth] is foreground.
  void TrainWithoutBackground();
  bool trained() const { return background_.trained(); }

  // Fills *scan (world frame) from one frame; buffers are reused across calls. Throws
  // artex::Error when untrained or for wrong image types/sizes.
  void Process(const Frame& frame, Scan* scan, PreprocessStats* stats = nullptr);

  const cv::Mat& foreground_mask() const { return mask_; }  // CV_8UC1 of the last Process
  const BackgroundModel& background_model() const { return background_; }
  const DepthMesher& mesher() const { return mesher_; }
  const Calibration& calibration() const { return calibration_; }

 private:
  Calibration calibration_;
  PreprocessOptions options_;
  BackgroundModel background_;
  DepthMesher mesher_;
  cv::Mat mask_;
};

}  // namespace artex
