// PNG and JPEG through libpng and libjpeg-turbo (sensors/image_codec.h) against OpenCV's
// imgcodecs, which artex used before: the same images for every layout in every read mode,
// files OpenCV reads back for everything written, and clear errors for damaged data.
#include "sensors/image_codec.h"

#include <gtest/gtest.h>
#include <png.h>
#include <zlib.h>

#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <vector>

namespace artex {
namespace {

cv::Mat Noise(int rows, int cols, int type, unsigned seed) {
  cv::Mat m(rows, cols, type);
  cv::RNG rng(seed);
  rng.fill(m, cv::RNG::UNIFORM, 0, m.depth() == CV_16U ? 65536 : 256);
  // Smooth areas too, so that both codecs meet long runs.
  m(cv::Rect(0, 0, cols / 2, rows / 2)).setTo(cv::Scalar::all(m.depth() == CV_16U ? 4000 : 90));
  return m;
}

std::vector<unsigned char> CvEncode(const std::string& ext, const cv::Mat& m) {
  std::vector<unsigned char> bytes;
  EXPECT_TRUE(cv::imencode(ext, m, bytes));
  return bytes;
}

void ExpectSame(const cv::Mat& a, const cv::Mat& b, const std::string& what) {
  ASSERT_EQ(a.type(), b.type()) << what;
  ASSERT_EQ(a.size(), b.size()) << what;
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << what;
}

// Every read mode against OpenCV's flag for it.
void ExpectAsOpenCv(const std::vector<unsigned char>& bytes, const std::string& what) {
  const std::pair<ImageRead, int> modes[] = {{ImageRead::kUnchanged, cv::IMREAD_UNCHANGED},
                                             {ImageRead::kColor, cv::IMREAD_COLOR},
                                             {ImageRead::kGrayscale, cv::IMREAD_GRAYSCALE}};
  for (const auto& [mode, flag] : modes) {
    cv::Mat ours;
    std::string error;
    ASSERT_TRUE(DecodeImage(bytes.data(), bytes.size(), mode, &ours, &error))
        << what << " flag " << flag << ": " << error;
    ExpectSame(ours, cv::imdecode(bytes, flag), what + " flag " + std::to_string(flag));
  }
}

// A libpng writer appending to *out (the test's files are valid: no error handling).
png_structp PngWriter(std::vector<unsigned char>* out, png_infop* info) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  *info = png_create_info_struct(png);
  png_set_write_fn(
      png, out,
      [](png_structp p, png_bytep data, png_size_t n) {
        auto* v = static_cast<std::vector<unsigned char>*>(png_get_io_ptr(p));
        v->insert(v->end(), data, data + n);
      },
      [](png_structp) {});
  return png;
}

// A PNG written by libpng itself, for the layouts OpenCV never writes: palettes, 1-4 bit
// greys, transparency chunks, interlacing. `samples` holds one byte (or, at 16 bits, two
// big-endian bytes) per sample, packed here for bit depths below 8.
std::vector<unsigned char> LibpngFile(int width, int height, int color_type, int bit_depth,
                                      bool interlaced, bool transparency, unsigned seed) {
  std::vector<unsigned char> out;
  png_infop info = nullptr;
  png_structp png = PngWriter(&out, &info);
  png_set_IHDR(png, info, width, height, bit_depth, color_type,
               interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE,
               PNG_FILTER_TYPE_BASE);
  std::mt19937 rng(seed);
  std::vector<png_color> palette(16);
  if (color_type == PNG_COLOR_TYPE_PALETTE) {
    for (auto& c : palette) {
      c.red = rng() & 255;
      c.green = rng() & 255;
      c.blue = rng() & 255;
    }
    png_set_PLTE(png, info, palette.data(), 16);
  }
  png_byte alphas[16];
  png_color_16 colour_key{};
  if (transparency) {
    for (png_byte& a : alphas) a = rng() & 255;
    colour_key.gray = 1;
    colour_key.red = 10;
    colour_key.green = 20;
    colour_key.blue = 30;
    png_set_tRNS(png, info, alphas, color_type == PNG_COLOR_TYPE_PALETTE ? 16 : 0, &colour_key);
  }
  png_write_info(png, info);
  const int channels = png_get_channels(png, info);
  const int levels = color_type == PNG_COLOR_TYPE_PALETTE ? 16 : (1 << std::min(bit_depth, 8));
  const std::size_t row_bytes = png_get_rowbytes(png, info);
  std::vector<std::vector<png_byte>> rows(height, std::vector<png_byte>(row_bytes, 0));
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width * channels; ++x) {
      const unsigned v = rng() % levels;
      if (bit_depth < 8) {
        const int bit = x * bit_depth;
        rows[y][bit / 8] |= static_cast<png_byte>(v << (8 - bit_depth - bit % 8));
      } else if (bit_depth == 8) {
        rows[y][x] = static_cast<png_byte>(v);
      } else {
        rows[y][2 * x] = static_cast<png_byte>(rng() & 255);
        rows[y][2 * x + 1] = static_cast<png_byte>(v);
      }
    }
  }
  std::vector<png_bytep> pointers;
  for (auto& r : rows) pointers.push_back(r.data());
  png_write_image(png, pointers.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return out;
}

