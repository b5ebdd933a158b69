#include "experiments/overlay.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "models/error.h"
#include "models/normals.h"
#include "render/rasterizer.h"

namespace artex {

bool OverlayOptions::IsValid(std::string* error) const {
  std::string msg;
  if (!(mesh_opacity >= 0 && mesh_opacity <= 1)) {
    msg =
        "overlay mesh_opacity: expected a number in [0, 1], found " + std::to_string(mesh_opacity);
  } else if (!(ambient >= 0 && ambient <= 1)) {
    msg = "overlay ambient: expected a number in [0, 1], found " + std::to_string(ambient);
  } else if (outline_thickness < 0) {
    msg = "overlay outline_thickness: expected >= 0, found " + std::to_string(outline_thickness);
  }
  if (msg.empty()) return true;
  if (error) *error = msg;
  return false;
}

cv::Mat ColorizeDepth(const cv::Mat& depth) {
  const cv::Mat valid = depth > 0;
  double lo = 0, hi = 0;
  if (cv::countNonZero(valid) > 0) cv::minMaxLoc(depth, &lo, &hi, nullptr, nullptr, valid);
  cv::Mat gray;
  depth.convertTo(gray, CV_8U, hi > lo ? -255.0 / (hi - lo) : 0.0,
                  hi > lo ? 255.0 * hi / (hi - lo) : 0.0);
  cv::Mat color;
  cv::applyColorMap(gray, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar(0, 0, 0), ~valid);
  return color;
}

OverlayImage RenderOverlay(const Frame& frame, const Calibration& calibration, const Template& tmpl,
                           const Eigen::MatrixX3d& posed, const OverlayOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  const bool color = options.background == OverlayBackground::kColor;
  const PinholeCamera& camera = color ? calibration.color : calibration.depth;
  const cv::Mat& source = color ? frame.color : frame.depth;
  const char* what = color ? "colour" : "depth";
  if (source.empty() || source.cols != camera.width || source.rows != camera.height) {
    throw Error("overlay of frame " + std::to_string(frame.index) + ": expected a " +
                std::to_string(camera.width) + "x" + std::to_string(camera.height) + " " + what +
                " image (calibration), found " +
                (source.empty() ? std::string("none")
                                : std::to_string(source.cols) + "x" + std::to_string(source.rows)));
  }
  if (posed.rows() != tmpl.num_vertices()) {
    throw Error("overlay: expected " + std::to_string(tmpl.num_vertices()) +
                " posed vertices (template), found " + std::to_string(posed.rows()));
  }
  OverlayImage out;
  out.image = color ? frame.color.clone() : ColorizeDepth(frame.depth);
  RasterBuffers buffers;
  Rasterize(posed, tmpl.triangles, camera, RasterOptions(), &buffers);
  Eigen::MatrixX3d normals;
  ComputeVertexNormals(posed, tmpl.triangles, &normals);
  const Eigen::Matrix3d r = camera.world_to_camera.linear();
  out.mask = cv::Mat(camera.height, camera.width, CV_8UC1, cv::Scalar(0));
  cv::Mat shade = out.image.clone();
  std::vector<uint8_t> visible(tmpl.num_triangles(), 0);
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const int i = buffers.index(x, y);
      const int f = buffers.triangle_id[i];
      if (f < 0) continue;
      visible[f] = 1;
      const double b1 = buffers.barycentric[i].x(), b2 = buffers.barycentric[i].y();
      Eigen::Vector3d n = (1 - b1 - b2) * normals.row(tmpl.triangles(f, 0)).transpose() +
                          b1 * normals.row(tmpl.triangles(f, 1)).transpose() +
                          b2 * normals.row(tmpl.triangles(f, 2)).transpose();
      n = r * n.normalized();
      // Headlight: outward normals facing the camera point along -z.
      const double lambert = options.ambient + (1 - options.ambient) * std::max(0.0, -n.z());
      const auto g = static_cast<uint8_t>(std::lround(255 * std::min(1.0, lambert)));
      shade.at<cv::Vec3b>(y, x) = cv::Vec3b(g, g, g);
      out.mask.at<uint8_t>(y, x) = 255;
    }
  }
  cv::Mat blended;
  cv::addWeighted(out.image, 1.0 - options.mesh_opacity, shade, options.mesh_opacity, 0.0, blended);
  blended.copyTo(out.image, out.mask);
  if (options.wireframe) {
    for (int f = 0; f < tmpl.num_triangles(); ++f) {
      if (!visible[f]) continue;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2d a = camera.Project(posed.row(tmpl.triangles(f, k)).transpose());
        const Eigen::Vector2d b =
            camera.Project(posed.row(tmpl.triangles(f, (k + 1) % 3)).transpose());
        cv::line(out.image, cv::Point2d(a.x(), a.y()), cv::Point2d(b.x(), b.y()),
                 cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
      }
    }
  }
  if (options.outline_thickness > 0) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(out.mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    cv::drawContours(out.image, contours, -1, cv::Scalar(255, 255, 255), options.outline_thickness,
                     cv::LINE_AA);
  }
  return out;
}

cv::Mat ContactSheet(const std::vector<cv::Mat>& images, const std::vector<std::string>& labels,
                     int columns, int tile_width) {
  if (images.empty()) throw Error("contact sheet: expected at least one image, found none");
  if (columns <= 0 || tile_width <= 0) {
    throw Error("contact sheet: expected positive columns and tile width, found " +
                std::to_string(columns) + " and " + std::to_string(tile_width));
  }
  const int n = static_cast<int>(images.size());
  columns = std::min(columns, n);
  const int rows = (n + columns - 1) / columns;
  int tile_height = 0;
  std::vector<cv::Mat> tiles;
  for (const cv::Mat& image : images) {
    cv::Mat tile;
    const double s = static_cast<double>(tile_width) / image.cols;
    cv::resize(image, tile,
               cv::Size(tile_width, std::max(1, static_cast<int>(std::lround(image.rows * s)))), 0,
               0, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    tile_height = std::max(tile_height, tile.rows);
    tiles.push_back(tile);
  }
  cv::Mat sheet(rows * tile_height, columns * tile_width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int i = 0; i < n; ++i) {
    cv::Mat roi = sheet(cv::Rect((i % columns) * tile_width, (i / columns) * tile_height,
                                 tiles[i].cols, tiles[i].rows));
    tiles[i].copyTo(roi);
    if (i < static_cast<int>(labels.size()) && !labels[i].empty()) {
      cv::putText(roi, labels[i], cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                  cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
      cv::putText(roi, labels[i], cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                  cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    }
  }
  return sheet;
}

}  // namespace artex
