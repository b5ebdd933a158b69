// The fast frame PNG decoder (sensors/png_decode.h) against OpenCV's decoder: the same image
// byte for byte for the layouts it takes, declined (false) for everything else and for damaged
// files, which ReadColorImage / ReadDepthImage then hand to OpenCV as before.
#include "sensors/png_decode.h"

#include <sys/resource.h>

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <vector>

#include "sensors/image_io.h"

namespace artex {
namespace {

// Smooth gradients with noise and flat patches, so the encoder's adaptive filtering uses every
// filter type.
cv::Mat TestImage(int rows, int cols, int type, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-3, 3);
  cv::Mat m(rows, cols, type);
  const int channels = m.channels();
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      for (int c = 0; c < channels; ++c) {
        const bool flat = (x / 8 + y / 8) % 3 == 0;
        const int v = flat ? 40 * c : (x * (c + 1) + 2 * y + noise(rng) + 50 * c);
        if (m.depth() == CV_16U) {
          m.ptr<uint16_t>(y)[x * channels + c] = static_cast<uint16_t>(v * 97 + (x ^ y));
        } else {
          m.ptr<uint8_t>(y)[x * channels + c] = static_cast<uint8_t>(v);
        }
      }
    }
  }
  return m;
}

std::vector<unsigned char> Encode(const cv::Mat& m, std::vector<int> params = {}) {
  std::vector<unsigned char> bytes;
  EXPECT_TRUE(cv::imencode(".png", m, bytes, params));
  return bytes;
}

void ExpectSame(const cv::Mat& a, const cv::Mat& b) {
  ASSERT_EQ(a.type(), b.type());
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
}

TEST(PngDecodeTest, SameImageAsOpenCvForColourAndDepth) {
  const std::vector<std::vector<int>> params = {
      {},
      {cv::IMWRITE_PNG_COMPRESSION, 0},
      {cv::IMWRITE_PNG_COMPRESSION, 9},
      {cv::IMWRITE_PNG_STRATEGY, cv::IMWRITE_PNG_STRATEGY_FILTERED},
      {cv::IMWRITE_PNG_STRATEGY, cv::IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY},
      {cv::IMWRITE_PNG_STRATEGY, cv::IMWRITE_PNG_STRATEGY_RLE},
      {cv::IMWRITE_PNG_STRATEGY, cv::IMWRITE_PNG_STRATEGY_FIXED}};
  const std::vector<cv::Size> sizes = {{1, 1}, {7, 3}, {64, 48}, {257, 31}};
  unsigned seed = 1;
  for (const int type : {CV_8UC3, CV_16UC1}) {
    for (const cv::Size& size : sizes) {
      for (const auto& p : params) {
        const cv::Mat m = TestImage(size.height, size.width, type, seed++);
        const std::vector<unsigned char> png = Encode(m, p);
        cv::Mat fast;
        ASSERT_TRUE(DecodeFramePng(png.data(), png.size(), &fast)) << size << " type " << type;
        ExpectSame(fast, cv::imdecode(png, cv::IMREAD_UNCHANGED | cv::IMREAD_ANYDEPTH));
        ExpectSame(fast, m);
      }
    }
  }
}