TEST(ImageCodecTest, OpenCvsPngsDecodeAsOpenCvDecodesThem) {
  for (const int type : {CV_8UC1, CV_8UC3, CV_8UC4, CV_16UC1, CV_16UC3, CV_16UC4}) {
    ExpectAsOpenCv(CvEncode(".png", Noise(37, 53, type, type + 1)),
                   "OpenCV PNG type " + std::to_string(type));
  }
}

TEST(ImageCodecTest, OtherPngLayoutsDecodeAsOpenCvDecodesThem) {
  struct Layout {
    int color_type, bit_depth;
    bool interlaced, transparency;
  };
  const Layout layouts[] = {
      {PNG_COLOR_TYPE_PALETTE, 4, false, false}, {PNG_COLOR_TYPE_PALETTE, 8, false, true},
      {PNG_COLOR_TYPE_GRAY, 1, false, false},    {PNG_COLOR_TYPE_GRAY, 2, true, false},
      {PNG_COLOR_TYPE_GRAY, 4, false, false},    {PNG_COLOR_TYPE_GRAY_ALPHA, 8, false, false},
      {PNG_COLOR_TYPE_GRAY_ALPHA, 16, false, false}, {PNG_COLOR_TYPE_RGB, 8, true, false},
      {PNG_COLOR_TYPE_RGB, 16, true, false},     {PNG_COLOR_TYPE_RGB_ALPHA, 8, true, false},
      {PNG_COLOR_TYPE_RGB, 8, false, true},      {PNG_COLOR_TYPE_GRAY, 16, true, false},
  };
  unsigned seed = 1;
  for (const Layout& l : layouts) {
    const std::vector<unsigned char> png =
        LibpngFile(29, 19, l.color_type, l.bit_depth, l.interlaced, l.transparency, seed++);
    ExpectAsOpenCv(png, "colour type " + std::to_string(l.color_type) + " depth " +
                            std::to_string(l.bit_depth) + (l.interlaced ? " interlaced" : "") +
                            (l.transparency ? " tRNS" : ""));
  }
}

TEST(ImageCodecTest, JpegsDecodeAsOpenCvDecodesThem) {
  ExpectAsOpenCv(CvEncode(".jpg", Noise(40, 56, CV_8UC3, 3)), "colour JPEG");
  ExpectAsOpenCv(CvEncode(".jpg", Noise(40, 56, CV_8UC1, 4)), "grey JPEG");
}

