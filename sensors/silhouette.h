// The free space of one depth frame, for the silhouette term of the fitting
// (energies/silhouette_term.h, docs/fitting.md "Silhouette term"): the template may not show
// where the depth camera saw something else behind it. A pixel is
//   allowed  when it is foreground, outside the image, or of unknown depth (no measurement;
//            see SilhouetteOptions::zero_depth), within edge_margin_px of such a pixel;
//   free     otherwise: the camera saw a non-subject surface at observed_depth, so a template
//            point projecting there in front of that surface (by more than depth_margin, a
//            FittingTerm option) contradicts the frame.
// Computed on a raster of the depth image subsampled to about raster_width pixels across,
// with the nearest allowed pixel of every free pixel (a distance transform), once per frame.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "render/camera.h"

namespace artex {

// What a pixel without a depth measurement means. kUnknown: anything could be there (a
// sensor hole, a dark or shiny surface, a projector shadow beside the subject); kFree: nothing
// (a recording whose background was removed before it reached artex); kAuto: kFree when at
// least presegmented_fraction of the valid depth pixels are foreground, else kUnknown.
enum class ZeroDepthMeaning { kAuto, kUnknown, kFree };
const std::map<std::string, ZeroDepthMeaning>& ZeroDepthMeaningNames();  // auto, unknown, free

struct SilhouetteOptions {
  // Build the map in preprocessing (scan.silhouette). The pipeline's configuration turns it on
  // when fitting.silhouette.weight > 0 and the key is not given.
  bool enabled = false;
  int raster_width = 160; // raster about this many pixels across (stride round(width / this))
  // Full-resolution pixels: free pixels this close to an allowed one are allowed too (mask
  // edges, mixed depth at the silhouette rim).
  double edge_margin_px = 6.0;
  ZeroDepthMeaning zero_depth = ZeroDepthMeaning::kAuto;
  double presegmented_fraction = 0.95;  // kAuto: see ZeroDepthMeaning

  bool IsValid(std::string* error) const;
};

struct SilhouetteMap {
  PinholeCamera camera;  // the depth camera (world_to_camera of the scan's world frame)
  int stride = 1;        // full-resolution pixels per raster pixel
  int width = 0, height = 0;  // raster size
  bool zero_depth_free = false;  // how zero depth was read (kAuto resolved)
  // Raster row-major, width * height entries: the observed depth (m) of a free pixel, +inf for
  // a free pixel without measurement, 0 for an allowed pixel.
  std::vector<float> free_depth;
  // Per raster pixel: the nearest observed depth (m) of the subject, 0 where none (a template
  // point far in front of it is in free space too: the camera would have seen it).
  std::vector<float> subject_depth;
  // Per raster pixel: the nearest allowed pixel inside the image, its centre in full-resolution
  // pixel coordinates (u, v); the pixel's own centre when allowed. Outside the image nothing
  // is free, but neither is it a target (a limb pulled to the nearest border would leave the
  // view through the top as readily as through the bottom).
  std::vector<Eigen::Vector2f> nearest_allowed;
  int free_pixels = 0;

  // The raster pixel of a full-resolution position, -1 when outside the image.
  int RasterIndex(double u, double v) const;
};

// Builds the map from a depth image (CV_16UC1, `depth_scale` units per metre) and its
// foreground mask (CV_8UC1, non-zero = subject), both of the depth camera's size. Throws
// artex::Error for invalid options or wrong image types or sizes.
std::shared_ptr<const SilhouetteMap> BuildSilhouetteMap(const cv::Mat& depth, double depth_scale,
                                                        const cv::Mat& foreground,
                                                        const PinholeCamera& camera,
                                                        const SilhouetteOptions& options);

}  // namespace artex
