// ReadDepthImage and ReadColorImage (sensors/image_io.h) on arbitrary bytes as a file, and
// DecodeImage (sensors/image_codec.h: libpng, libjpeg-turbo) in its three modes on the same
// bytes in memory; sizes as in the seed images.
#include <opencv2/core.hpp>

#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "sensors/image_codec.h"
#include "sensors/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const std::string png = artex::fuzz::WriteFile("image.png", bytes);
  cv::Mat image;
  std::string warning;
  try {
    artex::ReadDepthImage(png, 8, 6, &image, &warning);
    artex::ReadColorImage(png, 8, 6, &image, &warning);
  } catch (const artex::Error&) {
  }
  for (const artex::ImageRead mode : {artex::ImageRead::kUnchanged, artex::ImageRead::kColor,
                                      artex::ImageRead::kGrayscale}) {
    artex::DecodeImage(data, size, mode, &image, &warning);
  }
  return 0;
}