TEST(ImageCodecTest, WrittenPngsReadBackExactlyInOpenCv) {
  for (const int type : {CV_8UC1, CV_8UC3, CV_8UC4, CV_16UC1, CV_16UC3, CV_16UC4}) {
    const cv::Mat image = Noise(31, 47, type, type + 11);
    std::vector<unsigned char> bytes;
    std::string error;
    ASSERT_TRUE(EncodePng(image, &bytes, &error)) << error;
    const std::string what = "type " + std::to_string(type);
    ExpectSame(cv::imdecode(bytes, cv::IMREAD_UNCHANGED), image, what + " by OpenCV");
    cv::Mat back;
    ASSERT_TRUE(DecodeImage(bytes.data(), bytes.size(), ImageRead::kUnchanged, &back, &error));
    ExpectSame(back, image, what + " by DecodeImage");
  }
  // A view into a larger matrix (rows not contiguous) is written as the view.
  const cv::Mat big = Noise(40, 60, CV_8UC3, 5);
  const cv::Mat view = big(cv::Rect(7, 3, 30, 20));
  std::vector<unsigned char> bytes;
  std::string error;
  ASSERT_TRUE(EncodePng(view, &bytes, &error)) << error;
  ExpectSame(cv::imdecode(bytes, cv::IMREAD_UNCHANGED), view, "view");
  // What PNG cannot hold is refused with the reason.
  EXPECT_FALSE(EncodePng(cv::Mat(4, 4, CV_32FC1, cv::Scalar(1)), &bytes, &error));
  EXPECT_NE(error.find("8- or 16-bit"), std::string::npos) << error;
  EXPECT_FALSE(EncodePng(cv::Mat(), &bytes, &error));
}

TEST(ImageCodecTest, WrittenJpegsReadBackInOpenCv) {
  for (const int type : {CV_8UC1, CV_8UC3}) {
    cv::Mat image(48, 64, type);
    for (int y = 0; y < image.rows; ++y) {  // smooth: JPEG's own error stays small
      for (int x = 0; x < image.cols * image.channels(); ++x) {
        image.ptr<uint8_t>(y)[x] = static_cast<uint8_t>(2 * y + x);
      }
    }
    std::vector<unsigned char> bytes;
    std::string error;
    ASSERT_TRUE(EncodeJpeg(image, 90, &bytes, &error)) << error;
    const cv::Mat cv_back = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(cv_back.type(), type);
    EXPECT_GT(cv::PSNR(cv_back, image), 30.0) << "type " << type;
    std::vector<unsigned char> cv_bytes;  // OpenCV's encoder, the same library and settings
    ASSERT_TRUE(cv::imencode(".jpg", image, cv_bytes, {cv::IMWRITE_JPEG_QUALITY, 90}));
    EXPECT_EQ(bytes, cv_bytes) << "type " << type;
    ExpectAsOpenCv(bytes, "written JPEG type " + std::to_string(type));
  }
  std::vector<unsigned char> bytes;
  std::string error;
  EXPECT_FALSE(EncodeJpeg(cv::Mat(4, 4, CV_16UC3, cv::Scalar::all(1)), 90, &bytes, &error));
  EXPECT_FALSE(EncodeJpeg(cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(1)), 0, &bytes, &error));
  EXPECT_NE(error.find("quality"), std::string::npos) << error;
}

TEST(ImageCodecTest, DamagedAndForeignBytesGiveReasonsNotCrashes) {
  cv::Mat image;
  std::string error;
  EXPECT_FALSE(DecodeImage(nullptr, 0, ImageRead::kUnchanged, &image, &error));
  EXPECT_EQ(error, "empty file");
  const std::vector<unsigned char> bmp = CvEncode(".bmp", Noise(8, 8, CV_8UC3, 1));
  EXPECT_FALSE(DecodeImage(bmp.data(), bmp.size(), ImageRead::kColor, &image, &error));
  EXPECT_EQ(error, "not a PNG or JPEG image");
  EXPECT_TRUE(image.empty());

  const std::vector<unsigned char> png = CvEncode(".png", Noise(30, 40, CV_8UC3, 2));
  for (std::size_t n = 8; n < png.size(); n += 5) {  // every truncation fails with a reason
    EXPECT_FALSE(DecodeImage(png.data(), n, ImageRead::kUnchanged, &image, &error)) << n;
    EXPECT_EQ(error.rfind("PNG: ", 0), 0u) << error;
    EXPECT_TRUE(image.empty());
  }
  for (std::size_t at = 8; at < png.size(); at += 3) {  // flipped bits: an error or an image
    std::vector<unsigned char> bad = png;
    bad[at] ^= 0x21;
    if (!DecodeImage(bad.data(), bad.size(), ImageRead::kUnchanged, &image, &error)) {
      EXPECT_FALSE(error.empty());
    }
  }
  const std::vector<unsigned char> jpeg = CvEncode(".jpg", Noise(30, 40, CV_8UC3, 3));
  for (std::size_t n = 3; n < jpeg.size(); n += 11) {
    if (!DecodeImage(jpeg.data(), n, ImageRead::kColor, &image, &error)) {
      EXPECT_EQ(error.rfind("JPEG: ", 0), 0u) << error;
    }
  }
}

