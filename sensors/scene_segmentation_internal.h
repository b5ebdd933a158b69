// Private to sensors/scene_planes.cc and sensors/subject_segmentation.cc (the implementation
// of sensors/scene_segmentation.h): what both check of their input.
#pragma once

#include <opencv2/core.hpp>
#include <sstream>

#include "models/error.h"
#include "render/camera.h"
#include "sensors/image_io.h"

namespace artex {
namespace scene_internal {

// Throws artex::Error "<what>: expected a CV_16UC1 WxH depth image, found ..." unless depth is
// one of the camera's size.
inline void CheckDepth(const cv::Mat& depth, const PinholeCamera& camera, const char* what) {
  if (depth.type() != CV_16UC1 || depth.cols != camera.width || depth.rows != camera.height) {
    std::ostringstream msg;
    msg << what << ": expected a CV_16UC1 " << camera.width << "x" << camera.height
        << " depth image, found " << MatTypeName(depth.type()) << " " << depth.cols << "x"
        << depth.rows;
    throw Error(msg.str());
  }
}

}  // namespace scene_internal
}  // namespace artex
