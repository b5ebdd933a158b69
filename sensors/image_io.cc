#include "sensors/image_io.h"

#include <cctype>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <system_error>
#include <vector>

#include "models/error.h"
#include "sensors/image_codec.h"
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

// Read as stored (ImageRead::kUnchanged), as both callers do.
bool ReadImage(const std::string& path, cv::Mat* image, std::string* warning) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    if (warning) *warning = path + ": missing frame file";
    return false;
  }
  // 8-bit RGB and 16-bit greyscale PNGs (what recorders write) by the fast decoder; it gives
  // the general decoder's image for them and declines everything else, which the general
  // decoder (sensors/image_codec.h: PNG and JPEG only) then decodes from the same bytes.
  std::vector<unsigned char> bytes;
  if (!ReadBytes(path, &bytes)) bytes.clear();
  if (DecodeFramePng(bytes.data(), bytes.size(), image)) return true;
  std::string error;
  if (!DecodeImage(bytes.data(), bytes.size(), ImageRead::kUnchanged, image, &error)) {
    if (warning) *warning = path + ": unreadable image (" + error + ")";
    return false;
  }
  return true;
}

}  // namespace

cv::Mat ReadImageFile(const std::string& path, ImageRead mode) {
  std::vector<unsigned char> bytes;
  if (!ReadBytes(path, &bytes)) throw Error(path + ": cannot read the image");
  cv::Mat image;
  std::string error;
  if (!DecodeImage(bytes.data(), bytes.size(), mode, &image, &error)) {
    throw Error(path + ": unreadable image (" + error + ")");
  }
  return image;
}

std::string MatTypeName(int type) {
  const int depth = CV_MAT_DEPTH(type);
  const char* names[] = {"CV_8U",  "CV_8S",  "CV_16U", "CV_16S",
                         "CV_32S", "CV_32F", "CV_64F", "CV_16F"};
  const std::string base = depth >= 0 && depth < 8 ? names[depth] : "CV_?";
  return base + "C" + std::to_string(CV_MAT_CN(type));
}

bool ReadDepthImage(const std::string& path, int width, int height, cv::Mat* depth,
                    std::string* warning) {
  if (!ReadImage(path, depth, warning)) return false;
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
  if (!ReadImage(path, color, warning)) return false;
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
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::vector<unsigned char> buffer;
  std::string error;
  bool ok = false;
  if (ext == ".png") {
    ok = EncodePng(image, &buffer, &error);
  } else if (ext == ".jpg" || ext == ".jpeg") {
    ok = EncodeJpeg(image, kJpegQuality, &buffer, &error);
  } else {
    error = "expected a .png, .jpg or .jpeg file name";
  }
  if (!ok) {
    throw Error(path + ": cannot encode a " + MatTypeName(image.type()) + " image as '" + ext +
                "': " + error);
  }
  WriteFileAtomic(path, std::string(buffer.begin(), buffer.end()));
}

}  // namespace artex
