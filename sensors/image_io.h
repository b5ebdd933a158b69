// Reading RGB-D frame images with the checks every reader shares. Both functions return false
// and fill *warning (naming the file, expected and found) for an unusable image instead of
// throwing, so that sequence readers can skip single bad frames (sensors/sequence.h).
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "sensors/image_codec.h"

namespace artex {

// A 16-bit single-channel depth PNG of exactly width x height pixels -> CV_16UC1.
bool ReadDepthImage(const std::string& path, int width, int height, cv::Mat* depth,
                    std::string* warning);
// A colour image (PNG/JPEG, 8-bit, 3 channels) of exactly width x height -> CV_8UC3 (BGR).
// A single-channel 8-bit image is rejected (a depth or mask image in the wrong place).
bool ReadColorImage(const std::string& path, int width, int height, cv::Mat* color,
                    std::string* warning);

// A PNG or JPEG file's image, read as `mode` asks (sensors/image_codec.h); throws
// artex::Error naming the file and the reason.
cv::Mat ReadImageFile(const std::string& path, ImageRead mode);

// "CV_16UC1"-style name of an OpenCV matrix type, for messages.
std::string MatTypeName(int type);

}  // namespace artex
