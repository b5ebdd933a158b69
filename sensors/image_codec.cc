#include "sensors/image_codec.h"

#include <jpeglib.h>
#include <png.h>
#include <zlib.h>

#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>


// libpng and libjpeg report errors by longjmp. Every function below that calls setjmp keeps
// only trivially destructible locals, so that the jump skips no destructor; the matrices and
// vectors live in their callers' frames.

namespace artex {
namespace {

constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
constexpr unsigned char kJpegSignature[3] = {0xff, 0xd8, 0xff};
constexpr bool kLittleEndian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;
// The most decoded bytes a file's byte may stand for (deflate's largest expansion; JPEG, whose
// decoder fills a truncated file's missing rows with grey, is held to the same bound): a header
// claiming more is refused before the image is allocated.
constexpr double kMaxExpansion = 1032.0;

void SetError(std::string* error, const std::string& text) {
  if (error) *error = text;
}

// The decoded image's bytes, or 0 when they would exceed kMaxImageBytes.
std::size_t ImageBytes(std::size_t width, std::size_t height, std::size_t bytes_per_pixel) {
  if (width == 0 || height == 0) return 0;
  const std::size_t row = width * bytes_per_pixel;
  if (row / bytes_per_pixel != width || row > kMaxImageBytes / height) return 0;
  return row * height;
}

// ---- PNG ----

struct PngState {
  const unsigned char* data = nullptr;  // reading
  std::size_t size = 0;
  std::size_t pos = 0;
  std::vector<unsigned char>* out = nullptr;  // writing
  char message[200] = {0};
};

void OnPngError(png_structp png, png_const_charp message) {
  auto* state = static_cast<PngState*>(png_get_error_ptr(png));
  std::snprintf(state->message, sizeof(state->message), "%s", message ? message : "error");
  png_longjmp(png, 1);
}

void OnPngWarning(png_structp, png_const_charp) {}

void ReadPngBytes(png_structp png, png_bytep out, png_size_t n) {
  auto* state = static_cast<PngState*>(png_get_io_ptr(png));
  if (n > state->size - state->pos) png_error(png, "truncated data");
  std::memcpy(out, state->data + state->pos, n);
  state->pos += n;
}

void WritePngBytes(png_structp png, png_bytep data, png_size_t n) {
  auto* state = static_cast<PngState*>(png_get_io_ptr(png));
  bool ok = true;
  try {
    state->out->insert(state->out->end(), data, data + n);
  } catch (const std::bad_alloc&) {
    ok = false;
  }
  if (!ok) png_error(png, "out of memory");
}

void FlushPng(png_structp) {}

struct PngLayout {
  int width = 0;
  int height = 0;
  int channels = 0;  // of the decoded image
  int depth = 0;     // CV_8U or CV_16U
};

// Reads the header and sets libpng's transforms so that the rows come out as `mode` asks
// (OpenCV's PNG reading: tests/sensors/image_codec_test.cc compares the two).
bool BeginPng(png_structp png, png_infop info, ImageRead mode, std::size_t max_stored_source,
              PngLayout* layout) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_user_limits(png, 1u << 20, 1u << 20);
  png_read_info(png, info);
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0;
  png_get_IHDR(png, info, &width, &height, &bit_depth, &color_type, nullptr, nullptr, nullptr);
  const double stored = (static_cast<double>(png_get_rowbytes(png, info)) + 1.0) * height;
  if (stored > kMaxExpansion * static_cast<double>(max_stored_source)) {
    png_error(png, "the header's size needs more data than the file holds");
  }
  const bool colour = (color_type & PNG_COLOR_MASK_COLOR) != 0;
  const bool transparency = png_get_valid(png, info, PNG_INFO_tRNS) != 0;
  int channels = 1;
  if (color_type == PNG_COLOR_TYPE_GRAY_ALPHA || color_type == PNG_COLOR_TYPE_RGB_ALPHA) {
    channels = 4;
  } else if (colour) {  // RGB or palette
    channels = transparency ? 4 : 3;
  }
  int depth = bit_depth == 16 ? CV_16U : CV_8U;
  if (mode == ImageRead::kColor) {
    channels = 3;
    depth = CV_8U;
  } else if (mode == ImageRead::kGrayscale) {
    channels = 1;
    depth = CV_8U;
  }
  if (bit_depth == 16 && depth == CV_8U) png_set_strip_16(png);
  if (bit_depth == 16 && depth == CV_16U && kLittleEndian) png_set_swap(png);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (!colour && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (channels == 4) {
    if (transparency) png_set_tRNS_to_alpha(png);
  } else {
    png_set_strip_alpha(png);
  }
  if (channels >= 3) {
    if (!colour) png_set_gray_to_rgb(png);
    png_set_bgr(png);
  } else if (colour) {
    png_set_rgb_to_gray(png, 1, 0.299, 0.587);
  }
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  const std::size_t sample = depth == CV_16U ? 2 : 1;
  if (png_get_rowbytes(png, info) != width * channels * sample) {
    png_error(png, "unexpected row layout after conversion");
  }
  layout->width = static_cast<int>(width);
  layout->height = static_cast<int>(height);
  layout->channels = channels;
  layout->depth = depth;
  return true;
}

bool ReadPngRows(png_structp png, png_infop info, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

bool DecodePng(const unsigned char* data, std::size_t size, ImageRead mode, cv::Mat* image,
               std::string* error) {
  PngState state;
  state.data = data;
  state.size = size;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, OnPngError,
                                           OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_read_struct(&png, &info, nullptr);
    SetError(error, "PNG: cannot allocate the decoder");
    return false;
  }
  png_set_read_fn(png, &state, ReadPngBytes);
  PngLayout layout;
  bool ok = BeginPng(png, info, mode, size, &layout);
  if (ok && ImageBytes(layout.width, layout.height,
                        layout.channels * (layout.depth == CV_16U ? 2 : 1)) == 0) {
    std::snprintf(state.message, sizeof(state.message), "image of %dx%d pixels above 1 GiB",
                  layout.width, layout.height);
    ok = false;
  }
  std::vector<png_bytep> rows;
  if (ok) {
    try {
      image->create(layout.height, layout.width, CV_MAKETYPE(layout.depth, layout.channels));
      rows.resize(layout.height);
    } catch (const std::exception&) {  // cv::Exception or std::bad_alloc
      std::snprintf(state.message, sizeof(state.message), "out of memory for %dx%d pixels",
                    layout.width, layout.height);
      ok = false;
    }
  }
  if (ok) {
    for (int y = 0; y < layout.height; ++y) rows[y] = image->ptr<png_byte>(y);
    ok = ReadPngRows(png, info, rows.data());
  }
  png_destroy_read_struct(&png, &info, nullptr);
  if (!ok) {
    image->release();
    SetError(error, std::string("PNG: ") + state.message);
  }
  return ok;
}

bool WritePng(png_structp png, png_infop info, const cv::Mat& image, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  const int channels = image.channels();
  const int color_type = channels == 1   ? PNG_COLOR_TYPE_GRAY
                         : channels == 3 ? PNG_COLOR_TYPE_RGB
                                         : PNG_COLOR_TYPE_RGB_ALPHA;
  const int bit_depth = image.depth() == CV_16U ? 16 : 8;
  png_set_IHDR(png, info, image.cols, image.rows, bit_depth, color_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
  png_set_compression_level(png, Z_BEST_SPEED);
  png_set_compression_strategy(png, Z_RLE);
  png_write_info(png, info);
  if (channels >= 3) png_set_bgr(png);
  if (bit_depth == 16 && kLittleEndian) png_set_swap(png);
  png_write_image(png, rows);
  png_write_end(png, info);
  return true;
}

// ---- JPEG ----

struct JpegError {
  jpeg_error_mgr manager;  // first: libjpeg passes &manager as the error handler
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {0};
};

void OnJpegError(j_common_ptr info) {
  auto* error = reinterpret_cast<JpegError*>(info->err);
  (*info->err->format_message)(info, error->message);
  std::longjmp(error->jump, 1);
}

void OnJpegMessage(j_common_ptr) {}

// libjpeg's error manager, reporting through `error`'s jump instead of exiting the process.
jpeg_error_mgr* JpegErrorManager(JpegError* error) {
  jpeg_std_error(&error->manager);
  error->manager.error_exit = OnJpegError;
  error->manager.output_message = OnJpegMessage;
  return &error->manager;
}

// Reads the header and starts the decompression; sets *channels (1 or 3).
bool BeginJpeg(jpeg_decompress_struct* info, JpegError* error, const unsigned char* data,
               std::size_t size, ImageRead mode, int* channels) {
  if (setjmp(error->jump)) return false;
  jpeg_mem_src(info, data, static_cast<unsigned long>(size));
  jpeg_read_header(info, TRUE);
  if (info->jpeg_color_space == JCS_CMYK || info->jpeg_color_space == JCS_YCCK) {
    std::snprintf(error->message, sizeof(error->message), "CMYK images are not supported");
    return false;
  }
  *channels = mode == ImageRead::kColor       ? 3
              : mode == ImageRead::kGrayscale ? 1
                                              : (info->num_components > 1 ? 3 : 1);
  info->out_color_space = *channels == 3 ? JCS_EXT_BGR : JCS_GRAYSCALE;
  jpeg_start_decompress(info);
  if (info->output_components != *channels) {
    std::snprintf(error->message, sizeof(error->message), "unexpected component count %d",
                  info->output_components);
    return false;
  }
  return true;
}

bool ReadJpegRows(jpeg_decompress_struct* info, JpegError* error, cv::Mat* image) {
  if (setjmp(error->jump)) return false;
  while (info->output_scanline < info->output_height) {
    JSAMPROW row = image->ptr<JSAMPLE>(static_cast<int>(info->output_scanline));
    jpeg_read_scanlines(info, &row, 1);
  }
  jpeg_finish_decompress(info);
  return true;
}

bool DecodeJpeg(const unsigned char* data, std::size_t size, ImageRead mode, cv::Mat* image,
                std::string* error) {
  jpeg_decompress_struct info;
  JpegError jpeg_error;
  info.err = JpegErrorManager(&jpeg_error);
  jpeg_create_decompress(&info);
  int channels = 0;
  bool ok = BeginJpeg(&info, &jpeg_error, data, size, mode, &channels);
  if (ok && ImageBytes(info.output_width, info.output_height, channels) == 0) {
    std::snprintf(jpeg_error.message, sizeof(jpeg_error.message),
                  "image of %ux%u pixels above 1 GiB", info.output_width, info.output_height);
    ok = false;
  }
  // Without the bound a header on a few bytes would make libjpeg write gigabytes of grey. Even
  // a flat image needs two bits per 8x8 block and channel, about 1 byte per 256 decoded bytes.
  if (ok && static_cast<double>(info.output_width) * info.output_height * channels >
                kMaxExpansion * static_cast<double>(size)) {
    std::snprintf(jpeg_error.message, sizeof(jpeg_error.message),
                  "the header's size (%ux%u) needs more data than the file holds",
                  info.output_width, info.output_height);
    ok = false;
  }
  if (ok) {
    try {
      image->create(static_cast<int>(info.output_height), static_cast<int>(info.output_width),
                    CV_MAKETYPE(CV_8U, channels));
    } catch (const std::exception&) {
      std::snprintf(jpeg_error.message, sizeof(jpeg_error.message), "out of memory");
      ok = false;
    }
  }
  if (ok) ok = ReadJpegRows(&info, &jpeg_error, image);
  jpeg_destroy_decompress(&info);
  if (!ok) {
    image->release();
    SetError(error, std::string("JPEG: ") + jpeg_error.message);
  }
  return ok;
}

struct JpegOutput {
  unsigned char* data = nullptr;  // allocated by libjpeg (malloc)
  unsigned long size = 0;
};

bool WriteJpeg(jpeg_compress_struct* info, JpegError* error, const cv::Mat& image, int quality,
               JpegOutput* out) {
  if (setjmp(error->jump)) return false;
  jpeg_mem_dest(info, &out->data, &out->size);
  info->image_width = static_cast<JDIMENSION>(image.cols);
  info->image_height = static_cast<JDIMENSION>(image.rows);
  info->input_components = image.channels();
  info->in_color_space = image.channels() == 3 ? JCS_EXT_BGR : JCS_GRAYSCALE;
  jpeg_set_defaults(info);
  jpeg_set_quality(info, quality, TRUE);
  jpeg_start_compress(info, TRUE);
  while (info->next_scanline < info->image_height) {
    JSAMPROW row = const_cast<JSAMPROW>(image.ptr<JSAMPLE>(static_cast<int>(info->next_scanline)));
    jpeg_write_scanlines(info, &row, 1);
  }
  jpeg_finish_compress(info);
  return true;
}

}  // namespace

bool DecodeImage(const unsigned char* data, std::size_t size, ImageRead mode, cv::Mat* image,
                 std::string* error) {
  if (data != nullptr && size >= 8 && std::memcmp(data, kPngSignature, 8) == 0) {
    return DecodePng(data, size, mode, image, error);
  }
  if (data != nullptr && size >= 3 && std::memcmp(data, kJpegSignature, 3) == 0) {
    return DecodeJpeg(data, size, mode, image, error);
  }
  image->release();
  SetError(error, size == 0 ? "empty file" : "not a PNG or JPEG image");
  return false;
}

bool EncodePng(const cv::Mat& image, std::vector<unsigned char>* bytes, std::string* error) {
  const int channels = image.channels();
  if (image.empty() || (image.depth() != CV_8U && image.depth() != CV_16U) ||
      (channels != 1 && channels != 3 && channels != 4)) {
    SetError(error, "PNG: expected an 8- or 16-bit image with 1, 3 or 4 channels");
    return false;
  }
  PngState state;
  state.out = bytes;
  bytes->clear();
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, OnPngError,
                                            OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_write_struct(&png, &info);
    SetError(error, "PNG: cannot allocate the encoder");
    return false;
  }
  png_set_write_fn(png, &state, WritePngBytes, FlushPng);
  std::vector<png_bytep> rows(image.rows);
  for (int y = 0; y < image.rows; ++y) rows[y] = const_cast<png_bytep>(image.ptr<png_byte>(y));
  const bool ok = WritePng(png, info, image, rows.data());
  png_destroy_write_struct(&png, &info);
  if (!ok) {
    bytes->clear();
    SetError(error, std::string("PNG: ") + state.message);
  }
  return ok;
}

bool EncodeJpeg(const cv::Mat& image, int quality, std::vector<unsigned char>* bytes,
                std::string* error) {
  if (image.empty() || image.depth() != CV_8U ||
      (image.channels() != 1 && image.channels() != 3) || quality < 1 || quality > 100) {
    SetError(error, "JPEG: expected an 8-bit image with 1 or 3 channels, quality 1-100");
    return false;
  }
  jpeg_compress_struct info;
  JpegError jpeg_error;
  info.err = JpegErrorManager(&jpeg_error);
  jpeg_create_compress(&info);
  JpegOutput out;
  const bool ok = WriteJpeg(&info, &jpeg_error, image, quality, &out);
  jpeg_destroy_compress(&info);
  if (ok) bytes->assign(out.data, out.data + out.size);
  std::free(out.data);
  if (!ok) {
    bytes->clear();
    SetError(error, std::string("JPEG: ") + jpeg_error.message);
  }
  return ok;
}

}  // namespace artex