TEST(ImageCodecTest, ImagesAboveTheLimitAreRefusedBeforeAllocation) {
  // A true 1-bit palette image of 32768 x 16384 pixels (64 KB of deflated zeros) decodes to
  // 1.6 GB of BGR, above kMaxImageBytes.
  std::vector<unsigned char> file;
  png_infop info = nullptr;
  png_structp png = PngWriter(&file, &info);
  png_set_IHDR(png, info, 32768, 16384, 1, PNG_COLOR_TYPE_PALETTE, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_color palette[2] = {{0, 0, 0}, {255, 255, 255}};
  png_set_PLTE(png, info, palette, 2);
  png_write_info(png, info);
  std::vector<png_byte> row(32768 / 8, 0);
  for (int y = 0; y < 16384; ++y) png_write_row(png, row.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  cv::Mat image;
  std::string error;
  EXPECT_FALSE(DecodeImage(file.data(), file.size(), ImageRead::kColor, &image, &error));
  EXPECT_NE(error.find("32768x16384 pixels above 1 GiB"), std::string::npos) << error;
  EXPECT_TRUE(image.empty());
}

TEST(ImageCodecTest, HeaderClaimingMoreThanItsDataIsRefusedBeforeAllocation) {
  // A valid file whose header claims 16000 x 16000 RGB pixels (768 MB): deflate cannot expand
  // its few hundred bytes that far, so the rows are never allocated.
  std::vector<unsigned char> png = LibpngFile(23, 17, PNG_COLOR_TYPE_RGB, 8, false, false, 9);
  for (const std::size_t at : {std::size_t{16}, std::size_t{20}}) {  // IHDR width, height
    for (int k = 0; k < 4; ++k) png[at + k] = static_cast<unsigned char>(16000u >> (24 - 8 * k));
  }
  const unsigned long crc = crc32(0, png.data() + 12, 17);  // chunk type + body
  for (int k = 0; k < 4; ++k) png[29 + k] = static_cast<unsigned char>(crc >> (24 - 8 * k));
  cv::Mat image;
  std::string error;
  EXPECT_FALSE(DecodeImage(png.data(), png.size(), ImageRead::kUnchanged, &image, &error));
  EXPECT_NE(error.find("needs more data than the file holds"), std::string::npos) << error;
  // The same for a JPEG (libjpeg would fill the missing rows with grey): its frame header
  // (SOF0: FF C0, length, precision, height, width) claiming 16000 x 16000.
  std::vector<unsigned char> jpeg = CvEncode(".jpg", Noise(16, 16, CV_8UC3, 4));
  std::size_t sof = 2;
  while (sof + 9 < jpeg.size() && !(jpeg[sof] == 0xff && jpeg[sof + 1] == 0xc0)) ++sof;
  ASSERT_LT(sof + 9, jpeg.size());
  for (const std::size_t at : {sof + 5, sof + 7}) {
    jpeg[at] = static_cast<unsigned char>(16000 >> 8);
    jpeg[at + 1] = static_cast<unsigned char>(16000 & 255);
  }
  EXPECT_FALSE(DecodeImage(jpeg.data(), jpeg.size(), ImageRead::kColor, &image, &error));
  EXPECT_NE(error.find("(16000x16000) needs more data than the file holds"), std::string::npos)
      << error;
  // A real JPEG of a flat image, the most compressible there is, stays well within the bound.
  const std::vector<unsigned char> flat =
      CvEncode(".jpg", cv::Mat(480, 640, CV_8UC3, cv::Scalar(90, 120, 150)));
  ASSERT_TRUE(DecodeImage(flat.data(), flat.size(), ImageRead::kColor, &image, &error)) << error;
  EXPECT_LT(640.0 * 480 * 3 / flat.size(), 1032.0 / 2);
}

}  // namespace
}  // namespace artex
