// A fast decoder for the two PNG layouts of recorded frames: 8-bit RGB (colour, returned as
// BGR like OpenCV) and 16-bit greyscale (depth). The zlib stream is inflated in one call by
// libdeflate (about twice as fast as zlib's inflate, which took most of the frame reading's
// CPU) and the rows are unfiltered here. Anything else (other colour types and bit depths,
// interlacing, palettes, transparency chunks, a CRC or checksum mismatch, truncated data)
// is declined, and the caller decodes the file with libpng (sensors/image_codec.h). For the
// layouts it takes the result is the image OpenCV's and libpng's decoders give, byte for byte
// (tests/sensors/png_decode_test.cc).
#pragma once

#include <cstddef>
#include <opencv2/core.hpp>

namespace artex {

// Decodes `size` bytes of a PNG file into *image (CV_8UC3 BGR or CV_16UC1) when it is one of
// the two layouts above and intact; false (and *image untouched) otherwise.
bool DecodeFramePng(const unsigned char* data, std::size_t size, cv::Mat* image);

}  // namespace artex