// A PNG written here with the given filter type per row (PNG filters 0-4 applied by hand), so
// that every filter type is decoded whatever OpenCV's encoder would choose.
std::vector<unsigned char> PngWithFilters(const cv::Mat& m, const std::vector<int>& filters) {
  const int bpp = m.depth() == CV_16U ? 2 : 3;
  const std::size_t stride = static_cast<std::size_t>(m.cols) * bpp;
  std::vector<unsigned char> raw, previous(stride, 0), line(stride);
  for (int y = 0; y < m.rows; ++y) {
    for (int x = 0; x < m.cols; ++x) {  // the PNG sample order: RGB, big-endian
      if (bpp == 3) {
        const cv::Vec3b p = m.at<cv::Vec3b>(y, x);
        line[3 * x] = p[2];
        line[3 * x + 1] = p[1];
        line[3 * x + 2] = p[0];
      } else {
        const uint16_t v = m.at<uint16_t>(y, x);
        line[2 * x] = static_cast<unsigned char>(v >> 8);
        line[2 * x + 1] = static_cast<unsigned char>(v & 0xff);
      }
    }
    const int filter = filters[y % filters.size()];
    raw.push_back(static_cast<unsigned char>(filter));
    for (std::size_t i = 0; i < stride; ++i) {
      const int a = i >= static_cast<std::size_t>(bpp) ? line[i - bpp] : 0, b = previous[i],
                c = i >= static_cast<std::size_t>(bpp) ? previous[i - bpp] : 0;
      int predictor = 0;
      if (filter == 1) predictor = a;
      if (filter == 2) predictor = b;
      if (filter == 3) predictor = (a + b) / 2;
      if (filter == 4) {
        const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
        predictor = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
      }
      raw.push_back(static_cast<unsigned char>(line[i] - predictor));
    }
    previous = line;
  }
  uLongf size = compressBound(raw.size());
  std::vector<unsigned char> z(size);
  EXPECT_EQ(compress2(z.data(), &size, raw.data(), raw.size(), 6), Z_OK);
  z.resize(size);
  std::vector<unsigned char> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  const auto chunk = [&](const char* type, const std::vector<unsigned char>& body) {
    const uint32_t n = static_cast<uint32_t>(body.size());
    for (int k = 3; k >= 0; --k) png.push_back(static_cast<unsigned char>(n >> (8 * k)));
    const std::size_t start = png.size();
    png.insert(png.end(), type, type + 4);
    png.insert(png.end(), body.begin(), body.end());
    const uint32_t crc = static_cast<uint32_t>(crc32(0, png.data() + start, n + 4));
    for (int k = 3; k >= 0; --k) png.push_back(static_cast<unsigned char>(crc >> (8 * k)));
  };
  std::vector<unsigned char> header;
  for (const uint32_t v : {static_cast<uint32_t>(m.cols), static_cast<uint32_t>(m.rows)})
    for (int k = 3; k >= 0; --k) header.push_back(static_cast<unsigned char>(v >> (8 * k)));
  header.insert(header.end(), {static_cast<unsigned char>(bpp == 3 ? 8 : 16),
                               static_cast<unsigned char>(bpp == 3 ? 2 : 0), 0, 0, 0});
  chunk("IHDR", header);
  // The image data split over two IDAT chunks.
  const std::size_t half = z.size() / 2;
  chunk("IDAT", std::vector<unsigned char>(z.begin(), z.begin() + half));
  chunk("IDAT", std::vector<unsigned char>(z.begin() + half, z.end()));
  chunk("IEND", {});
  return png;
}

TEST(PngDecodeTest, EveryFilterType) {
  const std::vector<std::vector<int>> patterns = {{0}, {1}, {2}, {3}, {4}, {4, 3, 2, 1, 0},
                                                  {2, 4, 1, 3}};
  unsigned seed = 100;
  for (const int type : {CV_8UC3, CV_16UC1}) {
    for (const auto& filters : patterns) {
      const cv::Mat m = TestImage(23, 37, type, seed++);
      const std::vector<unsigned char> png = PngWithFilters(m, filters);
      cv::Mat fast;
      ASSERT_TRUE(DecodeFramePng(png.data(), png.size(), &fast)) << "filter " << filters[0];
      ExpectSame(fast, m);
      ExpectSame(fast, cv::imdecode(png, cv::IMREAD_UNCHANGED | cv::IMREAD_ANYDEPTH));
    }
  }
}

TEST(PngDecodeTest, DeclinesOtherLayoutsAndDamagedFiles) {
  cv::Mat out;
  for (const int type : {CV_8UC1, CV_8UC4, CV_16UC3}) {
    const std::vector<unsigned char> png = Encode(TestImage(20, 30, type, 5));
    EXPECT_FALSE(DecodeFramePng(png.data(), png.size(), &out)) << "type " << type;
  }
  const std::vector<unsigned char> png = Encode(TestImage(40, 50, CV_8UC3, 6));
  ASSERT_TRUE(DecodeFramePng(png.data(), png.size(), &out));
  // Every truncation and a flipped bit in each of many positions (CRCs, lengths, data).
  for (std::size_t n = 0; n < png.size(); n += 7) {
    EXPECT_FALSE(DecodeFramePng(png.data(), n, &out)) << "truncated to " << n;
  }
  for (std::size_t at = 0; at < png.size(); at += 3) {
    std::vector<unsigned char> bad = png;
    bad[at] ^= 0x10;
    cv::Mat image;
    if (DecodeFramePng(bad.data(), bad.size(), &image)) {
      // Only bytes outside the chunks' CRCs (after IEND) may change without being noticed.
      ExpectSame(image, cv::imdecode(png, cv::IMREAD_UNCHANGED));
    }
  }
  const std::vector<unsigned char> jpeg = [] {
    std::vector<unsigned char> b;
    cv::imencode(".jpg", TestImage(16, 16, CV_8UC3, 7), b);
    return b;
  }();
  EXPECT_FALSE(DecodeFramePng(jpeg.data(), jpeg.size(), &out));
}

// Peak resident memory of this process (MB).
double PeakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

