#include "sensors/silhouette.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "models/error.h"
#include "sensors/image_io.h"

namespace artex {

const std::map<std::string, ZeroDepthMeaning>& ZeroDepthMeaningNames() {
  static const std::map<std::string, ZeroDepthMeaning> names = {
      {"auto", ZeroDepthMeaning::kAuto},
      {"unknown", ZeroDepthMeaning::kUnknown},
      {"free", ZeroDepthMeaning::kFree}};
  return names;
}

bool SilhouetteOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (raster_width < 8 || raster_width > 4096) {
    msg << "raster_width: expected an integer in [8, 4096] (pixels), found " << raster_width;
  } else if (!(std::isfinite(edge_margin_px) && edge_margin_px >= 0.0 && edge_margin_px <= 1e3)) {
    msg << "edge_margin_px: expected a value in [0, 1000] (pixels), found " << edge_margin_px;
  } else if (!(presegmented_fraction > 0.0 && presegmented_fraction <= 1.0)) {
    msg << "presegmented_fraction: expected a value in (0, 1], found " << presegmented_fraction;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

int SilhouetteMap::RasterIndex(double u, double v) const {
  if (!(std::isfinite(u) && std::isfinite(v))) return -1;
  const double x = std::floor((u + 0.5) / stride), y = std::floor((v + 0.5) / stride);
  if (x < 0 || y < 0 || x >= width || y >= height) return -1;
  // Past the image's last column within the last raster pixel: outside too.
  if (u + 0.5 >= camera.width || v + 0.5 >= camera.height) return -1;
  return static_cast<int>(y) * width + static_cast<int>(x);
}

std::shared_ptr<const SilhouetteMap> BuildSilhouetteMap(const cv::Mat& depth, double depth_scale,
                                                        const cv::Mat& foreground,
                                                        const PinholeCamera& camera,
                                                        const SilhouetteOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("silhouette options: " + error);
  if (depth.type() != CV_16UC1 || depth.cols != camera.width || depth.rows != camera.height) {
    throw Error("silhouette map: expected a CV_16UC1 " + std::to_string(camera.width) + "x" +
                std::to_string(camera.height) + " depth image, found " +
                MatTypeName(depth.type()) + " " + std::to_string(depth.cols) + "x" +
                std::to_string(depth.rows));
  }
  if (foreground.type() != CV_8UC1 || foreground.size() != depth.size()) {
    throw Error("silhouette map: expected a CV_8UC1 foreground mask of the depth image's size, "
                "found " + MatTypeName(foreground.type()) + " " +
                std::to_string(foreground.cols) + "x" + std::to_string(foreground.rows));
  }
  if (!(depth_scale > 0.0 && std::isfinite(depth_scale))) {
    throw Error("silhouette map: depth_scale must be finite and > 0");
  }
  auto map = std::make_shared<SilhouetteMap>();
  map->camera = camera;
  const int w = camera.width, h = camera.height;
  const int s = std::max(1, static_cast<int>(std::lround(static_cast<double>(w) /
                                                         options.raster_width)));
  map->stride = s;
  map->width = (w + s - 1) / s;
  map->height = (h + s - 1) / s;
  const int rw = map->width, rh = map->height;

  // Per raster pixel: foreground seen, nearest valid depth.
  std::vector<uint8_t> fg(static_cast<size_t>(rw) * rh, 0);
  std::vector<uint16_t> nearest(static_cast<size_t>(rw) * rh, 0);
  std::vector<uint16_t> nearest_subject(static_cast<size_t>(rw) * rh, 0);
  long long valid_pixels = 0, foreground_valid = 0;
  for (int y = 0; y < h; ++y) {
    const uint16_t* d = depth.ptr<uint16_t>(y);
    const uint8_t* m = foreground.ptr<uint8_t>(y);
    const int row = (y / s) * rw;
    for (int x = 0; x < w; ++x) {
      const int i = row + x / s;
      if (m[x]) {
        fg[i] = 1;
        if (d[x]) {
          ++foreground_valid;
          if (nearest_subject[i] == 0 || d[x] < nearest_subject[i]) nearest_subject[i] = d[x];
        }
      }
      if (d[x]) {
        ++valid_pixels;
        if (nearest[i] == 0 || d[x] < nearest[i]) nearest[i] = d[x];
      }
    }
  }
  switch (options.zero_depth) {
    case ZeroDepthMeaning::kFree: map->zero_depth_free = true; break;
    case ZeroDepthMeaning::kUnknown: map->zero_depth_free = false; break;
    case ZeroDepthMeaning::kAuto:
      map->zero_depth_free =
          valid_pixels > 0 && static_cast<double>(foreground_valid) >=
                                  options.presegmented_fraction * static_cast<double>(valid_pixels);
      break;
  }

  // 255 = free, 0 = allowed (the distance transform's features). Outside the image anything
  // may be (no violation there), but it is no target: a limb pulled towards the nearest image
  // border would leave through the top as readily as through the bottom.
  cv::Mat free(rh, rw, CV_8UC1, cv::Scalar(0));
  map->free_depth.assign(static_cast<size_t>(rw) * rh, 0.0f);
  map->subject_depth.resize(static_cast<size_t>(rw) * rh);
  for (size_t i = 0; i < nearest_subject.size(); ++i) {
    map->subject_depth[i] = static_cast<float>(nearest_subject[i] / depth_scale);
  }
  const float inf = std::numeric_limits<float>::infinity();
  int allowed = 0;
  for (int y = 0; y < rh; ++y) {
    for (int x = 0; x < rw; ++x) {
      const int i = y * rw + x;
      if (!fg[i]) {
        if (nearest[i] != 0) {
          map->free_depth[i] = static_cast<float>(nearest[i] / depth_scale);
        } else if (map->zero_depth_free) {
          map->free_depth[i] = inf;
        }
      }
      if (map->free_depth[i] != 0.0f) {
        free.at<uint8_t>(y, x) = 255;
      } else {
        ++allowed;
      }
    }
  }
  map->nearest_allowed.assign(static_cast<size_t>(rw) * rh, Eigen::Vector2f::Zero());
  if (allowed == 0) {  // nothing to pull towards: no free space either
    std::fill(map->free_depth.begin(), map->free_depth.end(), 0.0f);
    return map;
  }
  cv::Mat distance, labels;
  cv::distanceTransform(free, distance, labels, cv::DIST_L2, cv::DIST_MASK_5,
                        cv::DIST_LABEL_PIXEL);
  // Labels of the allowed pixels -> their raster position.
  std::vector<Eigen::Vector2f> label_position;
  for (int y = 0; y < rh; ++y) {
    for (int x = 0; x < rw; ++x) {
      if (free.at<uint8_t>(y, x)) continue;
      const int label = labels.at<int>(y, x);
      if (label >= static_cast<int>(label_position.size())) label_position.resize(label + 1);
      label_position[label] = Eigen::Vector2f(static_cast<float>(x), static_cast<float>(y));
    }
  }
  const double margin = options.edge_margin_px / s;
  for (int y = 0; y < rh; ++y) {
    for (int x = 0; x < rw; ++x) {
      const int i = y * rw + x;
      const Eigen::Vector2f p = label_position[labels.at<int>(y, x)];
      // Raster -> full-resolution pixel centre.
      map->nearest_allowed[i] = Eigen::Vector2f((p.x() + 0.5f) * s - 0.5f, (p.y() + 0.5f) * s - 0.5f);
      if (map->free_depth[i] == 0.0f) continue;
      if (distance.at<float>(y, x) <= margin) {
        map->free_depth[i] = 0.0f;  // within the edge margin: allowed
      } else {
        ++map->free_pixels;
      }
    }
  }
  return map;
}

}  // namespace artex
