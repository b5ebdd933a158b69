#include "sensors/png_decode.h"

#include <libdeflate.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

namespace artex {
namespace {

uint32_t BigEndian32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};

libdeflate_decompressor* ThreadDecompressor() {
  thread_local std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> d(
      libdeflate_alloc_decompressor());
  return d.get();
}

// Reverses the PNG filter of one row in place (filter types 0-4, BPP bytes per pixel);
// prior: the previous reconstructed row (nullptr for the first row). False: unknown filter.
// The left neighbours are carried in registers: reading back the byte just written would
// chain every byte on a store-to-load forwarding.
template <int BPP>
bool Unfilter(int filter, unsigned char* __restrict row, const unsigned char* __restrict prior,
              std::size_t length) {
  unsigned char left[BPP];
  switch (filter) {
    case 0:
      return true;
    case 1:  // Sub
      for (int j = 0; j < BPP; ++j) left[j] = row[j];
      for (std::size_t i = BPP; i < length; i += BPP) {
        for (int j = 0; j < BPP; ++j) {
          left[j] = static_cast<unsigned char>(row[i + j] + left[j]);
          row[i + j] = left[j];
        }
      }
      return true;
    case 2:  // Up
      if (prior)
        for (std::size_t i = 0; i < length; ++i) row[i] = static_cast<unsigned char>(row[i] + prior[i]);
      return true;
    case 3:  // Average
      for (int j = 0; j < BPP; ++j) {
        left[j] = static_cast<unsigned char>(row[j] + (prior ? prior[j] >> 1 : 0));
        row[j] = left[j];
      }
      for (std::size_t i = BPP; i < length; i += BPP) {
        for (int j = 0; j < BPP; ++j) {
          const int up = prior ? prior[i + j] : 0;
          left[j] = static_cast<unsigned char>(row[i + j] + ((left[j] + up) >> 1));
          row[i + j] = left[j];
        }
      }
      return true;
    case 4:  // Paeth
      if (!prior) return Unfilter<BPP>(1, row, prior, length);  // a zero prior row: Sub
      for (int j = 0; j < BPP; ++j) {
        left[j] = static_cast<unsigned char>(row[j] + prior[j]);
        row[j] = left[j];
      }
      for (std::size_t i = BPP; i < length; i += BPP) {
        for (int j = 0; j < BPP; ++j) {
          const int a = left[j], b = prior[i + j], c = prior[i + j - BPP];
          const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
          const int predictor = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
          left[j] = static_cast<unsigned char>(row[i + j] + predictor);
          row[i + j] = left[j];
        }
      }
      return true;
    default:
      return false;
  }
}

}  // namespace

bool DecodeFramePng(const unsigned char* data, std::size_t size, cv::Mat* image) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (size < 8 || std::memcmp(data, kSignature, 8) != 0) return false;
  std::size_t at = 8;
  uint32_t width = 0, height = 0;
  int bpp = 0;  // bytes per pixel: 3 (RGB, 8 bit) or 2 (grey, 16 bit)
  std::vector<unsigned char> compressed;
  bool header = false, ended = false, idat_done = false;
  while (!ended) {
    if (size - at < 12) return false;
    const uint32_t length = BigEndian32(data + at);
    if (length > size - at - 12) return false;
    const unsigned char* type = data + at + 4;
    const unsigned char* body = data + at + 8;
    const uint32_t crc = BigEndian32(body + length);
    if (libdeflate_crc32(0, type, length + 4) != crc) return false;
    const bool is_idat = std::memcmp(type, "IDAT", 4) == 0;
    if (!header) {  // IHDR comes first
      if (std::memcmp(type, "IHDR", 4) != 0 || length != 13) return false;
      width = BigEndian32(body);
      height = BigEndian32(body + 4);
      const int depth = body[8], colour = body[9];
      if (body[10] != 0 || body[11] != 0 || body[12] != 0) return false;  // interlaced etc.
      if (depth == 8 && colour == 2) {
        bpp = 3;
      } else if (depth == 16 && colour == 0) {
        bpp = 2;
      } else {
        return false;
      }
      // libpng's default limits (1000000 per side); larger images are left to OpenCV's errors.
      if (width == 0 || height == 0 || width > 1000000 || height > 1000000 ||
          uint64_t{width} * height > (uint64_t{1} << 28))
        return false;
      header = true;
    } else if (is_idat) {
      if (idat_done) return false;  // IDAT chunks must be consecutive
      compressed.insert(compressed.end(), body, body + length);
    } else {
      if (!compressed.empty()) idat_done = true;
      if (std::memcmp(type, "IEND", 4) == 0) {
        ended = true;
      } else if (std::memcmp(type, "tRNS", 4) == 0 || !(type[0] & 0x20)) {
        return false;  // transparency, a palette or another critical chunk
      }
    }
    at += 12 + std::size_t{length};
  }
  if (compressed.empty()) return false;
  const std::size_t stride = std::size_t{width} * bpp;
  // Deflate expands by at most 1032:1: a header claiming more than that from the data it
  // carries cannot decode, and is declined before its buffer is allocated.
  if (std::size_t{height} * (stride + 1) / 1032 > compressed.size()) return false;
  std::vector<unsigned char> raw(std::size_t{height} * (stride + 1));
  libdeflate_decompressor* d = ThreadDecompressor();
  if (!d) return false;
  if (libdeflate_zlib_decompress(d, compressed.data(), compressed.size(), raw.data(), raw.size(),
                                 nullptr) != LIBDEFLATE_SUCCESS)
    return false;
  cv::Mat out(static_cast<int>(height), static_cast<int>(width), bpp == 3 ? CV_8UC3 : CV_16UC1);
  const unsigned char* prior = nullptr;
  for (uint32_t y = 0; y < height; ++y) {
    unsigned char* line = raw.data() + y * (stride + 1);
    unsigned char* row = line + 1;
    if (!(bpp == 3 ? Unfilter<3>(line[0], row, prior, stride)
                   : Unfilter<2>(line[0], row, prior, stride)))
      return false;
    prior = row;
    unsigned char* o = out.ptr<unsigned char>(static_cast<int>(y));
    if (bpp == 3) {  // RGB -> BGR
      for (uint32_t x = 0; x < width; ++x) {
        o[3 * x] = row[3 * x + 2];
        o[3 * x + 1] = row[3 * x + 1];
        o[3 * x + 2] = row[3 * x];
      }
    } else {  // big-endian samples -> uint16_t
      uint16_t* o16 = reinterpret_cast<uint16_t*>(o);
      for (uint32_t x = 0; x < width; ++x)
        o16[x] = static_cast<uint16_t>((row[2 * x] << 8) | row[2 * x + 1]);
    }
  }
  *image = out;
  return true;
}

}  // namespace artex
