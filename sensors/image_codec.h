// PNG and JPEG images in memory, by libpng and libjpeg-turbo directly (docs/install.md,
// "Image files"). These are the only image formats artex reads or writes. OpenCV's imgcodecs
// module, which did this before, loads GDAL and about a hundred other libraries into every
// process that links it (0.15 s of each `artex` command's start on the development machine).
//
// The images are OpenCV matrices laid out as OpenCV's own codecs give and take them: colour
// channels in BGR(A) order, 16-bit PNG samples in the machine's byte order.
#pragma once

#include <cstddef>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace artex {

enum class ImageRead {
  // As stored: 8 or 16 bits (16: PNG only); 1 channel (grey), 3 (BGR) or 4 (BGRA: an alpha
  // channel or PNG transparency, greys expanded to BGR) as OpenCV's IMREAD_UNCHANGED.
  kUnchanged,
  kColor,      // 8-bit BGR (16-bit samples reduced to their high byte, greys expanded)
  kGrayscale,  // 8-bit, one channel (colours converted with weights 0.299, 0.587, 0.114)
};

// Decodes PNG or JPEG bytes (by their signature). False, *image released and *error set
// (the reason; the caller names the file) for any other format, damaged or truncated PNG
// data, a CMYK JPEG, or an image above kMaxImageBytes decoded. A truncated JPEG decodes, its
// missing rows grey, as libjpeg (and OpenCV) give it.
bool DecodeImage(const unsigned char* data, std::size_t size, ImageRead mode, cv::Mat* image,
                 std::string* error);

// PNG of an 8- or 16-bit image with 1, 3 (BGR) or 4 (BGRA) channels, zlib level 1 with run-
// length matching after the Sub filter (OpenCV's default, fast). False and *error otherwise.
bool EncodePng(const cv::Mat& image, std::vector<unsigned char>* bytes, std::string* error);
// Baseline JPEG of an 8-bit grey or BGR image at `quality` (1-100). False and *error otherwise.
bool EncodeJpeg(const cv::Mat& image, int quality, std::vector<unsigned char>* bytes,
                std::string* error);

// The largest decoded image accepted, in bytes (1 GiB): a small damaged or hostile file can
// declare any size, and the decoder allocates the image before it reads the rows.
constexpr std::size_t kMaxImageBytes = std::size_t{1} << 30;

}  // namespace artex
