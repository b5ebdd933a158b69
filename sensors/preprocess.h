// RGB-D preprocessing of one frame (paper sec. 2): background subtraction on the depth image,
// back-projection of the foreground to world points, depth mesh with vertex normals, and a
// colour per vertex from the separate colour camera. Output: a Scan (sensors/scan.h), the v_s,
// n(v_s), rgb(v_s) of the fitting energy (eq. 4).
#pragma once

#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "sensors/background_model.h"
#include "sensors/calibration.h"
#include "sensors/depth_mesh.h"
#include "sensors/scan.h"
#include "sensors/scene_segmentation.h"
#include "sensors/sequence.h"
#include "sensors/silhouette.h"

namespace artex {

// How the foreground is found. kAuto: the background model when empty-scene frames exist,
// else kSegment. kBackground: the background model (without frames: every valid depth in its
// range). kSegment: floor and walls removed, the subject's 3-D connected component tracked
// (sensors/scene_segmentation.h).
enum class ForegroundMode { kAuto, kBackground, kSegment };
const std::map<std::string, ForegroundMode>& ForegroundModeNames();  // auto, background, segment

struct PreprocessOptions {
  ForegroundMode foreground = ForegroundMode::kAuto;
  // The world frame (used by the pipeline before the Preprocessor is built, see
  // sensors/scene_segmentation.h); planes: segmentation.planes.
  WorldFrameMode world_frame = WorldFrameMode::kAuto;
  double assumed_camera_height = 1.2;  // m, world frame without a floor
  BackgroundModelOptions background;
  SubjectSegmentationOptions segmentation;
  DepthMeshOptions mesh;
  // The frame's free space for the fitting's silhouette term (scan.silhouette).
  SilhouetteOptions silhouette;
  bool IsValid(std::string* error) const;
};

struct PreprocessStats {
  int valid_depth_pixels = 0;      // depth != 0
  int foreground_pixels = 0;       // after morphology / component selection
  SegmentationStats segmentation;  // kSegment only
  DepthMeshStats mesh;
  int color_invalid = 0;  // vertices projecting outside the colour image
  int silhouette_free_pixels = 0;  // raster pixels of the free space (0 without a map)
  double background_seconds = 0, mesh_seconds = 0, color_seconds = 0, silhouette_seconds = 0;
  double total_seconds = 0;
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
  // No background frames: kAuto and kSegment segment the subject (floor and walls are
  // detected on the first processed frame unless SetScenePlanes gave them); kBackground takes
  // every valid depth within [min_depth, max_depth].
  void TrainWithoutBackground();
  bool trained() const { return segmenter_ != nullptr || background_.trained(); }
  bool segmenting() const { return segmenter_ != nullptr; }
  // kSegment: the floor and walls to remove (e.g. those of the world frame estimate).
  void SetScenePlanes(const std::vector<ScenePlane>& planes);
  // kSegment: forget the tracked subject (after a lost frame).
  void ResetSubject();
  const SubjectSegmenter* segmenter() const { return segmenter_.get(); }

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
  std::unique_ptr<SubjectSegmenter> segmenter_;
  cv::Mat mask_;
};

}  // namespace artex
