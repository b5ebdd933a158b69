#include "sensors/image_io.h"

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <system_error>
#include <vector>

#include "models/error.h"
#include "sensors/png_decode.h"
#include "sensors/sequence.h"

namespace artex {
namespace {

std::string SizeText(int width, int height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

// The file's bytes (false: unreadable).
bool ReadBytes(const std::string& path, std::vector<unsigned char>* bytes) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return false;
  const std::streamoff size = in.tellg();
  if (size < 0) return false;
  bytes->resize(static_cast<std::size_t>(size));
  in.seekg(0);
  return static_cast<bool>(in.read(reinterpret_cast<char*>(bytes->data()), size));
}

bool ReadImage(const std::string& path, int flags, cv::Mat* image, std::string* warning) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    if (warning) *warning = path + ": missing frame file";
    return false;
  }
  // 8-bit RGB and 16-bit greyscale PNGs (what recorders write) by the fast decoder; it gives
  // OpenCV's image for them (read unchanged, as both callers do) and declines everything
  // else, which OpenCV then decodes from the same bytes.
  std::vector<unsigned char> bytes;
  if (!ReadBytes(path, &bytes)) bytes.clear();
  if (DecodeFramePng(bytes.data(), bytes.size(), image)) return true;
  // Frames are PNG or JPEG: other bytes never reach OpenCV's other decoders (its DICOM reader
  // aborts the process on some damaged files, found by the image fuzzer).
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  static const unsigned char kJpeg[3] = {0xff, 0xd8, 0xff};
  const bool png = bytes.size() >= 8 && std::memcmp(bytes.data(), kPng, 8) == 0;
  const bool jpeg = bytes.size() >= 3 && std::memcmp(bytes.data(), kJpeg, 3) == 0;
  if (!png && !jpeg) bytes.clear();
  try {
    *image = cv::imdecode(bytes, flags);
  } catch (const cv::Exception& e) {
    image->release();
  }
  if (image->empty()) {
    if (warning) *warning = path + ": unreadable image (not a valid PNG/JPEG)";
    return false;
  }
  return true;
}

}  // namespace

std::string MatTypeName(int type) {
  const int depth = CV_MAT_DEPTH(type);
  const char* names[] = {"CV_8U",  "CV_8S",  "CV_16U", "CV_16S",
                         "CV_32S", "CV_32F", "CV_64F", "CV_16F"};
  const std::string base = depth >= 0 && depth < 8 ? names[depth] : "CV_?";
  return base + "C" + std::to_string(CV_MAT_CN(type));
}

bool ReadDepthImage(const std::string& path, int width, int height, cv::Mat* depth,
                    std::string* warning) {
  if (!ReadImage(path, cv::IMREAD_UNCHANGED | cv::IMREAD_ANYDEPTH, depth, warning)) return false;
  if (depth->type() != CV_16UC1) {
    if (warning) {
      *warning = path +
                 ": wrong depth image format: expected 16-bit single-channel (CV_16UC1), "
                 "found " +
                 MatTypeName(depth->type());
    }
    return false;
  }
  if (depth->cols != width || depth->rows != height) {
    if (warning) {
      *warning = path + ": wrong depth image size: expected " + SizeText(width, height) +
                 " (calibration), found " + SizeText(depth->cols, depth->rows);
    }
    return false;
  }
  return true;
}

bool ReadColorImage(const std::string& path, int width, int height, cv::Mat* color,
                    std::string* warning) {
  if (!ReadImage(path, cv::IMREAD_UNCHANGED, color, warning)) return false;
  if (color->type() == CV_8UC4) {
    cv::Mat bgr;
    cv::cvtColor(*color, bgr, cv::COLOR_BGRA2BGR);
    *color = bgr;
  }
  if (color->type() != CV_8UC3) {
    if (warning) {
      *warning = path + ": wrong colour image format: expected 8-bit 3-channel (CV_8UC3), found " +
                 MatTypeName(color->type());
    }
    return false;
  }
  if (color->cols != width || color->rows != height) {
    if (warning) {
      *warning = path + ": wrong colour image size: expected " + SizeText(width, height) +
                 " (calibration), found " + SizeText(color->cols, color->rows);
    }
    return false;
  }
  return true;
}

void WriteFileAtomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".partial";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot write (cannot create " + tmp + ")");
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.close();
    if (!out) {
      std::remove(tmp.c_str());
      throw Error(path + ": cannot write (write to " + tmp + " failed)");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot write (rename failed: " + ec.message() + ")");
  }
}

void WriteImageAtomic(const std::string& path, const cv::Mat& image) {
  const std::string ext = std::filesystem::path(path).extension().string();
  std::vector<uchar> buffer;
  bool ok = false;
  try {
    ok = !image.empty() && cv::imencode(ext, image, buffer);
  } catch (const cv::Exception& e) {
    throw Error(path + ": cannot encode a " + MatTypeName(image.type()) + " image as '" + ext +
                "': " + e.what());
  }
  if (!ok) {
    throw Error(path + ": cannot encode a " + MatTypeName(image.type()) + " image as '" + ext +
                "'");
  }
  WriteFileAtomic(path, std::string(buffer.begin(), buffer.end()));
}

}  // namespace artex