TEST(PngDecodeTest, HeaderClaimingMoreThanItsDataIsDeclinedWithoutItsBuffer) {
  // A valid 23 x 37 file whose header claims 16000 x 16000 pixels (768 MB of rows): declined
  // before the rows are allocated (deflate cannot expand its few hundred bytes that far).
  std::vector<unsigned char> png = PngWithFilters(TestImage(23, 37, CV_8UC3, 9), {0});
  for (const std::size_t at : {std::size_t{16}, std::size_t{20}}) {  // IHDR width, height
    for (int k = 0; k < 4; ++k) png[at + k] = static_cast<unsigned char>(16000u >> (24 - 8 * k));
  }
  const uint32_t crc = static_cast<uint32_t>(crc32(0, png.data() + 12, 17));  // type + body
  for (int k = 0; k < 4; ++k) png[29 + k] = static_cast<unsigned char>(crc >> (24 - 8 * k));
  const double before = PeakRssMb();
  cv::Mat out;
  EXPECT_FALSE(DecodeFramePng(png.data(), png.size(), &out));
  EXPECT_LT(PeakRssMb() - before, 100.0) << "the claimed rows were allocated";
}

TEST(PngDecodeTest, ReadersGiveOpenCvsImage) {
  const std::string dir = ::testing::TempDir() + "/png_decode_test";
  std::filesystem::create_directories(dir);
  const cv::Mat colour = TestImage(48, 64, CV_8UC3, 8), depth = TestImage(48, 64, CV_16UC1, 9);
  ASSERT_TRUE(cv::imwrite(dir + "/c.png", colour));
  ASSERT_TRUE(cv::imwrite(dir + "/d.png", depth));
  ASSERT_TRUE(cv::imwrite(dir + "/g.png", TestImage(48, 64, CV_8UC1, 10)));
  cv::Mat image;
  std::string warning;
  ASSERT_TRUE(ReadColorImage(dir + "/c.png", 64, 48, &image, &warning)) << warning;
  ExpectSame(image, cv::imread(dir + "/c.png", cv::IMREAD_UNCHANGED));
  ASSERT_TRUE(ReadDepthImage(dir + "/d.png", 64, 48, &image, &warning)) << warning;
  ExpectSame(image, cv::imread(dir + "/d.png", cv::IMREAD_UNCHANGED | cv::IMREAD_ANYDEPTH));
  // The decoder's images meet the readers' checks as OpenCV's did.
  EXPECT_FALSE(ReadDepthImage(dir + "/c.png", 64, 48, &image, &warning));
  EXPECT_NE(warning.find("found CV_8UC3"), std::string::npos) << warning;
  EXPECT_FALSE(ReadColorImage(dir + "/d.png", 64, 48, &image, &warning));
  EXPECT_NE(warning.find("found CV_16UC1"), std::string::npos) << warning;
  EXPECT_FALSE(ReadColorImage(dir + "/g.png", 64, 48, &image, &warning));
  EXPECT_NE(warning.find("found CV_8UC1"), std::string::npos) << warning;
  EXPECT_FALSE(ReadColorImage(dir + "/c.png", 65, 48, &image, &warning));
  EXPECT_NE(warning.find("wrong colour image size"), std::string::npos) << warning;
  // Only PNG and JPEG: a BMP that OpenCV reads is refused, and so is a damaged file that
  // reached OpenCV's DICOM reader, which aborted the process (found by the image fuzzer).
  ASSERT_TRUE(cv::imwrite(dir + "/c.bmp", colour));
  EXPECT_FALSE(ReadColorImage(dir + "/c.bmp", 64, 48, &image, &warning));
  EXPECT_NE(warning.find("c.bmp: unreadable image (not a PNG or JPEG image)"), std::string::npos)
      << warning;
  const unsigned char kAbortedDicom[] = {
      0x89, 0x00, 0x00, 0xc2, 0xb0, 0x72, 0x08, 0xe2, 0x12, 0xf9, 0x6b, 0x52, 0x00, 0x00, 0x00,
      0x08, 0x00, 0x00, 0x00, 0x06, 0x10, 0x00, 0x00, 0x00, 0x00, 0x8b, 0xfe, 0x5c, 0x64, 0x00,
      0x00, 0x00, 0x00, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x89, 0x49, 0x50, 0x25,
      0xd0, 0xe6, 0x12, 0x3d, 0x2e, 0xd1, 0xe3, 0x12, 0x3d, 0x2e, 0xd1, 0xe3, 0x12, 0x3d, 0x2e,
      0xd1, 0x33, 0xf6, 0x12, 0x02, 0xdd, 0xc9, 0x59, 0x05, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
      0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
      0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
      0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
      0xff, 0x80, 0x00, 0x00, 0x00, 0x5b, 0x00, 0x49, 0x44, 0x49, 0x43, 0x4d, 0x42, 0x60, 0x82};
  {
    std::ofstream out(dir + "/dicom.png", std::ios::binary);
    out.write(reinterpret_cast<const char*>(kAbortedDicom), sizeof(kAbortedDicom));
  }
  EXPECT_FALSE(ReadDepthImage(dir + "/dicom.png", 8, 6, &image, &warning));
  EXPECT_NE(warning.find("not a PNG or JPEG image"), std::string::npos) << warning;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artex
