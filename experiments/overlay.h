// Fitted template over input frames (`artex overlay`, paper Fig. 3): the posed template is
// rasterised through the depth or colour camera of the calibration (pinhole; lens distortion
// ignored), shaded (Lambert, headlight) and blended over the colour image or the colour-mapped
// depth, its silhouette outlined; frames are tiled into a contact sheet.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/template.h"
#include "sensors/calibration.h"
#include "sensors/sequence.h"

namespace artex {

enum class OverlayBackground { kColor, kDepth };

struct OverlayOptions {
  // kColor: the colour image through calibration.color; kDepth: the colour-mapped depth
  // through calibration.depth.
  OverlayBackground background = OverlayBackground::kColor;
  double mesh_opacity = 0.45;  // blend weight of the shaded template, [0, 1]
  double ambient = 0.25;       // grey = ambient + (1 - ambient) max(0, -n_z (camera)), [0, 1]
  bool wireframe = false;      // also draw the visible triangle edges
  int outline_thickness = 1;   // silhouette outline (pixels, white); 0: none

  bool IsValid(std::string* error) const;
};

struct OverlayImage {
  cv::Mat image;  // CV_8UC3 BGR, the camera's size
  cv::Mat mask;   // CV_8UC1, 255 where the template is visible
};

// CV_16UC1 depth -> CV_8UC3 TURBO colour map over the frame's valid range (near = red),
// missing pixels black.
cv::Mat ColorizeDepth(const cv::Mat& depth);

// posed: V x 3 template vertices in the calibration's world frame (m). Throws artex::Error when
// the frame lacks the chosen image or its size differs from the camera's.
OverlayImage RenderOverlay(const Frame& frame, const Calibration& calibration, const Template& tmpl,
                           const Eigen::MatrixX3d& posed, const OverlayOptions& options);

// Tiles images (each scaled to tile_width, aspect kept) row by row, `columns` per row, with
// the label written in the top-left corner of each tile; black where a row is incomplete.
cv::Mat ContactSheet(const std::vector<cv::Mat>& images, const std::vector<std::string>& labels,
                     int columns, int tile_width);

}  // namespace artex
